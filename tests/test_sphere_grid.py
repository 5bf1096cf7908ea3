"""The sphere grid (``intersector = "grid"``, the default for exact spheres;
microsim/tracer/integrators/sphere_grid.py): Embree's native spheres, met by walking cells.

- The walk finds Embree's hits: on every query the tracer's paths made to Embree at phi 0.01,
  0.1, 0.3 and 0.6 (normal and grazing incidence), and on rays along the cells' faces, through
  their corners, grazing spheres and ending at the tile's sides, hit or miss agree and so does
  the shape hit, except on rays that pass a sphere within float32 precision of its tangent
  (counted); t agrees to float32 precision along the surface's normal (Embree's centres and
  roots are float32, the walk's float64).
- Tables traced on the grid and on Embree, with independent seeds, agree cell by cell and order
  by order within their errors (the mean z^2 within the two-sided 99 % interval pooled over the
  orders, and within ``microsim.testing.bounds`` for each), and so do their albedos.
- The cells list every sphere in every cell it reaches into; their side follows the rule of
  geometry/sphere_cells.py; the grid takes exact spheres only.
- Energy, reciprocity, threads and resume on the grid: tests/test_energy.py,
  tests/test_reciprocity.py, tests/test_backends.py and tests/test_resume.py, whose exact spheres
  take the grid by default; bit identity on every host: the ``sphere_grid`` golden.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from microsim import config
from microsim.core.orders import ORDERS
from microsim.geometry import sphere_cells
from microsim.physics.rng import geometry_rng
from microsim.run.plan import Plan
from microsim.testing import trace
from microsim.testing.bounds import chi2_bound, chi2_lower_bound, mean_z2_interval
from microsim.testing.refusals import assert_run_refused, small_config
from microsim.tracer.estimators import DEFAULT, build, setups
from microsim.tracer.integrators.direct import DirectBackend
from microsim.tracer.integrators.records import Beam
from microsim.tracer.integrators.sphere_grid import SphereCells, first_hits
from microsim.tracer.sensor import Sensor
from microsim.tracer.shapes import SPHERE

#: float32's relative precision
EPS32 = 2.0**-23


def spheres(phi: float, intersector: str, seed: int = 5, **run) -> dict:
    return {"scene": {"kind": "poisson_spheres", "volume_fraction": phi, "tile": 16.0, "intersector": intersector},
            "material": {"kind": "lambert", "albedo": 0.8}, "base": {"kind": "lambert", "albedo": 0.5},
            "illumination": {"theta_i_deg": [0.0, 80.0]}, "sensor": {"cells": 100},
            "run": {"paths": 1000, "realizations": 2, "seed": seed, **run}}


def realization(phi: float):
    """(plan, the Embree scene, its sphere cells) of realization 0 at ``phi``."""
    plan = Plan.from_config(config.validate(spheres(phi, "embree")))
    scene = plan.generator.generate(plan.scene, plan.config, geometry_rng(plan.config.run.seed, 0))
    return plan, scene, sphere_cells.build(scene, sphere_cells.void_side(scene, plan.scene["free_path"]))


def embree_hits(scene, origins, directions, tfar):
    """(primitive or -1, t) of Embree's native spheres on the rays."""
    embree_scene = DirectBackend(scene, build(DEFAULT, Sensor.build(100))).embree
    prim, t, _ = embree_scene.intersect(origins, directions, tfar)
    return prim, t


def compare(scene, cells, origins, directions, tfar):
    """Hit or miss and the shape hit of Embree and the walk on every ray: (rays that disagree, of
    them those within float32 precision of a tangent); asserts t to float32 precision. Distances
    are taken in the spheres' frame (a grain's: the frame scaled by ``sphere_scale``)."""
    origins, directions, tfar = (np.ascontiguousarray(a, np.float32) for a in (origins, directions, tfar))
    prim, t = embree_hits(scene, origins, directions, tfar)
    walked, t_walk = first_hits(cells, origins, directions, tfar)
    shape = np.where(prim >= 0, scene.prim_shape[np.maximum(prim, 0)], -1)
    walked_shape = np.where(walked >= 0, scene.prim_shape[np.maximum(walked, 0)], -1)
    differ = shape != walked_shape
    frame = np.array([*cells.scale, 1.0])
    o, d = origins.astype(np.float64) * frame, directions.astype(np.float64) * frame
    scale = EPS32 * frame.max() * (np.abs(origins).max(axis=1) + np.abs(tfar))  # float32's spacing about the ray
    centres, radii = sphere_cells.native_spheres(scene)
    sphere_of_shape = np.full(len(scene.shapes), -1)
    sphere_of_shape[scene.sphere_shape] = np.arange(len(scene.sphere_shape))
    tangent = np.zeros(len(origins), bool)
    for which in (shape, walked_shape):
        k = np.where(which >= 0, sphere_of_shape[np.maximum(which, 0)], -1)
        c, r = centres[np.maximum(k, 0)], radii[np.maximum(k, 0)]
        along = np.einsum("ij,ij->i", c - o, d) / np.einsum("ij,ij->i", d, d)
        miss_distance = np.linalg.norm(o + along[:, None] * d - c, axis=1)
        tangent |= (k >= 0) & (np.abs(miss_distance - r) <= 64 * scale)
    hit = ~differ & (walked >= 0)
    k = sphere_of_shape[walked_shape[hit]]
    point = o[hit] + t_walk[hit, None] * d[hit]
    normal = np.where((k >= 0)[:, None], point - centres[np.maximum(k, 0)], [0.0, 0.0, 1.0])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    across = np.abs(t[hit] - t_walk[hit]) * np.abs(np.einsum("ij,ij->i", normal, d[hit]))
    assert np.all(across <= 8 * scale[hit]), (across / scale[hit]).max()
    return int(differ.sum()), int((differ & tangent).sum())


def logged_queries(plan, scene, paths: int = 16_000, each: int = 50_000) -> np.ndarray:
    """The first ``each`` queries the direct backend makes to Embree at each incidence of the plan
    (rows of origin, direction, tfar), ``paths`` paths an incidence."""
    sensor = Sensor.build(100)
    logs = []
    for k in range(plan.n_incidences):
        estimators, wi = build(DEFAULT, sensor), np.asarray(plan.incidence_direction(k))
        backend = DirectBackend(scene, estimators, 1, log_rays=each)
        backend.trace(Beam(wi, np.uint64(k), paths, 0), scene.arrays(), setups(estimators, wi, 0.0))
        logs.append(backend.ray_log)
    return np.concatenate(logs)


@pytest.mark.parametrize("phi", [0.01, 0.1, 0.3, 0.6])
def test_the_walk_finds_embree_s_hits_on_the_tracer_s_queries(phi):
    plan, scene, cells = realization(phi)
    log = logged_queries(plan, scene)
    assert len(log) == 100_000
    differ, tangent = compare(scene, cells, log[:, :3], log[:, 3:6], log[:, 6])
    print(f"phi {phi}: {len(log)} queries, {differ} differ, {tangent} of them at a tangent")
    assert differ == tangent <= 5, (differ, tangent)


#: micrograin fields of the order-1 checks (tau0, beta_x, beta_y), each at two incidences
FIELDS = [(0.3, 1.0, 1.0), (0.9, 2.0, 2.0), (0.5, 0.5, 2.0), (0.6, 0.05, 0.05)]


def grains(field, intersector: str, seed: int = 5, theta=(0.0, 80.0), **run) -> dict:
    tau0, beta_x, beta_y = field
    return {"scene": {"kind": "micrograins", "tau0": tau0, "beta_x": beta_x, "beta_y": beta_y,
                      "intersector": intersector},
            "material": {"kind": "lambert", "albedo": 0.8}, "base": {"kind": "lambert", "albedo": 0.5},
            "illumination": {"theta_i_deg": list(theta), "phi_i_deg": [0.0, 90.0]}, "sensor": {"cells": 100},
            "run": {"paths": 1000, "realizations": 2, "seed": seed, **run}}


@pytest.mark.parametrize("field", FIELDS, ids=str)
def test_the_walk_finds_embree_s_hits_on_the_grains(field):
    """Grains are walked as the unit spheres of their scaled frame: on the tracer's queries at 0
    and 80 deg (and 90 deg azimuth: across the anisotropic field's narrow axis), the walk and
    Embree's instanced spheres meet the same grain or the base, and t agrees."""
    plan = Plan.from_config(config.validate(grains(field, "embree")))
    scene = plan.generator.generate(plan.scene, plan.config, geometry_rng(plan.config.run.seed, 0))
    cells = sphere_cells.build(scene, sphere_cells.GRAIN_SIDE)
    assert tuple(cells.scale) == scene.sphere_scale == (field[1], field[2]) and cells.base_prim == 0
    log = logged_queries(plan, scene, paths=8_000, each=25_000)
    differ, tangent = compare(scene, cells, log[:, :3], log[:, 3:6], log[:, 6])
    print(f"field {field}: {len(log)} queries, {differ} differ, {tangent} of them at a tangent")
    assert differ == tangent <= 5, (differ, tangent)


def segment_ends(scene, origins, directions):
    """tfar of each ray: where it leaves the tile or the slab, as prepare_segment bounds a segment."""
    limits = []
    with np.errstate(divide="ignore", invalid="ignore"):
        for axis, (low, high) in enumerate(((0.0, scene.tile), (0.0, scene.tile_y), (scene.z_bottom, scene.z_top))):
            d = directions[:, axis]
            limits.append(np.where(d > 0, (high - origins[:, axis]) / d,
                                   np.where(d < 0, (low - origins[:, axis]) / d, np.inf)))
    return np.minimum.reduce(limits)


def unit(v):
    return v / np.linalg.norm(v, axis=1)[:, None]


@pytest.mark.parametrize("phi", [0.1, 0.6])
def test_the_walk_finds_embree_s_hits_on_the_cells_edges_and_tangents(phi):
    """Rays in the cells' faces (no component across them), vertical rays down the cells' corners,
    rays that pass spheres at 1 +- delta radii (delta from 1e-2 down to 1e-7), and rays that end at
    the tile's sides among the spheres that straddle them (periodic images)."""
    _, scene, cells = realization(phi)
    rng = np.random.default_rng(9)
    n, side = 400, cells.side
    low, high = np.array([0.0, 0.0, scene.z_bottom]), np.array([scene.tile, scene.tile_y, scene.z_top])
    inside = rng.uniform(low, high, (n, 3))
    along_faces = inside.copy()
    along_faces[:, 0] = rng.integers(0, cells.counts[0], n) * side[0]  # in a plane x = i side
    face_directions = unit(np.column_stack([np.zeros(n), rng.normal(size=(n, 2))]))
    corners = inside.copy()
    corners[:, :2] = rng.integers(0, cells.counts[:2], (n, 2)) * side[:2]
    down = np.broadcast_to([0.0, 0.0, -1.0], (n, 3))
    centres = scene.shapes.params[scene.sphere_shape][:, :3]
    chosen = centres[rng.integers(0, len(centres), n)]
    d = unit(rng.normal(size=(n, 3)))
    across = unit(np.cross(d, rng.normal(size=(n, 3))))
    delta = 10.0 ** rng.uniform(-7.0, -2.0, n) * rng.choice([-1.0, 1.0], n)
    passing = chosen + (1.0 + delta)[:, None] * across - 2.0 * d
    keep = np.all((passing >= low) & (passing < high), axis=1)
    to_sides = inside.copy()
    to_sides[:, 0] = scene.tile - rng.uniform(0.0, 2.0, n)
    sideways = unit(np.column_stack([np.ones(n), rng.normal(0.0, 0.3, (n, 2))]))
    origins = np.concatenate([along_faces, corners, passing[keep], to_sides])
    directions = np.concatenate([face_directions, down, d[keep], sideways])
    origins, directions = origins.astype(np.float32), directions.astype(np.float32)
    differ, tangent = compare(scene, cells, origins, directions, segment_ends(scene, origins, directions))
    print(f"phi {phi}: {len(origins)} rays, {keep.sum()} grazing, {differ} differ, {tangent} of them at a tangent")
    assert differ == tangent <= 0.05 * keep.sum(), (differ, tangent)


def sphere_table(phi: float, intersector: str, seed: int):
    data = spheres(phi, intersector, seed, paths=48_000, realizations=REALIZATIONS)
    return trace(config.validate({**data, "sensor": {"cells": 60}}), threads=2)


REALIZATIONS = 16


def grain_table(field, intersector: str, seed: int):
    data = grains(field, intersector, seed, theta=(0.0, 70.0), paths=48_000, realizations=REALIZATIONS)
    return trace(config.validate({**data, "sensor": {"cells": 60}}), threads=2)


TABLES = {"spheres": sphere_table, "grains": grain_table}


@pytest.mark.parametrize("what, scene", [("spheres", 0.01), ("spheres", 0.3), ("spheres", 0.6),
                                         ("grains", (0.5, 0.5, 2.0))], ids=str)
def test_grid_and_embree_tables_agree_order_by_order(what, scene):
    grid, embree = TABLES[what](scene, "grid", 11), TABLES[what](scene, "embree", 12)
    assert (grid.plan.scene["intersector"], embree.plan.scene["intersector"]) == ("grid", "embree")
    pooled = []
    for i in range(len(grid.brdf)):
        a, b = grid.brdf[i], embree.brdf[i]
        for order in range(ORDERS):  # 1, 2, 3, 4+: disjoint
            z2 = (a.mean[order] - b.mean[order]) ** 2 / (a.stderr[order] ** 2 + b.stderr[order] ** 2)
            z2 = z2[np.isfinite(z2)]
            assert chi2_lower_bound(z2.size, REALIZATIONS) <= z2.mean() <= chi2_bound(z2.size, REALIZATIONS), \
                (i, order, z2.mean())
            pooled.append(z2)
        a, b = grid.albedo[i], embree.albedo[i]
        albedo_z = (a.mean[:ORDERS + 1] - b.mean[:ORDERS + 1]) / np.hypot(a.stderr[:ORDERS + 1], b.stderr[:ORDERS + 1])
        assert np.all(np.abs(albedo_z) <= 4.0), albedo_z  # each order and all
    pooled = np.concatenate(pooled)
    low, high = mean_z2_interval(pooled.size, REALIZATIONS)
    assert low <= pooled.mean() <= high, (low, pooled.mean(), high)


def test_every_sphere_is_listed_in_every_cell_it_reaches_into():
    _, scene, cells = realization(0.3)
    assert isinstance(cells, SphereCells) and cells.base_prim == 0 and cells.base_z == np.float32(scene.info["base_z"])
    side = cells.side
    params = scene.shapes.params[scene.sphere_shape]
    listed = set()
    for cell in range(len(cells.starts) - 1):
        for e in range(cells.starts[cell], cells.starts[cell + 1]):
            listed.add((cell, int(cells.prims[e])))
            np.testing.assert_array_equal(cells.spheres[e], params[cells.prims[e] - scene.n_triangles, :4])
    nx, ny, nz = cells.counts
    reached = set()
    for k, (x, y, z, r) in enumerate(params[:, :4]):
        lo = np.floor((np.array([x, y, z]) - r - [0.0, 0.0, cells.z_low]) / side).astype(int)
        hi = np.floor((np.array([x, y, z]) + r - [0.0, 0.0, cells.z_low]) / side).astype(int)
        lo, hi = np.maximum(lo, 0), np.minimum(hi, cells.counts - 1)
        for a in range(lo[0], hi[0] + 1):
            for b in range(lo[1], hi[1] + 1):
                for c in range(lo[2], hi[2] + 1):
                    reached.add(((a * ny + b) * nz + c, k + scene.n_triangles))
    assert listed == reached


@pytest.mark.parametrize("phi", [0.01, 0.1, 0.3, 0.6])
def test_the_cells_side_is_the_free_path_within_two_and_four_radii(phi):
    _, scene, cells = realization(phi)
    least = min(max(4.0 / (-3.0 * math.log(1.0 - phi)), 2.0), 4.0)  # the Boolean void's mean free path
    assert math.isclose(sphere_cells.cell_side(4.0 / (-3.0 * math.log(1.0 - phi)), 1.0), least, rel_tol=1e-12)
    assert np.all(cells.side >= least) and np.all(cells.counts == np.floor(
        np.array([scene.tile, scene.tile_y, scene.z_top - scene.z_bottom]) / least))


def test_the_grid_takes_exact_spheres_only(tmp_path, capsys):
    assert_run_refused(small_config('kind = "poisson_spheres"\nvolume_fraction = 0.3\nsubdivisions = 1\n'
                                    'intersector = "grid"'), "scene.intersector = 'grid'", tmp_path, capsys)


@pytest.mark.parametrize("scene, expected", [
    ({"kind": "poisson_spheres", "volume_fraction": 0.01}, "embree"),
    ({"kind": "poisson_spheres", "volume_fraction": 0.03}, "grid"),
    ({"kind": "poisson_spheres", "volume_fraction": 0.6}, "grid"),
    ({"kind": "poisson_spheres", "volume_fraction": 0.3, "subdivisions": 1}, "embree"),
    ({"kind": "packed_spheres", "volume_fraction": 0.02}, "embree"),
    ({"kind": "packed_spheres", "volume_fraction": 0.4}, "grid"),
    ({"kind": "micrograins", "tau0": 0.5, "beta": 1.0}, "grid"),
    ({"kind": "poisson_spheres", "volume_fraction": 0.01, "intersector": "grid"}, "grid"),
], ids=str)
def test_the_default_intersector_is_the_faster_one_measured(scene, expected):
    """The grid for exact spheres from volume fraction 0.03 up and for exact grains; Embree for
    dilute suspensions and packings (the grid traced at 0.71 of Embree's speed at phi 0.01) and
    for icospheres; a given intersector as given (docs/developer/performance.md)."""
    data = {"scene": scene, "material": {"kind": "lambert", "albedo": 0.8}, "illumination": {"theta_i_deg": [0.0]},
            "sensor": {"cells": 24}, "run": {"paths": 100, "realizations": 2}}
    assert Plan.from_config(config.validate(data)).scene["intersector"] == expected
