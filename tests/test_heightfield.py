"""The heightfield scene (geometry/heightfield.py): a periodic height array, triangulated.

- A flat array is the plane: the same paths give the plane's cells bit for bit.
- A white Lambertian bumpy array is closed: every path leaves (albedo 1 to 1e-12) up to 89 deg.
- The triangulation wraps: the grid's last row and column of vertices repeat the first a period
  away, and its projected area is the tile's.
- Bad arrays are refused in one line naming scene.path, exit 2, nothing written.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from microsim import tables
from microsim.app import session
from microsim.geometry.heightfield import triangulate


def bumps(n: int = 32) -> np.ndarray:
    x = np.arange(n) / n * 2 * math.pi
    gx, gy = np.meshgrid(x, x, indexing="ij")
    return 0.5 * np.sin(gx) * np.cos(2 * gy)


def config(path, albedo=0.8, theta=(0.0, 60.0), pixel=0.1) -> dict:
    return {"scene": {"kind": "heightfield", "path": str(path), "pixel": pixel},
            "material": {"kind": "lambert", "albedo": albedo}, "illumination": {"theta_i_deg": list(theta)},
            "sensor": {"cells": 100}, "run": {"paths": 40_000, "realizations": 4, "seed": 3}}


def test_a_flat_heightfield_is_the_plane_bit_for_bit(tmp_path):
    np.save(tmp_path / "flat.npy", np.zeros((8, 8)))
    cfg = config(tmp_path / "flat.npy", theta=(0.0, 45.0, 85.0), pixel=0.125)  # a period of 1
    flat = tables.load(session.run(cfg, tmp_path / "h.h5").tables[0])
    plane = tables.load(session.run({**cfg, "scene": {"kind": "plane", "tile": 1.0}}, tmp_path / "p.h5").tables[0])
    for name in ("brdf", "brdf_order", "brdf_stderr", "albedo"):
        assert np.array_equal(flat.arrays[name], plane.arrays[name]), name


def test_a_white_bumpy_heightfield_returns_every_path(tmp_path):
    np.savez(tmp_path / "bumps.npz", height=bumps(), other=np.ones(3))
    table = tables.load(session.run(config(tmp_path / "bumps.npz", albedo=1.0, theta=(0.0, 60.0, 89.0)),
                                    tmp_path / "w.h5").tables[0])
    np.testing.assert_allclose(table.albedo, 1.0, rtol=0, atol=1e-12)
    assert not table.transmitted.any() and not table.truncated.any()
    assert table.scene["period"] == pytest.approx(3.2) and table.scene["surface_triangles"] == 2 * 32 * 32


def test_the_grid_wraps_at_the_period():
    h = bumps(8)
    vertices, faces = triangulate(h, 0.5)
    grid = vertices.reshape(9, 9, 3)
    assert np.array_equal(grid[-1, :, 2], grid[0, :, 2]) and np.array_equal(grid[:, -1, 2], grid[:, 0, 2])
    corners = vertices[faces]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    assert np.all(cross[:, 2] > 0) and 0.5 * cross[:, 2].sum() == pytest.approx(16.0, rel=1e-12)


@pytest.mark.parametrize("make, message", [
    (lambda d: str(d / "absent.npy"), "no such file"),
    (lambda d: np.save(d / "nan.npy", np.where(np.eye(8) > 0, np.nan, 0.0)) or str(d / "nan.npy"), "NaN"),
    (lambda d: np.save(d / "wide.npy", np.zeros((8, 16))) or str(d / "wide.npy"), "square array"),
    (lambda d: np.savez(d / "two.npz", a=np.zeros((8, 8)), b=np.zeros((8, 8))) or str(d / "two.npz"), "'height'"),
    (lambda d: (d / "text.npy").write_text("no array") and str(d / "text.npy"), "not a NumPy file"),
])
def test_a_bad_height_array_is_refused_in_one_line(make, message, tmp_path, tmp_path_factory, capsys):
    from microsim.testing.refusals import SMALL_RUN, assert_run_refused

    path = make(tmp_path_factory.mktemp("heights"))  # beside the run's directory, which must stay empty
    assert_run_refused(f'[scene]\nkind = "heightfield"\npath = "{path}"\n' + SMALL_RUN, message, tmp_path, capsys)


def test_the_cells_are_split_along_alternating_diagonals():
    """Cell (i, j) is split along (i, j)-(i+1, j+1) where i + j is even and along (i+1, j)-(i, j+1)
    where it is odd (microsim.geometry.gaussian_surface: the facets' x and y slopes are then uncorrelated
    on average)."""
    vertices, faces = triangulate(np.zeros((2, 2)), 1.0)
    n = 2

    def diagonal(cell):  # the edge the cell's two triangles share, as grid corners
        i, j = divmod(cell, n)
        first, second = set(faces[cell]), set(faces[n * n + cell])
        shared = sorted(tuple(vertices[k, :2] - [i, j]) for k in first & second)
        return shared

    assert diagonal(0) == [(0.0, 0.0), (1.0, 1.0)] and diagonal(3) == [(0.0, 0.0), (1.0, 1.0)]
    assert diagonal(1) == [(0.0, 1.0), (1.0, 0.0)] and diagonal(2) == [(0.0, 1.0), (1.0, 0.0)]


def test_a_steep_surface_is_said_to_be_slow_before_it_traces_and_its_rate_after(tmp_path, capsys):
    """Integer heights times 100 at pixel 0.1 (a surface 2500 times its tile's area) trace many
    times slower than a gentle one: the run says so before it traces (stderr), and after it with
    the rate it measured; a gentle surface gets no such note."""
    from microsim.cli import main

    rng = np.random.default_rng(1)
    notes = {}
    for name, heights, scale in (("steep", rng.integers(0, 5, (16, 16)).astype(float), 100.0),
                                 ("gentle", 0.05 * rng.normal(size=(16, 16)), 1.0)):
        np.save(tmp_path / f"{name}.npy", heights)
        (tmp_path / f"{name}.toml").write_text(
            f'[scene]\nkind = "heightfield"\npath = "{tmp_path / name}.npy"\npixel = 0.1\nheight_scale = {scale}\n'
            '[material]\nkind = "lambert"\nalbedo = 0.8\n[illumination]\ntheta_i_deg = [30.0]\n[sensor]\ncells = 50\n'
            '[run]\npaths = 2000\nrealizations = 2\n')
        assert main(["run", str(tmp_path / f"{name}.toml"), "--out", str(tmp_path / f"{name}.h5")]) == 0
        notes[name] = capsys.readouterr()
    before = notes["steep"].err.strip().splitlines()
    assert len(before) == 1 and before[0].startswith("note: scene: a steep surface") and "times the tile's area" in \
        before[0], before
    after = [line for line in notes["steep"].out.splitlines() if "steep surface" in line]
    assert len(after) == 1 and after[0].endswith("paths/s here"), notes["steep"].out
    assert "steep surface" not in notes["gentle"].err + notes["gentle"].out
