"""What a generator hands the surface tracer: triangles and spheres for Embree, and the analytic data behind them.

The scene is periodic in x and y over the tile [0, L_x) x [0, L_y) (``tile`` and ``tile_y``;
square unless ``tile_y`` is given; shapes crossing the tile edge come with their periodic images)
and bounded in z: nothing can be hit above ``z_top``; a ray going
below ``z_bottom`` has left through the bottom of the slab (transmitted). Every triangle names
its analytic shape (``face_shape``); every shape names its material (an index into
``materials``). Generators assemble scenes with :class:`SceneBuilder`, which also lays the base
plane that every scene kind can have.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from microsim.tracer.materials import Material, codes, row_length
from microsim.tracer.shapes import Shapes

#: the base plane's two triangles overhang the tile by this fraction on every side
BASE_MARGIN = 0.01


@dataclass
class MaterialTable:
    """Kind codes and parameter rows of the materials a scene uses."""

    code: np.ndarray  # (M,) int32 kind codes
    params: np.ndarray  # (M, materials.row_length()) float64

    def __post_init__(self):
        unknown = set(np.unique(self.code).tolist()) - codes()
        if unknown:
            raise ValueError(f"material kind codes {sorted(unknown)} unknown; known: {sorted(codes())}")

    @classmethod
    def of(cls, materials: list[Material]) -> "MaterialTable":
        params = np.zeros((len(materials), row_length()))
        for j, material in enumerate(materials):
            row = material.row()
            params[j, : len(row)] = row
        return cls(np.array([m.code for m in materials], dtype=np.int32), params)


class SceneArrays(NamedTuple):
    """What the tracer's kernels read of a scene (see :class:`Scene` and :class:`Shapes`)."""

    prim_shape: np.ndarray
    shape_code: np.ndarray
    shape_params: np.ndarray
    shape_material: np.ndarray
    shape_size: np.ndarray
    material_code: np.ndarray
    material_params: np.ndarray
    period: tuple  # (L_x, L_y), float64: the tile is [0, L_x) x [0, L_y)
    z_top: float
    z_bottom: float
    base_material: int  # the base plane's material index (its order-1 exits are tallied apart), -1: none


@dataclass
class Scene:
    """One realization of a microgeometry, ready to trace: triangles and native spheres.

    Primitives are numbered triangles first, then spheres; ``prim_shape`` gives each one's shape.
    Native spheres are given in the frame where x is scaled by ``sphere_scale[0]`` and y by
    ``sphere_scale[1]``: with a scale other than (1, 1) they stand for the ellipsoids that the
    map takes onto them (micrograins: the grains' unit space), and their shapes are those
    ellipsoids. Embree traces them through an instance that maps that frame back (the ray
    parameter t is the same in both frames).
    """

    vertices: np.ndarray  # (V, 3) float32
    faces: np.ndarray  # (F, 3) int32, counter-clockwise seen from outside (normal points out)
    face_shape: np.ndarray  # (F,) int32
    shapes: Shapes
    materials: MaterialTable
    tile: float  # period L_x in x (and in y unless tile_y is given)
    z_top: float
    z_bottom: float
    #: resolved parameters and measured properties, stored as the table's scene/ attrs
    info: dict = field(default_factory=dict)
    spheres: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), np.float32))  # (K, 4) x, y, z, r
    sphere_shape: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))  # (K,) int32
    sphere_scale: tuple = (1.0, 1.0)
    base_material: int = -1
    tile_y: float | None = None  # period L_y in y; None: the same as tile
    #: a heightfield's grid (microsim.tracer.integrators.grid.HeightGrid): its triangles are then met by
    #: walking the grid instead of by Embree; None: Embree
    grid: object = None

    def __post_init__(self):
        if self.tile_y is None:
            self.tile_y = self.tile
        if not (self.tile > 0.0 and self.tile_y > 0.0):
            raise ValueError(f"the tile's sides must be positive: {self.tile!r} x {self.tile_y!r}")
        self.vertices = np.ascontiguousarray(self.vertices, dtype=np.float32)
        self.faces = np.ascontiguousarray(self.faces, dtype=np.int32)
        self.face_shape = np.ascontiguousarray(self.face_shape, dtype=np.int32)
        self.spheres = np.ascontiguousarray(self.spheres, dtype=np.float32).reshape(-1, 4)
        self.sphere_shape = np.ascontiguousarray(self.sphere_shape, dtype=np.int32)
        if len(self.faces) != len(self.face_shape) or len(self.spheres) != len(self.sphere_shape):
            raise ValueError("every face and sphere needs a shape")
        if len(self.prim_shape) and self.prim_shape.max() >= len(self.shapes):
            raise ValueError("a primitive refers to a missing shape")

    @property
    def period(self) -> tuple[float, float]:
        """The tile's sides (L_x, L_y)."""
        return float(self.tile), float(self.tile_y)

    @property
    def n_triangles(self) -> int:
        return len(self.faces)

    @property
    def prim_shape(self) -> np.ndarray:
        return np.concatenate([self.face_shape, self.sphere_shape])

    def arrays(self) -> SceneArrays:
        s = self.shapes
        return SceneArrays(self.prim_shape, s.code, s.params, s.material, s.size, self.materials.code,
                           self.materials.params, self.period, self.z_top, self.z_bottom, self.base_material)


class SceneBuilder:
    """Assembles a :class:`Scene` part by part: each part's triangles, shapes and material.

    Parts keep the order in which they are added (triangle, shape and material indices follow
    it); the table's ``triangles`` count is added to the scene's info. The tile is
    [0, tile) x [0, tile_y) (``tile_y`` None: square).
    """

    def __init__(self, tile: float, tile_y: float | None = None):
        self.tile = tile
        self.tile_y = tile if tile_y is None else tile_y
        self.vertices, self.faces, self.face_shape, self.shapes, self.materials = [], [], [], [], []
        self.spheres, self.sphere_shape = [], []
        self.sphere_scale = (1.0, 1.0)
        self.base_material = -1
        self.n_vertices = self.n_shapes = 0

    def add(self, vertices, faces, face_shape, shapes: Shapes, material: Material) -> None:
        """A mesh whose faces name shapes by their index in ``shapes``, all made of ``material``."""
        self.vertices.append(vertices)
        self.faces.append(faces + self.n_vertices)
        self.face_shape.append(face_shape + self.n_shapes)
        self.n_vertices += len(vertices)
        self._add_shapes(shapes, material)

    def add_spheres(self, centres, radius: float, material: Material) -> None:
        """Exact spheres, Embree's native primitive: one float4 (x, y, z, r) and one shape each."""
        if self.sphere_scale != (1.0, 1.0):
            raise ValueError("the native spheres of a scene share one frame: spheres cannot join scaled ellipsoids")
        n = len(centres)
        self.spheres.append(np.column_stack([centres, np.full(n, radius)]))
        self.sphere_shape.append(np.arange(n, dtype=np.int32) + self.n_shapes)
        self._add_shapes(Shapes.spheres(centres, radius, radius), material)

    def add_ellipsoids(self, centres, semi_axes, material: Material) -> None:
        """Exact axis-aligned ellipsoids of one shape (semi-axes a, b, c), traced as Embree's native
        spheres of radius c in the frame scaled by (c / a, c / b) in x and y (see :class:`Scene`)."""
        a, b, c = semi_axes
        scale = (c / a, c / b)
        if self.spheres and scale != self.sphere_scale:
            raise ValueError("the native spheres of a scene share one frame: one ellipsoid shape per scene")
        self.sphere_scale = scale
        n = len(centres)
        scaled = np.asarray(centres, np.float64) * np.array([scale[0], scale[1], 1.0])
        self.spheres.append(np.column_stack([scaled, np.full(n, c)]))
        self.sphere_shape.append(np.arange(n, dtype=np.int32) + self.n_shapes)
        self._add_shapes(Shapes.ellipsoids(centres, np.tile([a, b, c], (n, 1)), 1.0), material)

    def _add_shapes(self, shapes: Shapes, material: Material) -> None:
        self.shapes.append(dataclasses.replace(shapes, material=np.full(len(shapes), len(self.materials), np.int32)))
        self.materials.append(material)
        self.n_shapes += len(shapes)

    def add_base_plane(self, z: float, material: Material) -> None:
        """The plane at height ``z`` facing +z: two triangles covering the tile with a margin
        (BASE_MARGIN of each side beyond it); its size (the clearance's scale) is the longer side."""
        x0, x1 = -BASE_MARGIN * self.tile, (1.0 + BASE_MARGIN) * self.tile
        y0, y1 = -BASE_MARGIN * self.tile_y, (1.0 + BASE_MARGIN) * self.tile_y
        vertices = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], dtype=np.float32)
        faces = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)
        plane = Shapes.planes(np.array([[0.0, 0.0, z]]), np.array([[0.0, 0.0, 1.0]]),
                              size=max(self.tile, self.tile_y))
        self.base_material = len(self.materials)
        self.add(vertices, faces, np.zeros(2, np.int32), plane, material)

    def build(self, z_top: float, z_bottom: float, info: dict) -> Scene:
        faces = _joined(self.faces, np.zeros((0, 3), np.int32))
        return Scene(_joined(self.vertices, np.zeros((0, 3))), faces,
                     _joined(self.face_shape, np.zeros(0, np.int32)), Shapes.concatenate(self.shapes),
                     MaterialTable.of(self.materials), self.tile, z_top, z_bottom,
                     dict(info, triangles=int(len(faces))),
                     _joined(self.spheres, np.zeros((0, 4))),
                     _joined(self.sphere_shape, np.zeros(0, np.int32)), self.sphere_scale,
                     self.base_material, self.tile_y)


def _joined(parts: list, empty: np.ndarray) -> np.ndarray:
    """The parts one after the other (one part: itself, not copied; none: ``empty``)."""
    return parts[0] if len(parts) == 1 else np.concatenate(parts or [empty])
