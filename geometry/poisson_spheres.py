"""Boolean model of spheres (docs/conventions.md §5.2): Poisson centres in the slab -depth <= z < 0.

The optional ``[base]`` plane lies under every sphere, at the lowest point any mesh can reach
(z = -depth - vertex radius): spheres rest above it and never cut it, so no hit point can be
projected to its far side (with flat shading, just under the realization's lowest vertex: below).

Spheres of radius r = 1 may overlap. Volume fraction phi = 1 - exp(-n 4/3 pi), so the number
density is n = -ln(1 - phi) / (4/3 pi) and the free path in the void is exponential with mean
l = 1 / (n pi) = 4 / (-3 ln(1 - phi)) (both from :mod:`microsim.physics.boolean_model`).

By default every sphere is exact: Embree's native sphere primitive (one x, y, z, r each),
which the direct Embree backend traces (``sphere_model = "exact"`` in the table). Given
``subdivisions`` or ``mesh_error``, each sphere is instead an icosphere rotated at random,
scaled so that its area is exactly 4 pi: by Cauchy's formula its mean projected area is then
pi, so the void free path keeps its exact mean l whatever the tessellation. The level is the
coarsest whose largest distance to the true sphere is within ``mesh_error`` (unless
``subdivisions`` is given); that distance is recorded. Hit points are projected onto the sphere
of the mesh's vertex radius and shaded with the exact sphere normal (``shading = "exact"``).
Both models draw the same centres for the same seed, so the two can be compared realization by
realization.

``shading = "flat"`` (icospheres only) lays the same icospheres as a user's periodic tile is laid
(:mod:`microsim.geometry.periodic_tile`): the realization's spheres, all with their centre in the tile,
are one :class:`~microsim.geometry.periodic_tile.Tile` of triangles, each its own flat facet (hits
projected onto its plane, shaded by its normal; ``"smooth"``: by its vertex normals
interpolated, as a smooth mesh is), with the copies of the triangles that reach into
the tile a period either way in place of the spheres' periodic images; paths start ``TOP_HEIGHT``
of the tile above the realization's highest vertex and a base lies ``BASE_GAP`` of it under its
lowest (``z_top``, ``z_bottom`` and ``base_z`` are therefore stored per realization, not among the
resolved parameters). :func:`export_tile` writes the same triangles to a PLY file, and scene
``mesh`` with ``period = tile`` and the same ``[base]`` then lays the same scene, array for array:
the same table, bit for bit (``tests/test_mesh_from_spheres.py``).

Defaults (every value used is recorded in the table's scene/ attrs):

- ``depth`` = tau l, the optical depth tau at which light diffusing in the slab is down by
  1e-3: tau = ln(1e3) / kappa, kappa the asymptotic decay rate in optical depth of a half
  space of isotropic scatterers with the particles' albedo c (root of c artanh(kappa) = kappa;
  the Lambert sphere's backward phase function decays faster, so this errs deep), capped at
  ``MAX_OPTICAL_DEPTH`` where c -> 1 allows no such depth. Single scattering (max_order = 1)
  needs only tau = ln(1e3), the depth at which the direct beam is down by 1e-3.
- ``tile`` = 64 r (``TILE``). Two conditions keep a periodic tile free of bias; the larger of
  the two is recorded as ``tile_bias_floor``, the shortest tile that meets both:
  - 3 l: a ray crosses a whole tile without a collision with probability below exp(-3);
  - 2 r / cos(theta_g), theta_g the run's largest incidence or 85 deg if that is larger (the
    grazing exits that count): a ray at theta_g that crosses a whole tile comes back at least a
    sphere diameter away from its own track, so the spheres it meets on its second pass are
    independent of those it missed on its first (the cylinders of radius r about the two passes
    do not overlap); a tile that broke it (16 r at phi = 0.3) made the grazing albedo 0.6 % too
    bright.
  64 r meets both for phi >= 0.061 and theta_g up to 88 deg. Below phi = 0.061 the tile is
  shorter than 3 l, and an outgoing ray can pass the periodic images of the spheres that shadow the
  incoming one ("ghost" shadow hiding, brightest for grazing pairs in the plane of a tile axis);
  at 64 r order-1 tables still agree with the finite-size model (``boolean_spheres_single``)
  down to phi = 0.005.
  A tile longer than the floor still pays: a realization averages over the whole tile, so the
  realization-to-realization spread falls as 1 / tile^2, while a path costs about the same (more
  paths do not lower that spread). Beyond 64 r the slab of a dilute or bright medium (up to 40
  free paths deep) would hold millions of spheres.

The rule that the defaults meet (checked by ``benchmarks/sphere_defaults.py``): the bias
of the albedo against a tile, or a depth, 4 times the default stays below 0.3 % (which is more
than a third of the standard error a default run of 1 M paths reaches). The exact spheres have no
tessellation bias. The depth's bias is bounded without a reference: the slab differs from the
half space only by the light that crosses its bottom, so it lowers the albedo by at most
``energy/transmitted``.

(measurements: docs/developer/performance.md, section 'Boolean spheres: tile and depth defaults')
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Literal

import numpy as np
import pydantic
import trimesh
from pydantic import Field
from scipy.optimize import brentq
from scipy.spatial.transform import Rotation

from microsim.core.schema import Section
from microsim.geometry import periodic_tile, sphere_cells, sphere_statistics, surface_statistics
from microsim.geometry.periodic_tile import Tile
from microsim.physics.boolean_model import free_path, number_density
from microsim.physics.rng import geometry_rng
from microsim.tracer.scene import Scene, SceneBuilder
from microsim.tracer.shapes import Shapes

KIND = "poisson_spheres"
INTEGRATOR = "surface"
#: a small whole run config of this kind, fixed seed (the generator protocol, geometry/__init__.py): what
#: the conformance test of every kind (tests/test_scene_kinds.py) and the CLI fuzzer start from
EXAMPLE = {"scene": {"kind": "poisson_spheres", "volume_fraction": 0.3, "tile": 8.0, "depth": 4.0,
                     "statistics": True, "statistics_rays": 1024},
           "material": {"kind": "lambert", "albedo": 0.8},
           "illumination": {"theta_i_deg": [0.0, 60.0]}, "sensor": {"cells": 24},
           "run": {"paths": 4000, "realizations": 4, "seed": 1}}
TRANSMISSION_TARGET = 1e-3
MAX_OPTICAL_DEPTH = 40.0
#: the default tile period, in radii (see the module doc)
TILE = 64.0
#: the shortest tile free of periodic bias spans this many free paths, and keeps the two passes of
#: a ray at GRAZING_DEG (or the run's largest incidence) a sphere diameter apart (module doc)
TILE_FREE_PATHS = 3.0
GRAZING_DEG = 85.0
MAX_SUBDIVISIONS = 6
#: the icosphere budget that stands in for exact spheres on the embreex backend
FALLBACK_MESH_ERROR = 0.01
#: the slab's top and bottom lie this far (radii) beyond the highest and lowest mesh point
SLAB_MARGIN = 1e-3


#: what ``scene.intersector`` defaults to for exact spheres (and grains): the grid traced spheres
#: 1.06-1.30 times as fast as Embree's native spheres a thread at phi 0.1-0.6, grains 1.31 times
#: (docs/developer/performance.md, "Sphere scenes: a grid walk against Embree" and "... re-measured")
DEFAULT_INTERSECTOR = "grid"
#: below this volume fraction exact spheres default to Embree: in a dilute suspension a segment
#: crosses many nearly empty cells, and the grid traced 0.71 times as fast as Embree at phi 0.01
#: (1.14 at 0.03, 1.00 at 0.05; the same page, "... re-measured")
GRID_FROM_VOLUME_FRACTION = 0.03


def intersector_key():
    """The ``intersector`` key of the scenes of spheres."""
    return Field(None, description="how rays meet exact spheres: grid (a walk over a uniform grid of cells, "
                 "float64 roots, no Embree scene) or embree (Embree's native spheres); default grid for exact "
                 "spheres from volume_fraction 0.03 up (embree below) and exact grains, embree for icospheres "
                 "(the only one they take)")


def check_intersector(scene) -> None:
    """ValueError, one line: the grid intersector asked for icospheres."""
    if scene.intersector == "grid" and not is_exact(scene):
        raise ValueError("scene.intersector = 'grid': for exact spheres only; drop subdivisions and mesh_error, "
                         "or give intersector = 'embree'")


def intersector(scene) -> str:
    """The intersector of a validated scene section of spheres (or grains): the given one, or the
    default for its spheres: the grid for exact ones, but for a suspension or packing more dilute
    than GRID_FROM_VOLUME_FRACTION; Embree for icospheres."""
    if scene.intersector:
        return scene.intersector
    dilute = getattr(scene, "volume_fraction", 1.0) < GRID_FROM_VOLUME_FRACTION
    return DEFAULT_INTERSECTOR if is_exact(scene) and not dilute else "embree"


class Config(Section):
    kind: Literal["poisson_spheres"]
    volume_fraction: float = Field(ge=0.001, le=0.9, description="phi of the Boolean model")
    depth: float | None = Field(None, gt=0.0, le=1e5, description="slab depth of the centres, in radii")
    tile: float | None = Field(None, ge=4.0, le=1e4, description="tile period, in radii")
    subdivisions: int | None = Field(None, ge=0, le=MAX_SUBDIVISIONS, description="icosphere level")
    mesh_error: float | None = Field(None, gt=0.0, le=0.5, description="largest mesh-to-sphere distance, in radii")
    shading: Literal["exact", "flat", "smooth"] = Field("exact", description="exact: hits shaded with the sphere's "
                                                        "normal; flat: each icosphere triangle with its own; smooth: "
                                                        "with its vertex normals interpolated (module doc)")
    intersector: Literal["grid", "embree"] | None = intersector_key()
    statistics: bool = sphere_statistics.statistics_key()
    statistics_rays: int | None = sphere_statistics.rays_key()

    @pydantic.model_validator(mode="after")
    def _rays_with_statistics(self):
        surface_statistics.check_keys(self)
        check_intersector(self)
        return self


#: a realization expects at least this many spheres (or grains): a Poisson count of 10 is 0 with
#: probability exp(-10) = 4.5e-5. A tile that expects 0.22 leaves 4 realizations of 5 empty, and
#: gives an albedo whose standard error is as large as the albedo
MIN_EXPECTED_OBJECTS = 10


def check(config) -> None:
    scene = config.scene
    if scene.subdivisions is not None and scene.mesh_error is not None:
        raise ValueError("scene.mesh_error: give either subdivisions or mesh_error, not both")
    if laid_as_tile(scene.shading) and is_exact(scene):
        raise ValueError(f"scene.shading = {scene.shading!r}: for icospheres only; give subdivisions or mesh_error")
    if scene.tile is not None or scene.depth is not None:
        resolved = resolve(config)
        if resolved["expected_spheres"] < MIN_EXPECTED_OBJECTS:
            given = ", ".join(f"scene.{key} = {resolved[key]:g}" for key in ("tile", "depth")
                              if getattr(scene, key) is not None)
            volume = MIN_EXPECTED_OBJECTS / resolved["number_density"]
            raise ValueError(f"{given}: {resolved['expected_spheres']:.3g} spheres expected a realization; accepted: "
                             f"at least {MIN_EXPECTED_OBJECTS} (tile^2 x depth >= {volume:.4g} radii^3 at "
                             f"volume_fraction {scene.volume_fraction:g})")


def for_backend(config, backend: str):
    """(config, note): the config as ``backend`` can trace it. The sphere grid walks exact spheres
    whichever backend is named (scene/intersector says so); Embree's native spheres, which the
    embreex backend cannot trace, become icospheres there."""
    return spheres_for_backend(config, backend)


def spheres_for_backend(config, backend: str, what: str = "spheres"):
    """:func:`for_backend` of the scenes of spheres (or grains: ``what``) that take ``intersector``."""
    if intersector(config.scene) == "grid":
        return config, ""
    return meshed_on_embreex(config, backend, what)


def meshed_on_embreex(config, backend: str, what: str):
    """(config, note): on the embreex backend, which traces triangles only, a scene of exact native
    spheres (``is_exact``) is given ``mesh_error = FALLBACK_MESH_ERROR``, and the note says so; on
    the direct backend the config is traced as it is. Shared by the scenes made of spheres."""
    if backend == "embreex" and is_exact(config.scene):
        meshed = config.scene.model_copy(update={"mesh_error": FALLBACK_MESH_ERROR})
        return (config.model_copy(update={"scene": meshed}),
                f"exact {what} traced as icospheres within mesh_error {FALLBACK_MESH_ERROR} (embreex traces triangles)")
    return config, ""


def is_exact(scene) -> bool:
    """Whether the spheres (or grains) are Embree's exact native spheres (no tessellation asked for)."""
    return scene.subdivisions is None and scene.mesh_error is None


def diffusion_decay(c: float) -> float:
    """kappa in (0, 1]: c artanh(kappa) / kappa = 1, decay rate of diffuse light in optical depth."""
    if c <= 1e-12:
        return 1.0
    if c >= 1.0:
        return 0.0
    return brentq(lambda k: c * math.atanh(k) - k, 1e-15, 1.0 - 1e-16)


def default_optical_depth(c: float, max_order: int) -> float:
    """Optical depth of the slab so that at most TRANSMISSION_TARGET of the light gets through."""
    direct = math.log(1.0 / TRANSMISSION_TARGET)
    if max_order == 1:
        return direct
    kappa = diffusion_decay(c)
    if kappa * MAX_OPTICAL_DEPTH <= direct:
        return MAX_OPTICAL_DEPTH
    return direct / kappa


def tile_bias_floor(free_path_length: float, theta_max_deg: float) -> float:
    """The shortest tile free of periodic bias, in radii (module doc): 3 free paths, and a sphere
    diameter between the passes of a ray at the grazing angle."""
    grazing = math.radians(max(GRAZING_DEG, theta_max_deg))
    return max(TILE_FREE_PATHS * free_path_length, 2.0 / math.cos(grazing))


@lru_cache(maxsize=None)
def unit_icosphere(level: int):
    """Icosphere of area 4 pi: (vertices, faces, vertex radius, largest distance to the unit sphere)."""
    mesh = trimesh.creation.icosphere(subdivisions=level)
    v = mesh.vertices / np.linalg.norm(mesh.vertices, axis=1)[:, None]
    f = mesh.faces.astype(np.int32)
    cross = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    area = 0.5 * np.linalg.norm(cross, axis=1).sum()
    scale = math.sqrt(4.0 * math.pi / area)
    normals = cross / np.linalg.norm(cross, axis=1)[:, None]
    nearest = scale * np.einsum("ij,ij->i", normals, v[f[:, 0]]).min()  # closest face plane
    return v * scale, f, scale, max(scale - 1.0, 1.0 - nearest)


def level_for(mesh_error: float) -> int:
    for level in range(MAX_SUBDIVISIONS + 1):
        if unit_icosphere(level)[3] <= mesh_error:
            return level
    return MAX_SUBDIVISIONS


#: memory per sphere once built: shape rows and Embree's copy and BVH (exact), or per triangle of
#: an icosphere (vertices, faces, Embree's copy and BVH). Measured peaks (benchmarks/memory.py,
#: build included): 140 B a triangle on the direct backend (phi 0.1-0.6, levels 1-3), 142-165 B
#: on embreex (levels 3 and 2); 180 B keeps a margin without refusing scenes that fit
EXACT_SPHERE_BYTES, TRIANGLE_BYTES = 300, 180
#: a flat-shaded icosphere triangle, laid as every periodic tile's (a facet of its own, and
#: periodic_tile.build's float64 corners and copies while it is laid): peak resident memory rose
#: 654 B a triangle from level 2 to level 3 (phi 0.3, tile 32, depth 10; 202 B with exact shading)
FLAT_TRIANGLE_BYTES = 700


def scene_bytes(resolved: dict) -> int:
    """Expected spheres (with 6 standard deviations of Poisson spread) times their size."""
    n = resolved["expected_spheres"]
    spheres = n + 6.0 * math.sqrt(n) + 1.0
    triangle = TRIANGLE_BYTES
    if laid_as_tile(resolved["shading"]):
        triangle = FLAT_TRIANGLE_BYTES + periodic_tile.triangle_bytes(resolved) - periodic_tile.TRIANGLE_BYTES
    per_sphere = resolved["triangles_per_sphere"] * triangle or EXACT_SPHERE_BYTES
    return int(spheres * per_sphere)


def slab(config, free_path_length: float) -> dict:
    """The slab's resolved parameters of a scene of spheres of void free path ``free_path_length``:
    the free path, the albedo the defaults assume, the depth and the tile (given or defaulted,
    module doc) and the tile's bias floor."""
    scene = config.scene
    c = config.material.albedo_bound()
    tau = default_optical_depth(c, config.run.max_order)
    depth = scene.depth if scene.depth is not None else tau * free_path_length
    return {
        "free_path": free_path_length,
        "particle_albedo_estimate": c,
        "depth": depth,
        "depth_default": scene.depth is None,
        "optical_depth": depth / free_path_length,
        "tile": scene.tile if scene.tile is not None else TILE,
        "tile_default": scene.tile is None,
        "tile_bias_floor": tile_bias_floor(free_path_length, max(config.illumination.theta_i_deg)),
    }


def resolve(config) -> dict:
    scene = config.scene
    phi = scene.volume_fraction
    n = number_density(phi)
    extent = slab(config, free_path(phi))
    depth, tile = extent["depth"], extent["tile"]
    if is_exact(scene):
        model = {"sphere_model": "exact", "triangles_per_sphere": 0, "vertex_radius": 1.0, "max_mesh_error": 0.0}
    else:
        level = scene.subdivisions if scene.subdivisions is not None else level_for(scene.mesh_error)
        _, faces, vertex_radius, error = unit_icosphere(level)
        model = {"sphere_model": "icosphere", "subdivisions": level, "triangles_per_sphere": len(faces),
                 "vertex_radius": vertex_radius, "max_mesh_error": error}
    model["intersector"] = intersector(scene)
    vertex_radius = model["vertex_radius"]
    # flat: the heights are the realization's tile's (module doc), stored per realization
    heights = {} if laid_as_tile(scene.shading) else {"base_z": -depth - vertex_radius,
                                                      "z_top": vertex_radius + SLAB_MARGIN,
                                                      "z_bottom": -depth - vertex_radius - SLAB_MARGIN}
    return {
        "kind": KIND,
        "volume_fraction": phi,
        "number_density": n,
        **extent,
        **model,
        "shading": scene.shading,
        "expected_spheres": n * tile * tile * depth,
        "base": config.base.kind if config.base is not None else "none",
        **heights,
        **sphere_statistics.resolve(config, (tile, tile, depth), extent["free_path"]),
    }


def periodic_images(centres: np.ndarray, tile: float, reach: float):
    """Centres plus their images shifted by +-tile that reach into the tile; index of each source."""
    all_centres, source = [centres], [np.arange(len(centres))]
    for sx in (-1, 0, 1):
        for sy in (-1, 0, 1):
            if sx == 0 and sy == 0:
                continue
            shifted = centres + np.array([sx * tile, sy * tile, 0.0])
            inside = (
                (shifted[:, 0] > -reach) & (shifted[:, 0] < tile + reach)
                & (shifted[:, 1] > -reach) & (shifted[:, 1] < tile + reach)
            )
            all_centres.append(shifted[inside])
            source.append(np.nonzero(inside)[0])
    return np.concatenate(all_centres), np.concatenate(source)


def laid_as_tile(shading: str) -> bool:
    """Flat and smooth shading lay the icospheres as a periodic tile (module doc)."""
    return shading in ("flat", "smooth")


def draw(resolved: dict, rng: np.random.Generator):
    """One realization's spheres, drawn from ``rng`` as every realization is: the Poisson count,
    the centres (count, 3), uniform in the tile and the slab, then (icospheres) the rotations
    (count, 3, 3), uniformly random; None for exact spheres, which draw none."""
    tile, depth = resolved["tile"], resolved["depth"]
    count = rng.poisson(resolved["number_density"] * tile * tile * depth)
    centres = rng.uniform((0.0, 0.0, -depth), (tile, tile, 0.0), size=(count, 3))
    if resolved["sphere_model"] == "exact":
        return centres, None
    return centres, Rotation.random(count, random_state=rng).as_matrix() if count else np.zeros((0, 3, 3))


def generate(resolved: dict, config, rng: np.random.Generator) -> Scene:
    centres, rotations = draw(resolved, rng)
    count = len(centres)
    if laid_as_tile(resolved["shading"]):
        tile = tile_of(resolved, centres, rotations)
        own = periodic_tile.summary(tile)
        heights = {key: own[key] for key in ("z_top", "z_bottom", "base_z")}
        scene = periodic_tile.build(tile, {**heights, "shading": resolved["shading"]}, config.material, config.base)
        scene.info = dict(resolved, spheres=int(count), **heights, **scene.info)
        return sphere_statistics.add(scene, centres, 1.0, resolved, config, rng)
    all_centres, source = periodic_images(centres, resolved["tile"], resolved["vertex_radius"])
    builder = SceneBuilder(resolved["tile"])
    if resolved["sphere_model"] == "exact":
        builder.add_spheres(all_centres, 1.0, config.material)
    else:
        add_icospheres(builder, all_centres, rotations[source], resolved["subdivisions"], config.material)
    if config.base is not None:
        builder.add_base_plane(resolved["base_z"], config.base)
    info = dict(resolved, spheres=int(count), sphere_images=int(len(all_centres) - count))
    scene = with_cells(builder.build(resolved["z_top"], resolved["z_bottom"], info), resolved)
    return sphere_statistics.add(scene, centres, 1.0, resolved, config, rng)


def with_cells(scene: Scene, resolved: dict) -> Scene:
    """``scene``, with the cells the sphere grid walks (:mod:`microsim.geometry.sphere_cells`) where
    its ``intersector`` is the grid."""
    if resolved.get("intersector") == "grid":
        scene.grid = sphere_cells.build(scene, sphere_cells.void_side(scene, resolved["free_path"]))
    return scene


def icospheres(centres, rotations, level: int, radii=1.0):
    """(vertices (V, 3) float64, faces (F, 3)): the icospheres of area 4 pi r^2 of ``level`` rotated
    by ``rotations`` about ``centres`` (radii r: one, or one a sphere), one after the other, as
    every icosphere scene lays them."""
    vertices0, faces0, _, _ = unit_icosphere(level)
    scale = np.broadcast_to(np.asarray(radii, np.float64), (len(centres),))[:, None, None]
    vertices = scale * np.einsum("sij,vj->svi", rotations, vertices0) + centres[:, None, :]
    faces = faces0[None, :, :] + (np.arange(len(centres)) * len(vertices0))[:, None, None]
    return vertices.reshape(-1, 3), faces.reshape(-1, 3)


def add_icospheres(builder: SceneBuilder, centres, rotations, level: int, material, radii=1.0) -> None:
    """Rotated icospheres of area 4 pi r^2 about ``centres`` (radii r: one, or one a sphere),
    shaded as spheres of the vertex radius (times r)."""
    _, faces0, vertex_radius, _ = unit_icosphere(level)
    vertices, faces = icospheres(centres, rotations, level, radii)
    face_shape = np.repeat(np.arange(len(centres), dtype=np.int32), len(faces0))
    radii = np.broadcast_to(np.asarray(radii, np.float64), (len(centres),))
    builder.add(vertices, faces, face_shape, Shapes.spheres(centres, radii, vertex_radius * radii), material)


def tile_of(resolved: dict, centres, rotations) -> Tile:
    """The icospheres about ``centres`` (all in the tile) as one periodic tile of triangles, the
    tile at [0, tile)^2 (spheres crossing a side reach beyond it): what ``shading = "flat"`` lays
    and :func:`export_tile` writes."""
    vertices, faces = icospheres(centres, rotations, resolved["subdivisions"])
    return Tile.of(vertices, faces, resolved["tile"])


def export_tile(config, path, realization: int = 0) -> dict:
    """Write realization ``realization`` of the validated ``config`` (icospheres) to the PLY file
    ``path``: its spheres, every one with its centre in the tile, as the icosphere triangles it
    lays (:func:`tile_of`: the vertices in float64 as laid, the faces in order; :func:`write_ply`);
    returns the ``[scene]`` section of scene ``mesh`` that traces them as ``shading = "flat"``
    (or ``"smooth"``, the config's where it is smooth) does (``period`` = the tile; give it the
    same ``[base]``). The realization is drawn as a run
    draws it (``geometry_rng(run.seed, realization)``). ValueError, one line, for exact spheres."""
    if is_exact(config.scene):
        raise ValueError("scene.subdivisions: export_tile writes icospheres; give subdivisions or mesh_error")
    resolved = resolve(config)
    tile = tile_of(resolved, *draw(resolved, geometry_rng(config.run.seed, realization)))
    write_ply(path, tile.vertices, tile.faces, f"microsim poisson_spheres realization {realization} of seed "
                                               f"{config.run.seed}, tile {resolved['tile']:g}")
    shading = "smooth" if resolved["shading"] == "smooth" else "flat"
    return {"kind": "mesh", "path": str(path), "period": resolved["tile"], "shading": shading}


def write_ply(path, vertices, faces, comment: str = "") -> None:
    """Binary PLY of ``vertices`` (V, 3) as doubles and triangles ``faces`` (F, 3): trimesh's PLY
    writer stores float32, whose rounding would move the facets' planes; trimesh reads doubles
    back exactly."""
    header = ("ply\nformat binary_little_endian 1.0\n" + (f"comment {comment}\n" if comment else "")
              + f"element vertex {len(vertices)}\nproperty double x\nproperty double y\nproperty double z\n"
              f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n")
    packed = np.zeros(len(faces), dtype=[("count", "u1"), ("index", "<i4", (3,))])
    packed["count"], packed["index"] = 3, faces
    with open(path, "wb") as file:
        file.write(header.encode("ascii"))
        file.write(np.ascontiguousarray(vertices, "<f8").tobytes())
        file.write(packed.tobytes())
