"""A flat Lambertian plane is exactly albedo / pi in every cell, single scattering only."""

import numpy as np
import pytest

from microsim.testing import trace_table

ALBEDO = 0.5
pytestmark = pytest.mark.slow  # 8 M paths


@pytest.fixture(scope="module")
def plane_table(tmp_path_factory):
    from microsim import config

    cfg = config.validate({
        "scene": {"kind": "plane"},
        "material": {"kind": "lambert", "albedo": ALBEDO},
        "illumination": {"theta_i_deg": [0.0, 45.0, 80.0]},
        "sensor": {"cells": 3240},
        # 8e6 paths: the smallest cells (at the horizon, P_C / pi = 1.4e-5) still get ~110 paths, so
        # their estimates and standard errors are close enough to normal for a 4.5-sigma bound on
        # every one of the 9720 cells (with ~27 paths, Poisson tails and the estimated sigma fail it).
        "run": {"paths": 8_000_000, "realizations": 256, "seed": 1},
    })
    return trace_table(cfg, tmp_path_factory.mktemp("plane") / "plane.h5")


def test_every_cell_within_4_5_standard_errors_of_albedo_over_pi(plane_table):
    t = plane_table
    assert np.all(t.brdf_stderr > 0)
    z = (t.brdf - ALBEDO / np.pi) / t.brdf_stderr
    assert np.max(np.abs(z)) <= 4.5


def test_mean_over_cells_within_half_a_percent(plane_table):
    mean = plane_table.brdf.mean(axis=1)
    assert np.all(np.abs(mean / (ALBEDO / np.pi) - 1) <= 0.005)


def test_albedo_within_4_standard_errors(plane_table):
    t = plane_table
    # every path leaves with weight exactly 0.5, so the estimate is exact up to rounding
    assert np.all(np.abs(t.albedo - ALBEDO) <= 4 * t.albedo_stderr + 1e-12)


def test_orders_2_and_up_are_exactly_zero(plane_table):
    t = plane_table
    assert np.all(t.brdf_order[:, 1:, :] == 0.0)
    assert np.array_equal(t.brdf_order[:, 0, :], t.brdf)
    assert np.all(t.transmitted == 0.0) and np.all(t.truncated == 0.0)
