"""The same triangles, the same table: a Boolean-sphere realization exported as
icospheres to a PLY tile (``microsim.geometry.poisson_spheres.export_tile``) and traced as scene ``mesh``
(``period`` = the tile, the same ``[base]``) gives that realization's table of
``poisson_spheres`` with ``shading = "flat"``, bit for bit.

What makes them comparable, by construction (geometry/poisson_spheres.py's module doc):

- flat shading lays the realization as the mesh scene lays its tile: one
  ``periodic_tile.Tile`` (``Tile.of``, the one computation of the facets' normals and areas, which
  ``periodic_tile.checked`` uses too), laid by ``periodic_tile.build`` (a facet per triangle, its
  size, the copies a period either way in place of the spheres' periodic images), at the heights
  ``periodic_tile.summary`` gives a tile (``z_top``, ``z_bottom``, ``base_z`` from the
  realization's highest and lowest vertices, where the sphere scene otherwise has the slab's);
- the PLY holds the vertices in float64 as laid and the faces in order (trimesh's own PLY writer
  rounds to float32: the facets' planes move, and with them up to 0.15 % of a cell's weight);
- a mesh with a ``period`` is laid where it lies (``periodic_tile.checked``): the spheres that
  cross a side are wrapped in, not moved;
- the same seed, incidences, sensor, material, base and paths: the paths' streams are keyed by
  (seed, realization, incidence), whatever the scene.

``run.realizations`` is at least 2 and the mesh is one tile, while the spheres are drawn anew each
realization: realization 0 is compared (``microsim.testing.trace_realizations``, every realization's
estimates, those the table averages). Realization 1, other spheres against the same tile, must
differ, and so must the tile traced with exact shading, shifted by half a radius, or written in
float32: the comparison sees what is not the same.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from microsim import config
from microsim.geometry import mesh, periodic_tile, poisson_spheres
from microsim.physics.rng import geometry_rng
from microsim.run.plan import Plan
from microsim.testing import trace_realizations

SPHERES = {"scene": {"kind": "poisson_spheres", "volume_fraction": 0.3, "tile": 10.0, "depth": 4.0,
                     "subdivisions": 1, "shading": "flat"},
           "material": {"kind": "lambert", "albedo": 0.8}, "base": {"kind": "lambert", "albedo": 0.5},
           "illumination": {"theta_i_deg": [0.0, 60.0, 85.0]}, "sensor": {"cells": 100},
           "run": {"paths": 40_000, "realizations": 2, "seed": 4}}
SEED = SPHERES["run"]["seed"]


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """(the spheres' config, the mesh's config of its realization 0)."""
    spheres = config.validate(SPHERES)
    scene = poisson_spheres.export_tile(spheres, tmp_path_factory.mktemp("tile") / "spheres.ply")
    return spheres, config.validate({**SPHERES, "scene": scene})


def test_the_mesh_scene_lays_the_same_arrays(exported):
    plans = [Plan.from_config(c) for c in exported]
    a, b = (plan.generator.generate(plan.scene, plan.config, geometry_rng(SEED, 0)) for plan in plans)
    assert 20 <= a.info["spheres"] and a.info["copies"] > 0  # spheres cross the sides: wrapped in
    for name in ("vertices", "faces", "face_shape", "spheres", "sphere_shape"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    for name in ("code", "params", "material", "size"):
        assert np.array_equal(getattr(a.shapes, name), getattr(b.shapes, name)), name
    assert np.array_equal(a.materials.code, b.materials.code) and np.array_equal(a.materials.params, b.materials.params)
    assert (a.tile, a.z_top, a.z_bottom, a.base_material) == (b.tile, b.z_top, b.z_bottom, b.base_material)
    assert a.info["base_z"] == plans[1].scene["base_z"] and a.info["z_top"] == plans[1].scene["z_top"]


def test_the_ply_holds_the_triangles_as_laid(exported):
    spheres, meshed = exported
    resolved = poisson_spheres.resolve(spheres)
    laid = poisson_spheres.tile_of(resolved, *poisson_spheres.draw(resolved, geometry_rng(SEED, 0)))
    read = trimesh.load(meshed.scene.path, force="mesh", process=False)
    assert np.array_equal(read.vertices, laid.vertices) and np.array_equal(read.faces, laid.faces)
    tile = mesh.load(meshed)[0]  # checked: laid where it lies, as the spheres are
    assert tile.vertices.min() < 0.0 and tile.vertices[:, :2].max() > resolved["tile"]
    for name in ("vertices", "faces", "normals", "areas"):
        assert np.array_equal(getattr(tile, name), getattr(laid, name)), name


def test_the_mesh_gives_the_flat_spheres_table_bit_for_bit(exported):
    (_, spheres), (_, meshed) = (trace_realizations(c) for c in exported)
    assert spheres.keys() == meshed.keys() >= {"brdf", "albedo"}
    for name in spheres:
        assert np.array_equal(spheres[name][0], meshed[name][0]), name  # the realization exported
        assert not np.array_equal(spheres[name][1], meshed[name][1]), name  # other spheres, the same tile
    assert np.all(spheres["albedo"][0][:, 0] > 0.2)  # light came back from every incidence


def test_the_smooth_mesh_gives_the_smooth_spheres_table_bit_for_bit(exported, tmp_path):
    """Smooth shading too: the corners' normals are computed from the same tile (welded across
    the seams) by both scenes; and they are not the flat table."""
    data = {**SPHERES, "scene": {**SPHERES["scene"], "shading": "smooth"}}
    spheres = config.validate(data)
    scene = poisson_spheres.export_tile(spheres, tmp_path / "smooth.ply")
    assert scene["shading"] == "smooth"
    meshed = config.validate({**data, "scene": scene})
    (_, a), (_, b), (_, flat) = (trace_realizations(c) for c in (spheres, meshed, exported[0]))
    for name in a:
        assert np.array_equal(a[name][0], b[name][0]), name
    assert not np.array_equal(a["brdf"][0], flat["brdf"][0])


def _rewritten(path: Path, name: str, move=(0.0, 0.0, 0.0), float32: bool = False) -> str:
    """The exported tile moved by ``move``, written as the exporter writes it or by trimesh (float32)."""
    read = trimesh.load(path, force="mesh", process=False)
    vertices, out = np.asarray(read.vertices) + np.array(move), path.with_name(name)
    if float32:
        trimesh.Trimesh(vertices, read.faces, process=False).export(out)
    else:
        poisson_spheres.write_ply(out, vertices, read.faces)
    return str(out)


@pytest.mark.parametrize("change", ["exact shading", "tile moved half a radius", "float32 PLY"])
def test_the_comparison_sees_a_changed_scene(change, exported):
    spheres, meshed = exported
    path = Path(meshed.scene.path)
    if change == "exact shading":
        spheres = config.validate({**SPHERES, "scene": {**SPHERES["scene"], "shading": "exact"}})
    else:
        changed = _rewritten(path, "moved.ply", move=(0.5, 0.0, 0.0)) if change.startswith("tile") else \
            _rewritten(path, "float32.ply", float32=True)
        meshed = config.validate({**SPHERES, "scene": {**meshed.scene.model_dump(), "path": changed}})
    (_, a), (_, b) = (trace_realizations(c) for c in (spheres, meshed))
    assert not np.array_equal(a["brdf"][0], b["brdf"][0])


@pytest.mark.parametrize("shading", ["flat", "smooth"])
def test_flat_and_smooth_shading_need_icospheres(shading, tmp_path, capsys):
    from microsim.testing.refusals import assert_run_refused, small_config

    assert_run_refused(small_config(f'kind = "poisson_spheres"\nvolume_fraction = 0.3\nshading = "{shading}"'),
                       f"scene.shading = '{shading}'", tmp_path, capsys, "icospheres only")


def test_a_sphere_tile_is_checked_as_every_tile():
    """Closed spheres cover no net area: accepted over a base, their winding judged by their
    volume; a tile with a period lies where it is, at most a period beyond a side."""
    spheres = config.validate(SPHERES)
    resolved = poisson_spheres.resolve(spheres)
    tile = poisson_spheres.tile_of(resolved, *poisson_spheres.draw(resolved, geometry_rng(SEED, 0)))
    v, f, period = tile.vertices, tile.faces, resolved["tile"]
    assert np.array_equal(periodic_tile.checked("k", v, f, period, closed_by_base=True).vertices, v)  # not moved
    with pytest.raises(ValueError, match=r"^k: the surface covers \S+ of the tile .* add a \[base\]"):
        periodic_tile.checked("k", v, f, period, closed_by_base=False)
    with pytest.raises(ValueError, match=r"^k: inverted orientation \(the faces cover no net area"):
        periodic_tile.checked("k", v, f[:, ::-1], period, closed_by_base=True)
    with pytest.raises(ValueError, match=r"^k: spans x = .* more than one period beyond the tile \[0, 10\)"):
        periodic_tile.checked("k", v + np.array([period, 0.0, 0.0]), f, period, closed_by_base=True)


def test_seams_are_matched_where_the_tile_puts_them():
    """With a period, a periodic surface is laid where it lies and its seams are matched a period
    apart wherever they are: moved by a quarter period, or with a closed body crossing a side
    (the bounds then are not the seams); a lifted seam is refused there as at 0."""
    from microsim.testing.surfaces import bumpy

    ball = trimesh.creation.icosphere(1, radius=0.3)

    def with_ball(vertices, faces):  # a ball crossing the side x = 2
        return np.vstack([vertices, ball.vertices + [1.9, 1.0, 1.0]]), np.vstack([faces, ball.faces + len(vertices)])

    good, lifted = bumpy(), bumpy(lift_edge=0.1)
    moved = good[0] + [0.5, 0.0, 0.0]
    assert np.array_equal(periodic_tile.checked("k", moved, good[1], 2.0, closed_by_base=False).vertices, moved)
    assert periodic_tile.checked("k", *with_ball(*good), 2.0, closed_by_base=False).vertices[:, 0].max() > 2.1
    for vertices, faces, where in [(lifted[0] + [0.5, 0.0, 0.0], lifted[1], "x = 0.5 or x = 2.5"),
                                   (*with_ball(*lifted), "x = 0 or x = 2")]:
        with pytest.raises(ValueError, match=rf"^k: the seams do not match .* 32 open edges on {where} have no twin"):
            periodic_tile.checked("k", vertices, faces, 2.0, closed_by_base=False)
