"""Micrograin fields (docs/conventions.md §5.3): half-ellipsoid grains on a base plane, a Boolean model.

Grains are the upper halves of ellipsoids of vertical semi-axis 1 and lateral semi-axes
1/beta_x, 1/beta_y (aligned with x and y), with centres a Poisson process on the base plane z = 0
of density rho = lambda beta_x beta_y / pi, lambda = -ln(1 - tau0), so that a fraction tau0 of
the base is covered (Lucas et al. 2024, Eq. 8-9; the relations are in
:mod:`microsim.physics.boolean_model`, shared with the ``micrograin`` model). Grains overlap freely. The
grains are made of ``[material]``, the plane of ``[base]`` (default: an absorber).

Exact grains (the default). Every grain is the same ellipsoid, so the map (x, y, z) ->
(beta_x x, beta_y y, z) takes the field onto unit spheres centred on the plane: the grains are
Embree's native spheres in that frame, traced through an instance that maps it back
(:class:`microsim.tracer.embree.Scene`; the ray parameter t is the same in both frames, and normals go
back by the inverse transpose). The lower halves of the spheres lie under the base plane, where
no ray goes. Hit points are projected onto the ellipsoid and shaded with its exact normal
(:func:`microsim.tracer.shapes.surface_point`). ``sphere_model = "exact"``, ``max_mesh_error = 0``.

Tessellated grains (``subdivisions`` or ``mesh_error``, and on the embreex backend, which traces
triangles only). Each grain is an icosphere of the level whose largest distance to the unit
sphere is within ``mesh_error`` (0.01 on embreex), measured in the grain's own frame, where the
grain is the unit sphere whatever beta: so the budget means the same for very flat (beta = 0.05)
and very tall (beta = 5) grains, in units of the local semi-axes. The icosphere is scaled by
(1/beta_x, 1/beta_y, 1); only its faces that reach above the base are kept. Hit points are
projected onto the ellipsoid of the mesh's vertex radius, as for meshed spheres.

Tile. A square of side L, periodic in x and y. The default is
L = max(TILE_FACTOR (tan(theta_max) + tan(GRAZING_DEG) + 4 a), FOOTPRINTS x 2 a, sqrt(10 / rho)), with
a = max(1/beta_x, 1/beta_y) the largest lateral semi-axis and theta_max the largest incidence of
the run (at least GRAZING_DEG = 86 deg). A ray entering the layer (z <= 1) at theta_i travels at
most tan(theta_i) horizontally before it reaches the base, and one leaving at theta_o at most
tan(theta_o): with L above their sum plus a grain width at each end, no single-scattering path
can meet the periodic image of a grain that shadows its incoming ray ("ghost" shadow hiding,
which a small tile brings at grazing angles, as measured for the sphere tile). TILE_FACTOR = 2
takes that guarantee from theta_o = 86 deg to 88.8 deg (the sensor's last ring reaches 90), and
it puts 4 times more grains in each realization: at grazing incidence the light that reaches
the base, or comes back near retro, passes a few gaps between grains, so the per-realization
estimates are skewed, and the larger the tile the closer their mean is to normal (a tile below
the no-ghost reach raised chi^2 per cell against the model at 86 deg). The footprint term
keeps FOOTPRINTS grain widths in a tile of very flat grains, and the last term 10 grains expected
in a sparse field (tau0 below about 0.03: a tile of fewer is often empty; a given tile that
expects fewer is refused). The reach uses theta_max up to
MAX_REACH_DEG = 89.5 deg, and the default tile never holds more than MAX_DEFAULT_GRAINS grains
(dense fields of tall grains at the most grazing incidences: light does not get far in them;
``tile_grain_budget`` in the table says when the budget set the tile).
A larger tile is not free: the offsets that keep scattered rays off their own grain grow with
the float32 spacing of the coordinates (microsim/tracer/integrators/surface_transport.py), and where
grains overlap an origin offset past a seam starts inside the neighbour (an "inside hit", passed
through and counted; the rate grows with the tile, and stays below 1e-4 of the segments in the
default tile of the most extreme field, tests/test_micrograins.py). A path that passes into a
grain that way may reach the base under it, and is then tallied as scattered by the base: the
base term carries that error, bounded by the inside-hit rate. The ratio beta_x / beta_y is kept
within [1/MAX_ANISOTROPY, MAX_ANISOTROPY] for that reason (at 1/1000 the inside hits reached
4e-3). Grains are cheap (one native sphere each; 1000 a realization at tau0 = 0.5, beta = 1).
Every value used is recorded in the table's scene/ attrs.

(measurements: docs/developer/performance.md, section 'Micrograin fields: tile size and inside hits')
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
import pydantic
from pydantic import Field

from microsim.core.schema import Section
from microsim.geometry import sphere_cells
from microsim.geometry.poisson_spheres import (
    EXACT_SPHERE_BYTES,
    MAX_SUBDIVISIONS,
    MIN_EXPECTED_OBJECTS,
    TRIANGLE_BYTES,
    check_intersector,
    intersector,
    intersector_key,
    is_exact,
    level_for,
    periodic_images,
    spheres_for_backend,
    unit_icosphere,
)
from microsim.physics.boolean_model import grain_density, grain_extinction
from microsim.tracer.materials import Absorber
from microsim.tracer.scene import Scene, SceneBuilder
from microsim.tracer.shapes import Shapes

KIND = "micrograins"
INTEGRATOR = "surface"
#: a small whole run config of this kind, fixed seed (the generator protocol, geometry/__init__.py): what
#: the conformance test of every kind (tests/test_scene_kinds.py) and the CLI fuzzer start from
EXAMPLE = {"scene": {"kind": "micrograins", "tau0": 0.5, "beta": 1.0, "tile": 7.0},
           "material": {"kind": "conductor", "eta": 1.0152, "k": 6.6273}, "base": {"kind": "lambert", "albedo": 0.5},
           "illumination": {"theta_i_deg": [0.0, 60.0]}, "sensor": {"cells": 24},
           "run": {"paths": 4000, "realizations": 4, "seed": 1}}
#: the tile keeps single-scattering paths up to this angle from meeting periodic images, TILE_FACTOR
#: times over (module doc)
GRAZING_DEG = 86.0
TILE_FACTOR = 2.0
#: the tile holds at least this many grain widths
FOOTPRINTS = 16.0
#: the reach term stops growing at this incidence, and the default tile at this many grains
#: (about 600 MB for Embree)
MAX_REACH_DEG = 89.5
MAX_DEFAULT_GRAINS = 2_000_000
BETA_RANGE = (0.01, 10.0)
#: the largest beta_x / beta_y (or its inverse): the tested extreme (module doc)
MAX_ANISOTROPY = 40.0
#: the slab's top lies this far above the grain tips; its bottom this far under the base
SLAB_MARGIN = 1e-3
#: an icosphere face is kept if a vertex lies above this height (unit frame)
KEEP_ABOVE = -1e-9


class Config(Section):
    kind: Literal["micrograins"]
    tau0: float = Field(gt=0.0, le=0.999, description="fraction of the base covered by grains (Eq. 8)")
    beta: float | None = Field(None, ge=BETA_RANGE[0], le=BETA_RANGE[1],
                               description="grain height / lateral semi-axis (sets beta_x = beta_y)")
    beta_x: float | None = Field(None, ge=BETA_RANGE[0], le=BETA_RANGE[1], description="height / semi-axis along x")
    beta_y: float | None = Field(None, ge=BETA_RANGE[0], le=BETA_RANGE[1], description="height / semi-axis along y")
    tile: float | None = Field(None, ge=1.0, le=1e4, description="tile period, in grain heights")
    subdivisions: int | None = Field(None, ge=0, le=MAX_SUBDIVISIONS, description="icosphere level of each grain")
    mesh_error: float | None = Field(None, gt=0.0, le=0.5,
                                     description="largest mesh-to-grain distance, in the grain's own frame")
    intersector: Literal["grid", "embree"] | None = intersector_key()

    @pydantic.model_validator(mode="after")
    def _one_beta(self):
        check_intersector(self)
        given = [key for key in ("beta_x", "beta_y") if getattr(self, key) is not None]
        if self.beta is not None and given:
            raise ValueError(f"scene.beta: give either beta or beta_x + beta_y, not both (got beta and {given[0]})")
        if self.beta is None and len(given) != 2:
            raise ValueError("scene.beta: missing; give beta, or beta_x and beta_y, each in "
                             f"[{BETA_RANGE[0]:g}, {BETA_RANGE[1]:g}]")
        if self.beta is None and max(self.beta_x / self.beta_y, self.beta_y / self.beta_x) > MAX_ANISOTROPY:
            raise ValueError(f"scene.beta_x / scene.beta_y = {self.beta_x / self.beta_y:g}: out of range; accepted: "
                             f"[1/{MAX_ANISOTROPY:g}, {MAX_ANISOTROPY:g}]")
        return self

    @property
    def betas(self) -> tuple[float, float]:
        return (self.beta, self.beta) if self.beta is not None else (self.beta_x, self.beta_y)


def check(config) -> None:
    scene = config.scene
    if scene.subdivisions is not None and scene.mesh_error is not None:
        raise ValueError("scene.mesh_error: give either subdivisions or mesh_error, not both")
    if scene.tile is not None:
        density = grain_density(scene.tau0, *scene.betas)
        if (expected := density * scene.tile**2) < MIN_EXPECTED_OBJECTS:
            raise ValueError(f"scene.tile = {scene.tile:g}: {expected:.3g} grains expected a tile (tau0 {scene.tau0:g}); "
                             f"accepted: at least {MIN_EXPECTED_OBJECTS} (a tile of "
                             f"{math.sqrt(MIN_EXPECTED_OBJECTS / density):.4g} or more)")


def for_backend(config, backend: str):
    """(config, note): the config as ``backend`` can trace it: the sphere grid walks exact grains
    on either; with ``intersector = "embree"`` they are native spheres in a scaled frame, which
    the embreex backend cannot trace: there they become icospheres."""
    return spheres_for_backend(config, backend, "grains")


def default_tile(beta_x: float, beta_y: float, theta_max_deg: float, density: float) -> tuple[float, bool]:
    """The default tile side (see the module doc), and whether the grain budget set it."""
    a = max(1.0 / beta_x, 1.0 / beta_y)
    angle = min(max(theta_max_deg, GRAZING_DEG), MAX_REACH_DEG)
    reach = math.tan(math.radians(angle)) + math.tan(math.radians(GRAZING_DEG))
    tile = max(TILE_FACTOR * (reach + 4.0 * a), FOOTPRINTS * 2.0 * a, math.sqrt(MIN_EXPECTED_OBJECTS / density))
    budget = math.sqrt(MAX_DEFAULT_GRAINS / density)
    if tile > budget and budget > FOOTPRINTS * 2.0 * a:
        return budget, True
    return tile, False


def resolve(config) -> dict:
    scene = config.scene
    beta_x, beta_y = scene.betas
    theta_max = max(config.illumination.theta_i_deg)
    rho = grain_density(scene.tau0, beta_x, beta_y)
    tile, budget = (scene.tile, False) if scene.tile is not None else default_tile(beta_x, beta_y, theta_max, rho)
    if is_exact(scene):
        model = {"grain_model": "exact", "triangles_per_grain": 0, "vertex_radius": 1.0, "max_mesh_error": 0.0}
    else:
        level = scene.subdivisions if scene.subdivisions is not None else level_for(scene.mesh_error)
        vertices, faces, vertex_radius, error = unit_icosphere(level)
        model = {"grain_model": "icosphere", "subdivisions": level, "triangles_per_grain": len(_upper_faces(level)),
                 "vertex_radius": vertex_radius, "max_mesh_error": error}
    return {
        "kind": KIND,
        "tau0": scene.tau0,
        "beta_x": beta_x,
        "beta_y": beta_y,
        "grain_extinction": grain_extinction(scene.tau0),
        "grain_density": rho,
        "tile": tile,
        "tile_default": scene.tile is None,
        "tile_grazing_deg": min(max(theta_max, GRAZING_DEG), MAX_REACH_DEG),
        "tile_grain_budget": budget,
        **model,
        "expected_grains": rho * tile * tile,
        "base": config.base.kind if config.base is not None else "absorber",
        "z_top": model["vertex_radius"] + SLAB_MARGIN,
        "z_bottom": -SLAB_MARGIN,
        "intersector": intersector(scene),
    }


def scene_bytes(resolved: dict) -> int:
    """Expected grains and their images (6 standard deviations of Poisson spread) times their size."""
    a = max(1.0 / resolved["beta_x"], 1.0 / resolved["beta_y"]) * resolved["vertex_radius"]
    n = resolved["grain_density"] * (resolved["tile"] + 2.0 * a) ** 2
    grains = n + 6.0 * math.sqrt(n) + 1.0
    return int(grains * (resolved["triangles_per_grain"] * TRIANGLE_BYTES or EXACT_SPHERE_BYTES))


def generate(resolved: dict, config, rng: np.random.Generator) -> Scene:
    tile = resolved["tile"]
    beta_x, beta_y = resolved["beta_x"], resolved["beta_y"]
    count = rng.poisson(resolved["grain_density"] * tile * tile)
    centres = np.column_stack([rng.uniform(0.0, tile, size=(count, 2)), np.zeros(count)])
    reach = max(1.0 / beta_x, 1.0 / beta_y) * resolved["vertex_radius"]
    all_centres, _ = periodic_images(centres, tile, reach)
    builder = SceneBuilder(tile)
    semi_axes = (1.0 / beta_x, 1.0 / beta_y, 1.0)
    if resolved["grain_model"] == "exact":
        builder.add_ellipsoids(all_centres, semi_axes, config.material)
    else:
        add_meshed_grains(builder, all_centres, semi_axes, resolved["subdivisions"], config.material)
    builder.add_base_plane(0.0, config.base if config.base is not None else Absorber(kind="absorber"))
    info = dict(resolved, grains=int(count), grain_images=int(len(all_centres) - count))
    scene = builder.build(resolved["z_top"], resolved["z_bottom"], info)
    if resolved["intersector"] == "grid":
        scene.grid = sphere_cells.build(scene, sphere_cells.GRAIN_SIDE)
    return scene


def _upper_faces(level: int) -> np.ndarray:
    """The faces of the level's icosphere that reach above the base plane."""
    vertices, faces, _, _ = unit_icosphere(level)
    return faces[(vertices[faces][:, :, 2] > KEEP_ABOVE).any(axis=1)]


def add_meshed_grains(builder: SceneBuilder, centres, semi_axes, level: int, material) -> None:
    """Upper halves of icospheres scaled by ``semi_axes`` about ``centres``, shaded as ellipsoids."""
    vertices0, _, vertex_radius, _ = unit_icosphere(level)
    faces0 = _upper_faces(level)
    n = len(centres)
    vertices = vertices0[None, :, :] * np.asarray(semi_axes)[None, None, :] + centres[:, None, :]
    faces = faces0[None, :, :] + (np.arange(n) * len(vertices0))[:, None, None]
    face_shape = np.repeat(np.arange(n, dtype=np.int32), len(faces0))
    builder.add(vertices.reshape(-1, 3), faces.reshape(-1, 3), face_shape,
                Shapes.ellipsoids(centres, np.tile(semi_axes, (n, 1)), vertex_radius), material)
