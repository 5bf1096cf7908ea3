"""Damaged or partial tables: checksums on every dataset, presence, shape and
NaN checks on loading, and one line naming what is wrong from `microsim compare`."""

import hashlib
import re
import shutil

import h5py
import numpy as np
import pytest

from microsim import config, tables
from microsim.analysis import compare
from microsim.cli import main
from microsim.testing import write_table
from microsim.testing.refusals import assert_refused

COMPARE = ["--model", "lambert", "--param", "albedo=0.5", "--order", "1"]


def plane_table(directory, **sensor):
    """A Lambertian plane, 2 incidences x 20 cells and ``sensor``'s keys: small, but a real table."""
    cfg = config.validate({
        "scene": {"kind": "plane"},
        "material": {"kind": "lambert", "albedo": 0.5},
        "illumination": {"theta_i_deg": [0.0, 60.0]},
        "sensor": {"cells": 20, **sensor},
        "run": {"paths": 2000, "realizations": 2, "seed": 1},
    })
    return write_table(cfg, directory / "plane.h5")


@pytest.fixture(scope="module")
def good_table(tmp_path_factory):
    return plane_table(tmp_path_factory.mktemp("good"))


def damaged_copy(good_table, directory, damage):
    """A copy of the good table with ``damage(h5)`` applied to it."""
    path = directory / "damaged.h5"
    shutil.copyfile(good_table, path)
    with h5py.File(path, "r+") as h5:
        damage(h5)
    return path


def compare_error(path, capsys) -> str:
    """The one line `microsim compare` prints on stderr for a bad table (exit status 2)."""
    line = assert_refused(["compare", path, *COMPARE], capsys)
    assert line.startswith(f"microsim: error: TABLE.h5: {path}: ")
    return line


def replace_brdf_by_wrong_shape(h5):
    n_i = h5["brdf"].shape[0]
    del h5["brdf"]
    h5["brdf"] = np.zeros((n_i, 7))


def edit(name, change):
    """A damage that edits dataset ``name`` as another program would: ``change(values)`` in
    place, its digest made to agree (only the values can tell)."""
    def damage(h5):
        values = h5[name][()]
        change(values)
        del h5[name]
        h5.create_dataset(name, data=values)
        h5[name].attrs["sha256"] = hashlib.sha256(values.tobytes()).hexdigest()
    return damage


def write_nan_into_a_cell(h5):
    """NaN in a table as if it had been written so: its digest agrees."""
    edit("brdf", lambda brdf: brdf.__setitem__((1, 3), np.nan))(h5)


def move_a_cell_between_rings(h5):
    """Ring counts of as many cells, not those of the stored bounds: the second ring loses a cell
    to the third."""
    edit("sensor/ring_counts", lambda counts: (counts.__setitem__(1, counts[1] - 1),
                                               counts.__setitem__(2, counts[2] + 1)))(h5)


@pytest.mark.parametrize("damage, expected", [
    (lambda h5: h5.__delitem__("brdf_order_stderr"), "brdf_order_stderr is missing"),
    (lambda h5: h5.__delitem__("albedo_order"), "albedo_order is missing"),
    (replace_brdf_by_wrong_shape, "brdf has shape (2, 7), expected (2, {cells}) (incidences x cells)"),
    (write_nan_into_a_cell, "brdf holds NaN in 1 of {values} values"),
    # values no run gives, edited in by another program
    (edit("incidence/theta", lambda theta: theta.__setitem__(1, 10.0)),
     "incidence/theta holds 10 rad (572.958 deg), outside [0, pi/2)"),
    (edit("brdf_stderr", lambda e: e.__setitem__((0, 2), -e[0, 2])),
     "brdf_stderr holds a negative value in 1 of {values} values"),
    (edit("albedo", lambda a: a.__setitem__(0, -0.5)), "albedo holds a negative value in 1 of 2 values"),
    (move_a_cell_between_rings, "sensor/theta_lo disagrees with sensor/ring_counts (cell 7:"),
    (lambda h5: h5.attrs.__delitem__("microsim_version"),
     "not a microsim table (no microsim_version and config_toml attributes)"),
    (lambda h5: h5.attrs.__setitem__("format_version", "2.0"),
     "format_version 2.0: this microsim reads tables of format 1.x"),
], ids=["no brdf_order_stderr", "no albedo_order", "brdf of the wrong shape", "NaN in brdf", "theta beyond pi/2",
        "negative brdf_stderr", "negative albedo", "ring counts against bounds", "no microsim_version",
        "a later format"])
def test_a_damaged_table_gives_one_line_naming_the_dataset(good_table, tmp_path, capsys, damage, expected):
    cells = tables.load(good_table).sensor.n_cells
    path = damaged_copy(good_table, tmp_path, damage)
    assert expected.format(cells=cells, values=2 * cells) in compare_error(path, capsys)


@pytest.fixture(scope="module")
def points_table(tmp_path_factory):
    """The good table's plane with three next-event points."""
    return plane_table(tmp_path_factory.mktemp("points"), directions_deg=[[0, 0], [30, 45], [60, 180]])


def replace(name, shape):
    """A damage that stores dataset ``name`` with the wrong ``shape``."""
    def damage(h5):
        del h5[name]
        h5[name] = np.zeros(shape)
    return damage


@pytest.mark.parametrize("damage, expected", [
    (replace("brdf_points", (2, 4)), "brdf_points has shape (2, 4), expected (2, 3) (incidences x points)"),
    (replace("brdf_points_covariance", (2, 3, 2)),
     "brdf_points_covariance has shape (2, 3, 2), expected (2, 3, 3) (incidences x points x other_points)"),
    (replace("other_points", (2,)), "other_points has shape (2,), expected (3,) (other_points)"),
], ids=["a point too many", "a covariance short of a point", "a covariance's second axis short of a point"])
def test_an_estimator_s_axis_has_one_length_in_a_table(points_table, tmp_path, capsys, damage, expected):
    """The points' axis is as long as the points the table's sensor/points_kind holds, in every
    dataset that has it, the covariance's second axis too."""
    path = damaged_copy(points_table, tmp_path, damage)
    assert expected in compare_error(path, capsys)


def brdf_chunk(good_table):
    """(file offset, bytes) of brdf's stored values: one chunk, followed by its checksum. (The
    bytes alone do not find it: a plane's brdf equals its brdf_orders12.)"""
    with h5py.File(good_table, "r") as h5:
        dataset = h5["brdf"]
        assert dataset.id.get_num_chunks() == 1
        start = dataset.id.get_chunk_info(0).byte_offset
        brdf = dataset[()].tobytes()
    assert good_table.read_bytes()[start:start + len(brdf)] == brdf
    return start, brdf


def test_zeroed_bytes_fail_the_checksum(good_table, tmp_path, capsys):
    start, brdf = brdf_chunk(good_table)
    data = bytearray(good_table.read_bytes())
    # zero the middle of the values: a chunk zeroed whole, checksum included, would pass (the
    # Fletcher-32 sum of zeros is zero)
    data[start + 16:start + len(brdf) - 16] = bytes(len(brdf) - 32)
    path = tmp_path / "zeroed.h5"
    path.write_bytes(bytes(data))
    assert compare_error(path, capsys).endswith("dataset brdf is damaged (checksum mismatch)")


def test_a_chunk_zeroed_with_its_checksum_fails_the_digest(good_table, tmp_path, capsys):
    """Fletcher-32 of zeros is zero: a chunk zeroed whole, checksum included, passes it; the
    SHA-256 digest in the dataset's (checksummed) header does not."""
    start, brdf = brdf_chunk(good_table)
    data = bytearray(good_table.read_bytes())
    data[start:start + len(brdf) + 4] = bytes(len(brdf) + 4)  # the values and their Fletcher-32 sum
    path = tmp_path / "zeroed.h5"
    path.write_bytes(bytes(data))
    assert compare_error(path, capsys).endswith("dataset brdf is damaged (SHA-256 mismatch)")


def test_a_damaged_header_fails_its_checksum(good_table, tmp_path, capsys):
    with h5py.File(good_table, "r") as h5:
        header = h5py.h5o.get_info(h5["brdf"].id).addr
    data = bytearray(good_table.read_bytes())
    data[header + 16:header + 48] = bytes(32)
    path = tmp_path / "header.h5"
    path.write_bytes(bytes(data))
    assert re.search(r": brdf is damaged \(.*metadata checksum.*\)$", compare_error(path, capsys))


def test_written_datasets_carry_checksums_and_tables_without_them_still_compare(good_table, tmp_path, capsys):
    names = []
    with h5py.File(good_table, "r") as h5:
        h5.visititems(lambda name, obj: names.append(name) if isinstance(obj, h5py.Dataset) else None)
        assert names and all(h5[name].fletcher32 for name in names)
    assert main(["compare", str(good_table), *COMPARE]) == 0
    older = tmp_path / "older.h5"  # the same table as written before checksums
    with h5py.File(good_table, "r") as src, h5py.File(older, "w") as dst:
        for key, value in src.attrs.items():
            dst.attrs[key] = value
        for name in names:
            dst[name] = src[name][()]
        for group in ("sensor", "scene"):
            dst.require_group(group).attrs.update(src[group].attrs)
    assert main(["compare", str(older), *COMPARE]) == 0
    assert "overall" in capsys.readouterr().out


def test_nan_from_the_model_is_an_error_naming_it(good_table):
    class NaNModel:
        name, values = "nan_model", {}

        def __call__(self, wi, wo):
            return np.full(np.shape(wo)[:-1], np.nan)

        def __repr__(self):
            return "NaNModel()"

    table = tables.load(good_table)
    cells = table.brdf.size
    with pytest.raises(ValueError, match=rf"^model NaNModel\(\) is NaN or infinite in {cells} of {cells} cells$"):
        compare.compare(table, NaNModel(), "1")


def test_a_foreign_hdf5_file_is_not_a_microsim_table(tmp_path, capsys):
    """An HDF5 file that no run wrote is refused as not a microsim table, not as a table that
    lacks its scene."""
    path = tmp_path / "foreign.h5"
    with h5py.File(path, "w") as h5:
        h5["data"] = np.arange(3.0)
    assert compare_error(path, capsys).endswith("not a microsim table (no microsim_version and config_toml attributes)")


def test_a_missing_table_is_named_in_one_line(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"^\S*none\.h5: no such file$"):
        tables.load(tmp_path / "none.h5")
