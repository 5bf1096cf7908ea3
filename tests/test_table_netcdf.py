"""Tables that xarray reads: dimension scales and CF attributes, so that
``xarray.open_dataset(table, engine="h5netcdf")`` gives named dimensions and coordinates equal to
what :func:`microsim.tables.load` reads; tables of format 1.0 still load."""

from pathlib import Path

import numpy as np
import pytest

from microsim import config, tables
from microsim.core import table_layout
from microsim.tables import netcdf
from microsim.testing import write_table

xr = pytest.importorskip("xarray")
pytest.importorskip("h5netcdf")

DATA = Path(__file__).parent / "data"

#: a small table of every scene kind (and of both sphere shadings), with retro rings and a point
SCENES = {
    "plane": {"kind": "plane"},
    "poisson_spheres": {"kind": "poisson_spheres", "volume_fraction": 0.3},
    "icospheres": {"kind": "poisson_spheres", "volume_fraction": 0.3, "subdivisions": 1, "shading": "flat"},
    "micrograins": {"kind": "micrograins", "tau0": 0.5, "beta": 1.0},
    "vcavities": {"kind": "vcavities", "distribution": "beckmann", "roughness": 0.8},
    "halfspace_medium": {"kind": "halfspace_medium", "phase": "lambert_sphere"},
    "mesh": {"kind": "mesh", "path": str(Path(__file__).parents[1] / "runs/meshes/weave.ply")},
    "heightfield": {"kind": "heightfield", "path": str(Path(__file__).parents[1] / "runs/heightfields/dunes.npy"),
                    "pixel": 1.0, "height_scale": 0.15, "statistics": True},
}


@pytest.fixture(scope="module", params=sorted(SCENES))
def table(request, tmp_path_factory):
    cfg = config.validate({
        "scene": SCENES[request.param],
        "material": {"kind": "lambert", "albedo": 0.8},
        "illumination": {"theta_i_deg": [0.0, 60.0]},
        "sensor": {"cells": 100, "retro_rings": 3, "directions_deg": [[30.0, 0.0], [50.0, 90.0]]},
        "run": {"paths": 2000, "realizations": 2, "seed": 1},
    })
    path = tmp_path_factory.mktemp(request.param) / "table.h5"
    return write_table(cfg, path)


def test_xarray_reads_every_dataset_of_every_group_as_tables_load_does(table):
    loaded = tables.load(table).arrays
    read = {}
    with xr.open_datatree(table, engine="h5netcdf") as tree:
        for path, node in tree.subtree_with_keys:
            own = node.to_dataset(inherit=False)
            for name in own.variables:
                read[name if path == "." else f"{path}/{name}"] = own[name].values
    assert read.keys() == loaded.keys()
    for name, values in loaded.items():
        np.testing.assert_array_equal(read[name], values, err_msg=name)


def test_the_dimensions_are_the_layouts_axes_and_the_coordinates_are_named(table):
    loaded = tables.load(table)
    with xr.open_dataset(table, engine="h5netcdf") as ds:
        for name, variable in ds.variables.items():
            assert variable.dims == tables.DECLARED[name].axes, name
            assert variable.attrs["units"] == netcdf.cf_units(tables.DECLARED[name].unit), name
        assert ds.brdf.dims == ("incidences", "cells") and ds.brdf_order.dims == ("incidences", "orders", "cells")
        assert {"theta_i", "phi_i", "theta_o", "phi_o"} <= set(ds.brdf.coords)
        np.testing.assert_array_equal(ds.theta_i, loaded.theta_i)
        np.testing.assert_array_equal(ds.orders, [1, 2, 3, 4])
        assert ds.brdf.attrs["units"] == "1/sr" and ds.brdf.attrs["ancillary_variables"] == "brdf_stderr"
        assert ds.theta_o.attrs["bounds"] == "theta_o_bounds"
        np.testing.assert_array_equal(ds.theta_o_bounds[:, 0], loaded.arrays["sensor/theta_lo"])
        np.testing.assert_array_equal(ds.phi_o_bounds[:, 1], loaded.arrays["sensor/phi_hi"])
        np.testing.assert_allclose(np.cos(ds.theta_o), loaded.direction[:, 2], rtol=0, atol=1e-15)
        selected = ds.brdf.sel(incidences=1).where(ds.theta_o < 0.5, drop=True)
        assert selected.dims == ("cells",) and selected.size == np.count_nonzero(loaded.arrays["theta_o"] < 0.5)
        assert ds.attrs["format_version"] == table_layout.FORMAT_VERSION
    with xr.open_dataset(table, engine="h5netcdf", group="sensor") as sensor:
        assert sensor.points_direction.dims == ("incidences", "points", "xyz")
        assert sensor.ring_counts.dims == ("rings",)


def test_a_covariance_has_two_named_point_axes(table):
    with xr.open_dataset(table, engine="h5netcdf") as ds:
        assert ds.brdf_points_covariance.dims == ("incidences", "points", "other_points")
        assert ds.brdf_points.attrs["ancillary_variables"] == "brdf_points_stderr brdf_points_covariance"


def test_a_table_of_format_1_0_still_loads():
    """tests/data/table_format_1_0.h5: a Lambertian plane (albedo 0.8, 2 incidences, 100 cells, 3
    retro rings, one point) written by microsim at 9e69431, before the dimension scales."""
    old = tables.load(DATA / "table_format_1_0.h5")
    assert old.attrs["format_version"] == "1.0" and "theta_o" not in old.arrays
    assert old.brdf.shape == (2, old.sensor.n_cells) == (2, 100)
    np.testing.assert_allclose(old.albedo, 0.8, rtol=1e-12)
