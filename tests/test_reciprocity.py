"""A sphere table is reciprocal within its errors.

Incidence directions sit at the centres of sensor rings, so that f(a -> b) (incidence at ring
a's centre, the cell of ring b at relative azimuth phi) and f(b -> a) (the other way round, at
the same relative azimuth) estimate the same BRDF value up to the cell averaging.
"""

import numpy as np
import pytest

from microsim.testing import trace_table
from microsim.testing.reciprocity import azimuth_matched_z, cell_cosines
from microsim.tracer.sensor import Sensor

CELLS = 300
RINGS = (2, 4, 6, 8, 9)
pytestmark = pytest.mark.slow  # 2 M paths


@pytest.fixture(scope="module")
def table(tmp_path_factory):
    from microsim import config

    theta = np.degrees(Sensor.build(CELLS).ring_centres()[list(RINGS)])
    cfg = config.validate({
        "scene": {"kind": "poisson_spheres", "volume_fraction": 0.3, "tile": 16.0, "depth": 16.0},
        "material": {"kind": "lambert", "albedo": 0.8},
        "illumination": {"theta_i_deg": theta.tolist()},
        "sensor": {"cells": CELLS},
        "run": {"paths": 400_000, "realizations": 16, "seed": 11},
    })
    return trace_table(cfg, tmp_path_factory.mktemp("recip") / "recip.h5", workers=2)


def worst_z(value, stderr, sensor):
    """Largest |value(a -> b) - value(b -> a)| over its combined standard error, and the pair count."""
    z = azimuth_matched_z(value, stderr, sensor, RINGS)
    return z.max(), len(z)


def test_reciprocal_within_4_5_combined_standard_errors(table):
    assert np.allclose(table.theta_i, table.sensor.ring_centres()[list(RINGS)])
    assert np.all(table.brdf_stderr > 0)
    worst, compared = worst_z(table.brdf, table.brdf_stderr, table.sensor)
    assert compared >= 20
    assert worst <= 4.5


def test_a_non_reciprocal_quantity_is_detected(table):
    """Power of the check: f * cos(theta_o) is not reciprocal, and the same comparison rejects it."""
    mu_cell = cell_cosines(table.sensor)
    worst, _ = worst_z(table.brdf * mu_cell, table.brdf_stderr * mu_cell, table.sensor)
    assert worst > 4.5
