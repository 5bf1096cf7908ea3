"""`microsim export`: the MERL binary read back by a reader written here from
the format's description, and the netCDF grid in Eradiate's mqdiffuse layout read by xarray;
what either cannot hold, refused in one line."""

import numpy as np
import pytest

from microsim import tables
from microsim.cli import main
from microsim.models.tabulated import TabulatedBRDF
from microsim.testing import write_table
from microsim.testing.refusals import assert_refused

xr = pytest.importorskip("xarray")
pytest.importorskip("h5netcdf")

SPHERES = {
    "scene": {"kind": "poisson_spheres", "volume_fraction": 0.3},
    "material": {"kind": "lambert", "albedo": 0.8},
    "sensor": {"cells": 400},
    "run": {"paths": 10_000, "realizations": 4, "seed": 1},
}


def traced(directory, name, illumination):
    return write_table({**SPHERES, "illumination": illumination}, directory / f"{name}.h5")


@pytest.fixture(scope="module")
def full(tmp_path_factory):
    return traced(tmp_path_factory.mktemp("full"), "full", {"incidences": 13})


# --- a MERL reader, from the format's description (Matusik et al. 2003, BRDFRead.cpp) ---------
# The file: int32 dims (90, 90, 180), then red, green, blue blocks of 90 * 90 * 180 float64,
# little-endian; the value of a bin is stored / scale, scales 1/1500, 1.15/1500, 1.66/1500. A
# pair of directions (in, out) goes to half vector h = normalize(in + out) with angles
# (theta_h, phi_h) and the difference vector, in turned by -phi_h about z and by -theta_h about
# y, with angles (theta_d, phi_d); bins: theta_h -> int(sqrt(theta_h / (pi/2)) * 90),
# theta_d -> int(theta_d / (pi/2) * 90), phi_d (+ pi if negative) -> int(phi_d / pi * 180),
# each clamped; index = phi + 180 * (theta_d + 90 * theta_h).

SCALES = np.array([1.0, 1.15, 1.66]) / 1500.0


def read_merl(path):
    with open(path, "rb") as handle:
        dims = np.fromfile(handle, "<i4", 3)
        values = np.fromfile(handle, "<f8")
    assert dims.tolist() == [90, 90, 180] and values.size == 3 * 90 * 90 * 180
    return values.reshape(3, -1) * SCALES[:, None]


def merl_index(w_in, w_out):
    half = w_in + w_out
    half /= np.linalg.norm(half, axis=-1, keepdims=True)
    theta_h, phi_h = np.arccos(np.clip(half[:, 2], -1, 1)), np.arctan2(half[:, 1], half[:, 0])
    d = turn(turn(w_in, -phi_h, axis=2), -theta_h, axis=1)
    theta_d, phi_d = np.arccos(np.clip(d[:, 2], -1, 1)), np.arctan2(d[:, 1], d[:, 0])
    phi_d = np.where(phi_d < 0, phi_d + np.pi, phi_d)
    i_h = np.clip((np.sqrt(np.maximum(theta_h, 0) / (np.pi / 2)) * 90).astype(int), 0, 89)
    i_d = np.clip((theta_d / (np.pi / 2) * 90).astype(int), 0, 89)
    i_p = np.clip((phi_d / np.pi * 180).astype(int), 0, 179)
    return i_p + 180 * (i_d + 90 * i_h)


def turn(v, angle, axis):
    """``v`` (n, 3) turned by ``angle`` (n,) about the coordinate axis ``axis`` (1: y, 2: z)."""
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = v.T
    if axis == 2:
        return np.stack([c * x - s * y, s * x + c * y, z], 1)
    return np.stack([c * x + s * z, y, -s * x + c * z], 1)


def bin_centre_pairs():
    """(in, out) at the centre of every bin in index space, in file order, built here from the
    description: the difference vector at (theta_d, phi_d) turned by theta_h about y (phi_h = 0),
    the outgoing direction its mirror image about the half vector."""
    i_h, i_d, i_p = np.meshgrid(np.arange(90), np.arange(90), np.arange(180), indexing="ij")
    theta_h = ((i_h.ravel() + 0.5) / 90) ** 2 * np.pi / 2
    theta_d, phi_d = (i_d.ravel() + 0.5) / 90 * np.pi / 2, (i_p.ravel() + 0.5) / 180 * np.pi
    d = np.stack([np.sin(theta_d) * np.cos(phi_d), np.sin(theta_d) * np.sin(phi_d), np.cos(theta_d)], 1)
    w_in = turn(d, theta_h, axis=1)
    h = np.stack([np.sin(theta_h), 0 * theta_h, np.cos(theta_h)], 1)
    w_out = 2 * np.sum(w_in * h, axis=1, keepdims=True) * h - w_in
    return w_in, w_out


def test_the_merl_file_read_back_is_the_tabulated_brdf_at_every_bin_centre(full, tmp_path):
    out = tmp_path / "full.binary"
    assert main(["export", str(full), "--format", "merl", "--out", str(out)]) == 0
    channels = read_merl(out)
    w_in, w_out = bin_centre_pairs()
    expected = TabulatedBRDF(tables.load(full))(w_in, w_out)
    for channel in channels:  # grey: three channels alike, each within float64 rounding of f
        np.testing.assert_allclose(channel, expected, rtol=4e-16, atol=0)
    above = (w_in[:, 2] > 0) & (w_out[:, 2] > 0)
    assert np.array_equal(merl_index(w_in[above], w_out[above]), np.flatnonzero(above))
    assert np.all(channels[:, ~above] == 0) and np.all(channels[:, above] > 0)
    assert above.mean() > 0.5


def test_the_netcdf_grid_opens_in_xarray_in_eradiates_layout(full, tmp_path):
    out = tmp_path / "full.nc"
    assert main(["export", str(full), "--format", "netcdf-grid", "--out", str(out)]) == 0
    with xr.open_dataset(out, engine="h5netcdf") as ds:
        assert ds.brdf.dims == ("cos_theta_o", "phi_d", "cos_theta_i") and ds.brdf.attrs["units"] == "1/sr"
        assert ds.cos_theta_o.attrs["units"] == ds.cos_theta_i.attrs["units"] == "dimensionless"
        assert ds.phi_d.attrs["units"] == "rad"
        for name in ("cos_theta_o", "cos_theta_i"):  # evenly spaced, as mqdiffuse checks
            np.testing.assert_allclose(ds[name], np.linspace(0, 1, ds[name].size), rtol=0, atol=1e-15)
        np.testing.assert_allclose(ds.phi_d, np.linspace(0, 2 * np.pi, ds.phi_d.size, endpoint=False), atol=1e-15)
        tabulated = TabulatedBRDF(tables.load(full))
        k, j, i = 40, 30, 70  # a node: f there, phi_d = phi_o - phi_i
        mu_o, phi, mu_i = float(ds.cos_theta_o[k]), float(ds.phi_d[j]), float(ds.cos_theta_i[i])
        wo = [np.sqrt(1 - mu_o**2) * np.cos(phi + 0.3), np.sqrt(1 - mu_o**2) * np.sin(phi + 0.3), mu_o]
        wi = [np.sqrt(1 - mu_i**2) * np.cos(0.3), np.sqrt(1 - mu_i**2) * np.sin(0.3), mu_i]
        np.testing.assert_allclose(float(ds.brdf[k, j, i]), tabulated(wi, wo), rtol=1e-12)
        assert np.all(ds.brdf.values > 0)


@pytest.fixture(scope="module")
def anisotropic(tmp_path_factory):
    return traced(tmp_path_factory.mktemp("aniso"), "aniso", {"incidences": 13, "azimuths": 2})


@pytest.mark.parametrize("fmt", ["merl", "netcdf-grid"])
def test_an_anisotropic_table_is_refused(anisotropic, tmp_path, capsys, fmt):
    assert_refused(["export", str(anisotropic), "--format", fmt, "--out", str(tmp_path / "x")], capsys,
                   "anisotropic", "2 azimuths")
    assert not (tmp_path / "x").exists()


def test_bad_exports_are_refused_in_one_line_and_write_nothing(full, tmp_path, capsys):
    few = traced(tmp_path, "few", {"theta_i_deg": [0.0, 30.0, 60.0, 85.0]})
    taken = tmp_path / "taken.binary"
    taken.write_bytes(b"keep me")
    before = sorted(tmp_path.iterdir())
    for argv, words in (
            (["export", str(few), "--format", "merl"], ("not a full BRDF", "illumination.incidences")),
            (["export", str(full), "--format", "obj"], ("--format", "merl", "netcdf-grid")),
            (["export", str(tmp_path / "missing.h5"), "--format", "merl"], ("missing.h5", "not found")),
            (["export", str(full), "--format", "merl", "--out", str(taken)], ("--out", "exists", "--force"))):
        assert_refused(argv, capsys, *words)
    assert sorted(tmp_path.iterdir()) == before and taken.read_bytes() == b"keep me"


def test_no_export_writes_over_its_own_table(full, tmp_path, capsys):
    """`--out` the table itself (or a hard link to it) is refused, with --force or not: the export
    would replace the only copy of the BRDF it reads."""
    table = tmp_path / "own.h5"
    table.write_bytes(full.read_bytes())
    link = tmp_path / "link.binary"
    link.hardlink_to(table)
    before = table.read_bytes()
    for out in (table, link):
        for force in ([], ["--force"]):
            assert_refused(["export", str(table), "--format", "merl", "--out", str(out), *force], capsys,
                           "--out", "the table", "another name")
    assert table.read_bytes() == before


@pytest.mark.parametrize("fmt", ["merl", "netcdf-grid"])
def test_an_unwritable_folder_is_refused_before_the_work(full, capsys, fmt):
    """A folder nothing can write in, even root (/sys: permission bits say writable to root), is
    refused in one line before the table is read."""
    assert_refused(["export", str(full), "--format", fmt, "--out", "/sys/brdf.out"], capsys,
                   "--out", "/sys", "not writable")


SLOW_EXPORT = """
import sys, time
from microsim.interop import exporters
from microsim.cli import main

def slow(tabulated, path):
    path.write_bytes(b"half")
    time.sleep(120)

exporters.WRITERS["merl"] = slow
sys.exit(main(sys.argv[1:]))
"""


def test_ctrl_c_during_an_export_leaves_no_temporary(full, tmp_path):
    """Ctrl-C while the file is written: one line, the process dies of SIGINT, and neither the
    output nor its temporary is left in the folder."""
    import signal
    import sys

    from microsim.testing.interruptions import interrupt_group

    out = tmp_path / "brdf.binary"
    command = [sys.executable, "-c", SLOW_EXPORT, "export", str(full), "--format", "merl", "--out", str(out)]
    status, stderr = interrupt_group(command, tmp_path, lambda process: any(tmp_path.glob(".brdf.binary.*")))
    assert status == -signal.SIGINT and stderr == "microsim: error: stopped by SIGINT\n", stderr
    assert list(tmp_path.iterdir()) == []
