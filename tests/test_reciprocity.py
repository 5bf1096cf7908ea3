"""Acceptance c: a sphere table is reciprocal within its errors.

Incidence directions sit at the centres of sensor rings, so that f(a -> b) (incidence at ring
a's centre, the cell of ring b at relative azimuth phi) and f(b -> a) (the other way round, at
the same relative azimuth) estimate the same BRDF value up to the cell averaging.
"""

from fractions import Fraction

import numpy as np
import pytest

from microsim.tracer.sensor import Sensor

CELLS = 300
RINGS = (2, 4, 6, 8, 9)
pytestmark = pytest.mark.slow  # 2 M paths


@pytest.fixture(scope="module")
def table(tmp_path_factory):
    from microsim import config, tables
    from microsim.run import runner

    theta = np.degrees(Sensor.build(CELLS).ring_centres()[list(RINGS)])
    cfg = config.validate({
        "scene": {"kind": "poisson_spheres", "volume_fraction": 0.3, "tile": 16.0, "depth": 16.0},
        "material": {"kind": "lambert", "albedo": 0.8},
        "illumination": {"theta_i_deg": theta.tolist()},
        "sensor": {"cells": CELLS},
        "run": {"paths": 400_000, "realizations": 16, "seed": 11},
    })
    path = tmp_path_factory.mktemp("recip") / "recip.h5"
    tables.write(path, runner.run(cfg, workers=2), cfg)
    return tables.load(path)


def matched_cells(sensor, ring_a, ring_b):
    """Pairs (cell of ring b, cell of ring a) whose centres have the same azimuth."""
    na, nb = int(sensor.ring_counts[ring_a]), int(sensor.ring_counts[ring_b])
    by_azimuth = {Fraction(j, na): sensor.ring_start[ring_a] + j for j in range(na)}
    return [(sensor.ring_start[ring_b] + j, by_azimuth[Fraction(j, nb)])
            for j in range(nb) if Fraction(j, nb) in by_azimuth]


def reciprocal_pairs(sensor):
    """(incidence a, cell at ring b, incidence b, cell at ring a) at equal relative azimuth, a < b."""
    for ia, ring_a in enumerate(RINGS):
        for ib, ring_b in enumerate(RINGS):
            if ib > ia:
                for cell_b, cell_a in matched_cells(sensor, ring_a, ring_b):
                    yield ia, cell_b, ib, cell_a


def worst_z(value, stderr, sensor):
    """Largest |value(a -> b) - value(b -> a)| over its combined standard error, and the pair count."""
    z = [abs(value[ia, cb] - value[ib, ca]) / np.hypot(stderr[ia, cb], stderr[ib, ca])
         for ia, cb, ib, ca in reciprocal_pairs(sensor)]
    return max(z), len(z)


def test_reciprocal_within_4_5_combined_standard_errors(table):
    assert np.allclose(table.theta_i, table.sensor.ring_centres()[list(RINGS)])
    assert np.all(table.brdf_stderr > 0)
    worst, compared = worst_z(table.brdf, table.brdf_stderr, table.sensor)
    assert compared >= 20
    assert worst <= 4.5


def test_a_non_reciprocal_quantity_is_detected(table):
    """Power of the check: f * cos(theta_o) is not reciprocal, and the same comparison rejects it."""
    t_lo, t_hi = table.sensor.cell_bounds()[:2]
    mu_cell = np.cos(0.5 * (t_lo + t_hi))
    worst, _ = worst_z(table.brdf * mu_cell, table.brdf_stderr * mu_cell, table.sensor)
    assert worst > 4.5
