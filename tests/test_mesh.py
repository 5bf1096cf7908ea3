"""The mesh scene (geometry/mesh.py): a user's periodic tile, checked, and traced as every surface.

- A flat two-triangle tile is the plane: the same paths give the plane's cells bit for bit (a
  Lambertian plane's exits depend only on the random stream: every path meets the plane z = 0
  once and leaves in the direction it draws).
- A white Lambertian periodic bumpy tile is closed: every path leaves (albedo 1 to 1e-12,
  nothing transmitted or truncated) up to 89 deg.
- Bad meshes are refused in one line naming scene.path, exit 2, nothing written.
"""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
import trimesh

from microsim import tables
from microsim.app import session
from microsim.testing.surfaces import N, bumpy
from microsim.testing.surfaces import write_mesh as write


def mesh_config(path, albedo=0.8, theta=(0.0, 60.0), **scene) -> dict:
    return {"scene": {"kind": "mesh", "path": str(path), **scene}, "material": {"kind": "lambert", "albedo": albedo},
            "illumination": {"theta_i_deg": list(theta)}, "sensor": {"cells": 100},
            "run": {"paths": 40_000, "realizations": 4, "seed": 3}}


def test_a_flat_tile_mesh_is_the_plane_bit_for_bit(tmp_path):
    path = write(tmp_path / "flat.obj", np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float),
                 np.array([[0, 1, 2], [0, 2, 3]]))
    cfg = mesh_config(path, theta=(0.0, 45.0, 85.0))
    flat = tables.load(session.run(cfg, tmp_path / "mesh.h5").tables[0])
    plane = tables.load(session.run({**cfg, "scene": {"kind": "plane", "tile": 1.0}}, tmp_path / "plane.h5").tables[0])
    for name in ("brdf", "brdf_order", "brdf_stderr", "albedo"):
        assert np.array_equal(flat.arrays[name], plane.arrays[name]), name
    assert flat.scene["rms_slope"] == 0.0 and flat.scene["mean_cosine"] == 1.0 and flat.scene["period"] == 1.0


def test_a_white_closed_tile_returns_every_path(tmp_path):
    path = write(tmp_path / "bumps.ply", *bumpy())
    table = tables.load(session.run(mesh_config(path, albedo=1.0, theta=(0.0, 60.0, 89.0)), tmp_path / "w.h5").tables[0])
    np.testing.assert_allclose(table.albedo, 1.0, rtol=0, atol=1e-12)
    assert not table.transmitted.any() and not table.truncated.any()
    area = table.scene["area"]
    assert table.scene["mean_cosine"] == pytest.approx(4.0 / area, rel=1e-12)  # the tile's area over the mesh's
    assert table.scene["sha256"] == hashlib.sha256(open(path, "rb").read()).hexdigest()
    assert table.scene["triangles"] > table.scene["surface_triangles"] == 2 * N * N  # copies beyond the sides


@pytest.mark.parametrize("suffix", [".stl", ".glb"])
def test_a_format_without_shared_vertices_traces_as_the_ply_of_its_triangles(suffix, tmp_path):
    """STL stores each triangle's corners apart (and trimesh's GLB export, unprocessed, may too):
    read as they are, every edge would look open and the tile be refused as full of holes. The
    corners at the same coordinates are one vertex, so the tile (its coordinates float32-exact,
    as STL stores them) traces as the PLY of the same triangles, bit for bit, and a white one
    returns every path."""
    vertices, faces = bumpy()
    vertices = vertices.astype(np.float32).astype(np.float64)
    soup = vertices[faces].reshape(-1, 3)  # three vertices of its own for every face
    loose = write(tmp_path / f"bumps{suffix}", soup, np.arange(len(soup)).reshape(-1, 3))
    shared = write(tmp_path / "bumps.ply", vertices, faces)
    assert len(trimesh.load(loose, force="mesh", process=False).vertices) == 3 * len(faces)
    cfg = mesh_config(loose, theta=(0.0, 60.0))
    a = tables.load(session.run(cfg, tmp_path / "loose.h5").tables[0])
    b = tables.load(session.run(mesh_config(shared, theta=(0.0, 60.0)), tmp_path / "shared.h5").tables[0])
    for name in ("brdf", "brdf_order", "albedo"):
        assert np.array_equal(a.arrays[name], b.arrays[name]), name
    assert a.scene["surface_triangles"] == 2 * N * N
    white = tables.load(session.run(mesh_config(loose, albedo=1.0, theta=(0.0, 89.0)), tmp_path / "w.h5").tables[0])
    np.testing.assert_allclose(white.albedo, 1.0, rtol=0, atol=1e-12)


@pytest.mark.parametrize("make, message", [
    (lambda d: str(d / "absent.obj"), "no such file"),
    (lambda d: write(d / "inverted.ply", *bumpy(flip=True)), "inverted orientation"),
    (lambda d: write(d / "seams.ply", *bumpy(lift_edge=0.1)), "seams do not match"),
    (lambda d: write(d / "hole.ply", *bumpy(drop=4)), "add a [base]"),
    (lambda d: write(d / "nan.obj", np.array([[0, 0, 0], [1, 0, 0], [1, 1, np.nan], [0, 1, 0]]),
                     np.array([[0, 1, 2], [0, 2, 3]])), "NaN or infinite"),
    (lambda d: write(d / "degenerate.obj", np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 0]]),
                     np.array([[0, 1, 2], [0, 2, 3], [0, 4, 2]])), "degenerate"),
    (lambda d: (d / "text.obj").write_text("this is no mesh\n") and str(d / "text.obj"), "scene.path"),
])
def test_a_bad_mesh_is_refused_in_one_line(make, message, tmp_path, tmp_path_factory, capsys):
    from microsim.testing.refusals import SMALL_RUN, assert_run_refused

    path = make(tmp_path_factory.mktemp("meshes"))  # beside the run's directory, which must stay empty
    assert_run_refused(f'[scene]\nkind = "mesh"\npath = "{path}"\n' + SMALL_RUN, message, tmp_path, capsys)


def test_a_base_closes_a_tile_with_a_hole(tmp_path):
    path = write(tmp_path / "hole.ply", *bumpy(drop=4))
    cfg = {**mesh_config(path, albedo=1.0), "base": {"kind": "lambert", "albedo": 1.0}}
    table = tables.load(session.run(cfg, tmp_path / "hole.h5").tables[0])
    np.testing.assert_allclose(table.albedo, 1.0, rtol=0, atol=1e-12)


def ridges(length_y: float, cells_y: int):
    """A white-test tile invariant along y: steep triangular ridges (height 1.5, base 2) along y,
    x in [0, 4], y in [0, length_y], ``cells_y`` cells along y."""
    x, z = np.array([0.0, 1.0, 2.0, 3.0, 4.0]), np.array([0.0, 1.5, 0.0, 1.5, 0.0])
    y = np.linspace(0.0, length_y, cells_y + 1)
    vertices = np.array([[xi, yj, zi] for xi, zi in zip(x, z) for yj in y])
    faces = []
    for i in range(len(x) - 1):
        for j in range(cells_y):
            a, b = i * (cells_y + 1) + j, (i + 1) * (cells_y + 1) + j
            faces += [[a, b, b + 1], [a, b + 1, a + 1]]
    return vertices, np.array(faces)


def test_a_rectangular_tile_traces_as_the_square_tile_of_the_same_surface(tmp_path):
    """Ridges invariant along y on a 4 x 1 tile (the mesh's bounds) and on a 4 x 4 one: the paths'
    x and z motion is the same, their y is drawn over L_y and wrapped by it, so the tables agree
    to round-off (a tracer or a build that took L_x for L_y, or the reverse, would not: a start
    drawn over the wrong side moves every cell by about a standard error). A white one returns
    every path, and period_x + period_y given lay the same tile."""
    rect, square = write(tmp_path / "rect.ply", *ridges(1.0, 1)), write(tmp_path / "square.ply", *ridges(4.0, 4))
    theta = (0.0, 50.0, 80.0)
    out = {}
    for name, scene in (("rect", {"path": rect}), ("square", {"path": square}),
                        ("given", {"path": rect, "period_x": 4.0, "period_y": 1.0})):
        cfg = mesh_config(**scene, theta=theta)
        cfg["illumination"]["phi_i_deg"] = [30.0]
        out[name] = tables.load(session.run(cfg, tmp_path / f"{name}.h5").tables[0])
    rect_t, square_t = out["rect"], out["square"]
    assert rect_t.scene["period"] == 4.0 and rect_t.scene["period_y"] == 1.0
    assert square_t.scene["period_y"] == 4.0
    for name in ("brdf", "albedo"):
        a, b = rect_t.arrays[name], square_t.arrays[name]
        error = np.hypot(rect_t.arrays[f"{name}_stderr"], square_t.arrays[f"{name}_stderr"])
        print(f"{name}: largest |rect - square| {np.max(np.abs(a - b) / error):.3g} of the combined error")
        assert np.all(np.abs(a - b) <= 0.25 * error + 1e-12), np.max(np.abs(a - b) / error)
    assert np.array_equal(out["given"].arrays["brdf"], rect_t.arrays["brdf"])
    white = tables.load(session.run(mesh_config(rect, albedo=1.0, theta=(0.0, 60.0, 89.0)), tmp_path / "w.h5").tables[0])
    assert np.all(np.abs(white.albedo + white.truncated - 1.0) <= 1e-12) and np.all(white.transmitted == 0.0)
    assert np.all(white.arrays["albedo_order"][:, 1] > 0.01)  # inter-reflections between the ridges


@pytest.mark.parametrize("keys, key", [("period_x = 4.0", "scene.period_y"), ("period_y = 1.0", "scene.period_x"),
                                       ("period = 4.0\nperiod_x = 4.0\nperiod_y = 1.0", "scene.period")])
def test_half_a_rectangular_period_is_refused_in_one_line(keys, key, tmp_path, tmp_path_factory, capsys):
    from microsim.testing.refusals import SMALL_RUN, assert_run_refused

    path = write(tmp_path_factory.mktemp("rect") / "rect.ply", *ridges(1.0, 1))
    assert_run_refused(f'[scene]\nkind = "mesh"\npath = "{path}"\n{keys}\n' + SMALL_RUN, key, tmp_path, capsys)
