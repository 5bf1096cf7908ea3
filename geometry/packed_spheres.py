"""Packed spheres: a hard-sphere packing (no two spheres overlap) in the slab -depth <= z < 0.

The packing (:mod:`microsim.geometry.packings`) fills a box periodic in x, y and z of the tile's
period and the slab's depth: its top, the plane z = 0, is a plane cut through the bulk packing,
and the spheres are those whose centres lie below it, as the Boolean scene's are
(:mod:`microsim.geometry.poisson_spheres`). Laterally the spheres' periodic images fill the tile's
neighbours; in depth the box is not repeated (the slab is as deep as the box).

Radii: 1 (``radius_sigma = 0``), or lognormal of mean 1 and shape ``radius_sigma``,
r = exp(sigma z - sigma^2 / 2) with z a standard normal clipped at 4 (every value used is
recorded). The count is the volume fraction's: n = phi tile^2 depth / (4/3 pi E[r^3]),
E[r^3] = exp(3 sigma^2); the packer scales the radii by one common factor to the volume fraction
exactly (``mean_radius`` records it per realization; with few spheres it is not 1: 1.006 for the
24 of ``EXAMPLE``), so the slab's top ``z_top``, its bottom and the base lie ``SLAB_MARGIN``
beyond each realization's largest sphere, stored per realization.

Defaults, by the Boolean scene's rules with a packing's free path: the mean chord of the void
of any two-phase medium is 4 (1 - phi) / S_v, S_v = 3 phi E[r^2] / E[r^3] the spheres' area per
volume, so l = 4 (1 - phi) exp(2 sigma^2) / (3 phi) (Boolean spheres: 4 / (-3 ln(1 - phi)), the
same to first order in phi); ``depth`` = tau l, tau as the Boolean scene's; ``tile`` = 64 radii.

By default the spheres are exact (Embree's native spheres), traced by the direct backend. Given
``subdivisions`` or ``mesh_error``, or on the embreex backend (which traces triangles only:
``mesh_error`` FALLBACK_MESH_ERROR, said in the table), each sphere is an icosphere rotated at
random, scaled to its sphere's area 4 pi r^2 (the mean chord stays exact, by Cauchy's formula),
its hits projected onto the sphere of the mesh's vertex radius and shaded with the sphere's
normal, as the Boolean scene's icospheres are; the rotations are drawn after the packing, so
both models pack the same spheres for the same seed. An icosphere's vertices lie outside its
sphere (by max_mesh_error at most, in its radii), so the meshes of spheres in contact overlap
there, as a Boolean scene's spheres do: the tracer passes through the back faces it meets.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Literal

import numpy as np
import pydantic
from pydantic import Field
from scipy.spatial.transform import Rotation

from microsim.core.schema import Section
from microsim.geometry import packings, sphere_statistics, surface_statistics
from microsim.geometry.poisson_spheres import (
    EXACT_SPHERE_BYTES,
    MAX_SUBDIVISIONS,
    MIN_EXPECTED_OBJECTS,
    SLAB_MARGIN,
    TRIANGLE_BYTES,
    add_icospheres,
    check_intersector,
    intersector,
    intersector_key,
    is_exact,
    level_for,
    periodic_images,
    slab,
    spheres_for_backend,
    unit_icosphere,
    with_cells,
)
from microsim.tracer.scene import Scene, SceneBuilder

KIND = "packed_spheres"
INTEGRATOR = "surface"
#: a small whole run config of this kind, fixed seed (the generator protocol, geometry/__init__.py)
EXAMPLE = {"scene": {"kind": "packed_spheres", "volume_fraction": 0.4, "tile": 8.0, "depth": 4.0,
                     "statistics": True, "statistics_rays": 1024},
           "material": {"kind": "lambert", "albedo": 0.8},
           "illumination": {"theta_i_deg": [0.0, 60.0]}, "sensor": {"cells": 24},
           "run": {"paths": 4000, "realizations": 4, "seed": 1}}
#: the largest volume fraction the packer reaches for every size distribution here (equal spheres
#: jam at 0.634-0.650 at its growth rate; a margin keeps every realization short of jamming)
MAX_VOLUME_FRACTION = 0.62
#: the widest lognormal size distribution
MAX_SIGMA = 0.5
#: lognormal radii are clipped at this many standard deviations of their logarithm
CLIP = 4.0
#: the tile spans at least this many of the largest sphere's diameters
MIN_TILE_DIAMETERS = 4.0
#: the largest packing a realization generates
MAX_SPHERES = 200_000


class Config(Section):
    kind: Literal["packed_spheres"]
    volume_fraction: float = Field(ge=0.01, le=MAX_VOLUME_FRACTION, description="phi of the packing (the packer's "
                                   f"reach: {MAX_VOLUME_FRACTION})")
    radius_sigma: float = Field(0.0, ge=0.0, le=MAX_SIGMA, description="shape sigma of the lognormal radii of mean "
                                "1 (0: equal spheres)")
    depth: float | None = Field(None, gt=0.0, le=1e5, description="slab depth of the centres, in radii")
    tile: float | None = Field(None, ge=4.0, le=1e4, description="tile period, in radii")
    cache: str | None = Field(None, description="directory of generated packings (default: $MICROSIM_CACHE/packings, "
                              "else ~/.cache/microsim/packings)")
    subdivisions: int | None = Field(None, ge=0, le=MAX_SUBDIVISIONS, description="icosphere level")
    mesh_error: float | None = Field(None, gt=0.0, le=0.5, description="largest mesh-to-sphere distance, in the "
                                     "sphere's radii")
    intersector: Literal["grid", "embree"] | None = intersector_key()
    statistics: bool = sphere_statistics.statistics_key()
    statistics_rays: int | None = sphere_statistics.rays_key()

    @pydantic.model_validator(mode="after")
    def _rays_with_statistics(self):
        surface_statistics.check_keys(self)
        check_intersector(self)
        return self


def largest_radius(sigma: float) -> float:
    """The largest radius drawn: exp(CLIP sigma - sigma^2 / 2)."""
    return math.exp(CLIP * sigma - 0.5 * sigma * sigma)


def check(config) -> None:
    scene = config.scene
    if scene.subdivisions is not None and scene.mesh_error is not None:
        raise ValueError("scene.subdivisions, scene.mesh_error: give one of them, not both")
    resolved = resolve(config)
    smallest = MIN_TILE_DIAMETERS * 2.0 * resolved["largest_radius"]
    if resolved["tile"] < smallest:
        raise ValueError(f"scene.tile = {resolved['tile']:g}: the tile must span {MIN_TILE_DIAMETERS:g} diameters of the "
                         f"largest sphere; accepted: at least {smallest:.4g} radii at radius_sigma {scene.radius_sigma:g}")
    if resolved["depth"] < 2.0 * resolved["largest_radius"]:
        raise ValueError(f"scene.depth = {resolved['depth']:g}: the slab must hold the largest sphere; accepted: at "
                         f"least {2.0 * resolved['largest_radius']:.4g} radii")
    if resolved["expected_spheres"] < MIN_EXPECTED_OBJECTS:
        raise ValueError(f"scene.tile, scene.depth: {resolved['expected_spheres']:.3g} spheres a realization; "
                         f"accepted: at least {MIN_EXPECTED_OBJECTS}")
    if resolved["expected_spheres"] > MAX_SPHERES:
        raise ValueError(f"scene.tile, scene.depth: {resolved['expected_spheres']:.3g} spheres a realization; "
                         f"accepted: at most {MAX_SPHERES} (lower the tile or the depth)")
    packings.check_writable(cache_directory(config))


def cache_directory(config) -> Path:
    """Where the packings of ``config`` are kept: ``scene.cache``, else the default cache. Not a
    resolved parameter: where a packing is kept changes nothing in the table."""
    return Path(config.scene.cache) if config.scene.cache is not None else packings.default_cache()


def for_backend(config, backend: str):
    """(config, note): the config as ``backend`` can trace it: the sphere grid walks exact spheres
    on either; with ``intersector = "embree"``, on embreex they become icospheres (module doc)."""
    return spheres_for_backend(config, backend)


def free_path(phi: float, sigma: float) -> float:
    """The mean chord of the void, 4 (1 - phi) exp(2 sigma^2) / (3 phi), in radii (module doc)."""
    return 4.0 * (1.0 - phi) * math.exp(2.0 * sigma * sigma) / (3.0 * phi)


def resolve(config) -> dict:
    scene = config.scene
    phi, sigma = scene.volume_fraction, scene.radius_sigma
    extent = slab(config, free_path(phi, sigma))
    depth, tile = extent["depth"], extent["tile"]
    top = largest_radius(sigma)
    return {
        "kind": KIND,
        "volume_fraction": phi,
        "radius_sigma": sigma,
        "largest_radius": top,
        **extent,
        "expected_spheres": phi * tile * tile * depth / (4.0 / 3.0 * math.pi * math.exp(3.0 * sigma * sigma)),
        **sphere_model(scene),
        "packer": packings.PROTOCOL,
        "base": config.base.kind if config.base is not None else "none",
        **sphere_statistics.resolve(config, (tile, tile, depth), extent["free_path"]),
    }


def sphere_model(scene) -> dict:
    """The spheres' model as the table records it: exact, or the icospheres' level, triangles,
    vertex radius and largest distance to the sphere (in its radii); and how rays meet them."""
    if is_exact(scene):
        return {"sphere_model": "exact", "triangles_per_sphere": 0, "vertex_radius": 1.0, "max_mesh_error": 0.0,
                "intersector": intersector(scene)}
    level = scene.subdivisions if scene.subdivisions is not None else level_for(scene.mesh_error)
    _, faces, vertex_radius, error = unit_icosphere(level)
    return {"sphere_model": "icosphere", "subdivisions": level, "triangles_per_sphere": len(faces),
            "vertex_radius": vertex_radius, "max_mesh_error": error, "intersector": intersector(scene)}


def scene_bytes(resolved: dict) -> int:
    per_sphere = resolved["triangles_per_sphere"] * TRIANGLE_BYTES or EXACT_SPHERE_BYTES
    return int((resolved["expected_spheres"] + 1.0) * per_sphere)


def draw(resolved: dict, rng: np.random.Generator, cache: Path) -> packings.Packing:
    """One realization's packing: the radii and the packer's seed drawn from ``rng``, the packing
    read from ``cache`` or generated there, its box moved to [0, tile)^2 x [-depth, 0)."""
    sigma, tile, depth = resolved["radius_sigma"], resolved["tile"], resolved["depth"]
    count = max(2, round(resolved["expected_spheres"]))
    seed = int(rng.integers(2**62))
    z = np.clip(rng.standard_normal(count), -CLIP, CLIP) if sigma > 0 else np.zeros(count)
    radii = np.exp(sigma * z - 0.5 * sigma * sigma)
    packed = packings.packing((tile, tile, depth), radii, resolved["volume_fraction"], seed, cache)
    return packed._replace(centres=packed.centres - np.array([0.0, 0.0, depth]))


def slab_heights(radii: np.ndarray, resolved: dict) -> dict:
    """The realization's top, bottom and base heights: SLAB_MARGIN beyond its largest sphere (the
    packer's common scale of the radii differs a little between realizations: per realization)."""
    top = float(radii.max()) * resolved["vertex_radius"]
    depth = resolved["depth"]
    return {"z_top": top + SLAB_MARGIN, "z_bottom": -depth - top - SLAB_MARGIN, "base_z": -depth - top}


def generate(resolved: dict, config, rng: np.random.Generator) -> Scene:
    packed = draw(resolved, rng, cache_directory(config))
    heights = slab_heights(packed.radii, resolved)
    reach = float(packed.radii.max()) * resolved["vertex_radius"]
    all_centres, source = periodic_images(packed.centres, resolved["tile"], reach)
    builder = SceneBuilder(resolved["tile"])
    if resolved["sphere_model"] == "exact":
        builder.add_spheres(all_centres, packed.radii[source], config.material)
    else:
        rotations = Rotation.random(len(packed.centres), random_state=rng).as_matrix()
        add_icospheres(builder, all_centres, rotations[source], resolved["subdivisions"], config.material,
                       packed.radii[source])
    if config.base is not None:
        builder.add_base_plane(heights["base_z"], config.base)
    volume = resolved["tile"] ** 2 * resolved["depth"]
    info = dict(resolved, **heights, spheres=len(packed.centres),
                sphere_images=int(len(all_centres) - len(packed.centres)),
                measured_volume_fraction=float(np.sum(4.0 / 3.0 * math.pi * packed.radii**3) / volume),
                mean_radius=float(packed.radii.mean()), shrink=packed.shrink)
    scene = with_cells(builder.build(heights["z_top"], heights["z_bottom"], info), resolved)
    return sphere_statistics.add(scene, packed.centres, packed.radii, resolved, config, rng)
