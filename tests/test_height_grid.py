"""The grid intersector of heightfields (``intersector = "grid"``, the default;
microsim/tracer/integrators/grid.py): the same triangles as Embree's, met by walking the grid.

- The walk finds Embree's hits: on every query a Gaussian surface's paths made to Embree, and on
  rays along the grid's lines and through its vertices, hit or miss agree and t agrees to
  float32's precision (Embree's vertices are float32, the walk's heights float64).
- A table traced on the grid and one traced on the triangles, with different seeds (independent
  paths) on the same surface (a height file), agree cell by cell and at exact directions (next-
  event estimation, whose shadow rays walk the grid too) within their errors: the mean z^2 lies
  within ``microsim.testing.bounds``' two-sided bounds.
- A [base] under the grid is met by a ray under the surface (as a pass-through at a back face
  leaves one), and not without a base.
- Energy on the grid: tests/test_periodic_tile_physics.py (heightfields default to it); on the
  triangles: here.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from microsim import config, tables
from microsim.geometry import heightfield, periodic_tile
from microsim.physics.rng import geometry_rng
from microsim.run.plan import Plan
from microsim.testing import trace_table
from microsim.testing.bounds import chi2_bound, chi2_lower_bound
from microsim.testing.refusals import assert_run_refused, small_config
from microsim.testing.surfaces import RIDGE_SAMPLES, ridges
from microsim.tracer.estimators import DEFAULT, build, setups
from microsim.tracer.integrators.direct import DirectBackend
from microsim.tracer.integrators.grid import HeightGrid, walk
from microsim.tracer.integrators.records import Beam
from microsim.tracer.sensor import Sensor


def gaussian(intersector: str, **scene) -> dict:
    return {"scene": {"kind": "heightfield", "generator": "gaussian", "roughness": 0.8, "tile": 8.0,
                      "intersector": intersector, **scene},
            "material": {"kind": "lambert", "albedo": 0.8}, "illumination": {"theta_i_deg": [0.0, 60.0, 85.0]},
            "sensor": {"cells": 100}, "run": {"paths": 40_000, "realizations": 4, "seed": 3}}


def realization(data: dict):
    plan = Plan.from_config(config.validate(data))
    return plan, plan.generator.generate(plan.scene, plan.config, geometry_rng(plan.config.run.seed, 0))


def walked(grid, origins, directions, tfar):
    """(face or -1, t) of the walk on every ray."""
    out = [walk(grid, tuple(map(float, o)), tuple(map(float, d)), float(t))
           for o, d, t in zip(origins, directions, tfar)]
    return np.array([f for f, _ in out]), np.array([t for _, t in out])


def test_the_walk_finds_embree_s_hits_on_the_tracer_s_queries():
    plan, scene = realization(gaussian("triangles"))
    grid = realization(gaussian("grid"))[1].grid
    sensor = Sensor.build(100)
    origins, directions, tfar = [], [], []
    for k in range(plan.n_incidences):
        estimators, wi = build(DEFAULT, sensor), np.asarray(plan.incidence_direction(k))
        backend = DirectBackend(scene, estimators, 1, log_rays=3000)
        backend.trace(Beam(wi, np.uint64(k), 1000, 0), scene.arrays(), setups(estimators, wi, 0.0))
        log = backend.ray_log
        origins.append(log[:, :3]), directions.append(log[:, 3:6]), tfar.append(log[:, 6])
    origins, directions, tfar = (np.concatenate(c) for c in (origins, directions, tfar))
    prim, t, _ = backend.embree.intersect(origins, directions, tfar)
    face, t_walk = walked(grid, origins, directions, tfar)
    assert len(prim) > 5000 and 0.3 < np.mean(prim >= 0) < 0.9  # hits and misses, up and down
    np.testing.assert_array_equal(face >= 0, prim >= 0)
    hit = prim >= 0
    np.testing.assert_array_equal(scene.prim_shape[face[hit]], scene.prim_shape[prim[hit]])  # the same facet
    np.testing.assert_allclose(t_walk[hit], t[hit], rtol=1e-5, atol=1e-6)


def test_the_walk_finds_embree_s_hits_along_the_grid_s_lines():
    """Rays in the planes x = i pixel or y = j pixel (a direction with no x or y part) and
    vertical rays through vertices: the walk's ties between cells."""
    _, scene = realization(gaussian("triangles"))
    grid = realization(gaussian("grid"))[1].grid
    rng = np.random.default_rng(5)
    n, pixel = len(grid.heights), grid.pixel
    count = 600
    origins = np.column_stack([rng.integers(0, n, count) * pixel, rng.uniform(0, n * pixel, count),
                               np.full(count, scene.z_top)])
    polar = rng.uniform(0.0, 1.5, count)
    directions = np.column_stack([np.zeros(count), np.sin(polar) * rng.choice([-1, 1], count), -np.cos(polar)])
    directions[:200] = [0.0, 0.0, -1.0]
    origins[:200, 1] = rng.integers(0, n, 200) * pixel  # through a vertex
    swap = slice(400, 600)  # the same in y
    origins[swap, :2], directions[swap, :2] = origins[swap, ::-1][:, 1:], directions[swap, ::-1][:, 1:]
    origins, directions = origins.astype(np.float32), directions.astype(np.float32)
    # to the tile's boundary, as prepare_segment bounds a segment
    with np.errstate(divide="ignore", invalid="ignore"):
        sides = [np.where(directions[:, a] > 0, (n * pixel - origins[:, a]) / directions[:, a],
                          np.where(directions[:, a] < 0, -origins[:, a] / directions[:, a], np.inf)) for a in (0, 1)]
    tfar = np.minimum.reduce([*sides, (scene.z_bottom - origins[:, 2]) / directions[:, 2]]).astype(np.float32)
    embree_scene = DirectBackend(scene, build(DEFAULT, Sensor.build(100))).embree
    prim, t, _ = embree_scene.intersect(origins, directions, tfar)
    face, t_walk = walked(grid, origins, directions, tfar)
    np.testing.assert_array_equal(face >= 0, prim >= 0)
    assert np.mean(prim >= 0) > 0.5  # grazing ones may reach a side first
    hit = prim >= 0
    np.testing.assert_allclose(t_walk[hit], t[hit], rtol=1e-5, atol=1e-6)


@pytest.fixture(scope="module")
def ridge_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("ridges") / "ridges.npy"
    np.save(path, ridges())
    return str(path)


def ridge_table(ridge_file, directory, intersector: str, seed: int, material=None) -> tables.Table:
    """The ridges, Lambertian 0.8 (or ``material``: then without points, which a mirror has none of)."""
    points = {} if material else {"directions_deg": [[30.0, 0.0], [60.0, 90.0], [75.0, 200.0]]}
    cfg = config.validate({
        "scene": {"kind": "heightfield", "path": ridge_file, "pixel": 1.0 / RIDGE_SAMPLES, "intersector": intersector},
        "material": material or {"kind": "lambert", "albedo": 0.8},
        "illumination": {"theta_i_deg": [0.0, 60.0, 85.0], "phi_i_deg": [0.0, 30.0, 90.0]},
        "sensor": {"cells": 100, **points},
        "run": {"paths": 96_000, "realizations": 16, "seed": seed}})
    return trace_table(cfg, directory / f"{intersector}{seed}.h5")


def test_grid_and_triangle_tables_agree_within_errors(ridge_file, tmp_path):
    grid, triangles = (ridge_table(ridge_file, tmp_path, kind, seed) for kind, seed in (("grid", 1), ("triangles", 2)))
    assert (grid.scene["intersector"], triangles.scene["intersector"]) == ("grid", "triangles")
    z2 = (grid.brdf - triangles.brdf) ** 2 / (grid.brdf_stderr**2 + triangles.brdf_stderr**2)
    cells = z2.size
    assert chi2_lower_bound(cells, 16) <= z2.mean() <= chi2_bound(cells, 16), z2.mean()
    points = "brdf_points"
    dz2 = ((grid.arrays[points] - triangles.arrays[points]) ** 2
           / (grid.arrays[f"{points}_stderr"] ** 2 + triangles.arrays[f"{points}_stderr"] ** 2))
    assert np.all(grid.arrays[points] > 0) and dz2.mean() <= chi2_bound(dz2.size, 16), dz2


@pytest.mark.parametrize("material", [{"kind": "lambert", "albedo": 1.0}, {"kind": "mirror"}], ids=["white", "mirror"])
def test_the_triangles_keep_energy_too(material, ridge_file, tmp_path):
    table = ridge_table(ridge_file, tmp_path, "triangles", 4, material)
    np.testing.assert_allclose(table.albedo + table.truncated, 1.0, rtol=0, atol=1e-6)


def test_the_base_is_met_under_the_grid():
    """Rays that reach under the surface (as a pass-through leaves them) meet the [base]."""
    _, scene = realization({**gaussian("grid"), "base": {"kind": "lambert", "albedo": 0.5}})
    grid = scene.grid
    assert grid.base_prim == scene.n_triangles - 2 and grid.base_z < grid.heights.min()
    below = (1.0, 1.0, float(grid.heights.min()) - 1e-4)
    face, t = walk(grid, below, (0.0, 0.0, -1.0), 10.0)
    assert face == grid.base_prim and math.isclose(t, below[2] - grid.base_z, rel_tol=1e-12)
    assert walk(grid._replace(base_prim=-1), below, (0.0, 0.0, -1.0), 10.0) == (-1, 10.0)


def test_the_grid_is_the_tile_s_heights():
    """height_grid reads the heights back from the triangulated tile, and the tile's own faces
    in the scene from where build lays them."""
    plan, scene = realization(gaussian("grid"))
    tile = heightfield.realize(plan.scene, geometry_rng(plan.config.run.seed, 0))
    n = len(scene.grid.heights)
    assert n == plan.scene["samples"] and scene.grid.pixel == plan.scene["pixel"]
    heights = tile.vertices[:, 2].reshape(n + 1, n + 1)
    np.testing.assert_array_equal(scene.grid.heights, heights[:n, :n])
    np.testing.assert_array_equal(heights[n], heights[0])  # the grid wraps
    first = periodic_tile.first_own_face(tile)
    assert scene.grid.first_face == first
    own = scene.vertices[scene.faces[first:first + len(tile.faces)]]
    np.testing.assert_array_equal(own, tile.vertices[tile.faces].astype(np.float32))
    assert isinstance(scene.grid, HeightGrid)


def test_an_unknown_intersector_is_refused(tmp_path, capsys):
    assert_run_refused(small_config('kind = "heightfield"\ngenerator = "gaussian"\nroughness = 0.5\n'
                                    'intersector = "bvh"'), "scene.intersector", tmp_path, capsys)
