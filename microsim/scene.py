"""What a generator hands the tracer: triangles for Embree plus the analytic data behind them.

The scene is periodic in x and y over the tile [0, L)^2 (shapes crossing the tile edge come
with their periodic images) and bounded in z: nothing can be hit above ``z_top``; a ray going
below ``z_bottom`` has left through the bottom of the slab (transmitted). Every triangle names
its analytic shape (``face_shape``); every shape names its material (an index into
``materials``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .materials import N_PARAMS, material_row
from .shapes import Shapes


@dataclass
class MaterialTable:
    """Kind codes and parameter rows of the materials a scene uses."""

    kind: np.ndarray  # (M,) int32
    params: np.ndarray  # (M, materials.N_PARAMS) float64

    @classmethod
    def from_specs(cls, specs: list[dict]) -> "MaterialTable":
        rows = [material_row(s) for s in specs]
        kind = np.array([r[0] for r in rows], dtype=np.int32)
        params = np.array([r[1] for r in rows], dtype=np.float64).reshape(len(rows), N_PARAMS)
        return cls(kind, params)


@dataclass
class Scene:
    """One realization of a microgeometry, ready to trace."""

    vertices: np.ndarray  # (V, 3) float32
    faces: np.ndarray  # (F, 3) int32, counter-clockwise seen from outside (normal points out)
    face_shape: np.ndarray  # (F,) int32
    shapes: Shapes
    materials: MaterialTable
    tile: float  # period L in x and y
    z_top: float
    z_bottom: float
    #: resolved parameters and measured properties, stored as the table's scene/ attrs
    info: dict = field(default_factory=dict)

    def __post_init__(self):
        self.vertices = np.ascontiguousarray(self.vertices, dtype=np.float32)
        self.faces = np.ascontiguousarray(self.faces, dtype=np.int32)
        self.face_shape = np.ascontiguousarray(self.face_shape, dtype=np.int32)
        if len(self.faces) != len(self.face_shape):
            raise ValueError("every face needs a shape")
        if len(self.faces) and self.face_shape.max() >= len(self.shapes):
            raise ValueError("face_shape refers to a missing shape")

    @property
    def n_triangles(self) -> int:
        return len(self.faces)

    def embree(self):
        """A committed Embree scene of the triangles (built in the process that traces)."""
        from embreex import mesh_construction, rtcore_scene

        scene = rtcore_scene.EmbreeScene()
        mesh_construction.TriangleMesh(scene, self.vertices, self.faces)
        probe = np.zeros((1, 3), np.float32)
        scene.run(probe, probe + np.float32([0, 0, 1]), dists=np.zeros(1, np.float32))  # commits the BVH
        return scene
