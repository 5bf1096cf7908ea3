"""Single scattering of dilute Lambertian spheres against radiative transfer (acceptance d).

The order-1 table of a Boolean sphere suspension with max_order = 1 must match the exact
single-scattering BRDF of a half space of Lambert-sphere particles,
c p(-wi.wo) / (mu_i + mu_o) (lambert_sphere_brdf.txt, Eq. 1 and 10), averaged over every cell
with the cos(theta_o) weight, away from the retro direction where shadow hiding (the
opposition effect of finite particles) adds light.

Finite particles also shift the rest of the BRDF: a hit point sits up to one radius above its
sphere's centre, so it is less attenuated than a point scatterer at the centre's depth; the
excess over radiative transfer grows linearly with r / l = -3/4 ln(1 - phi) (median over cells,
theta_i = 0, 30, 60 deg: +0.9 to +1.8 % at phi = 0.005, +4.4 to +5.0 % at 0.02, +7.9 to +9.3 %
at 0.04; fit 0.005 + 2.5 r / l), and an independent brute-force tracer on exact spheres gives
the same excess at phi = 0.02 (+4.6 to +5.9 %): benchmarks/dilute_limit.py. The 3 % check is
therefore made where the suspension is dilute enough for radiative transfer to hold to that
accuracy, phi = 0.005 (l = 266 radii).
"""

import numpy as np
import pytest

from microsim.models.phase import phase_lambert_sphere

ALBEDO = 0.9


@pytest.fixture(scope="module")
def table(tmp_path_factory):
    from microsim import config, runner, tables

    # tile 24 radii instead of the default 64 (3 free paths): rays cross it a few times per
    # free path, which only matters within 5 deg of the horizon; it keeps the scene at ~1300 spheres.
    cfg = config.validate({
        "scene": {"kind": "poisson_spheres", "volume_fraction": 0.005, "tile": 24.0},
        "material": {"kind": "lambert", "albedo": ALBEDO},
        "illumination": {"theta_i_deg": [0.0, 30.0, 60.0]},
        "sensor": {"cells": 100},
        "run": {"paths": 1_200_000, "realizations": 16, "seed": 3, "max_order": 1},
    })
    path = tmp_path_factory.mktemp("single") / "single.h5"
    tables.write(path, runner.run(cfg, workers=2), cfg)
    return tables.load(path)


def test_order_1_matches_the_single_scattering_brdf_away_from_retro(table):
    sensor = table.sensor
    assert np.all(table.brdf_order[:, 1:, :] == 0.0)
    for i, wi in enumerate(table.wi):
        model = sensor.cell_average(lambda wo: ALBEDO * phase_lambert_sphere(-(wo @ wi)) / (wi[2] + wo[:, 2]), 6, 6)
        away = np.degrees(np.arccos(np.clip(table.direction @ wi, -1, 1))) > 10.0
        relative = table.brdf_order[i, 0, away] / model[away] - 1.0
        assert np.median(np.abs(relative)) <= 0.03

