"""Single scattering of Boolean Lambertian spheres: radiative-transfer limit and finite size.

The order-1 table (max_order = 1, albedo 0.9) matches the exact
single scattering of a half space of Lambert-sphere point scatterers,
c p(-wi.wo) / (mu_i + mu_o) (d'Eon 2021, Eqs. 1 and 10), with median |rel| <= 3 %
on cells more than 10 deg from retro, at phi = 0.02.

Spheres of finite size are brighter than point scatterers at first order in r / l
(microsim/models/boolean_spheres.py): shadow hiding, whose 1 / tan(g / 2) tail reaches far past
10 deg, and the height of a hit point above its centre. At phi = 0.02 (r / l = 0.015) that model
predicts a median excess over the point-scatterer formula of 4.0-4.2 % (theta_i = 0, 30, 60),
and the tracer follows it within its standard errors. So the 3 % check against radiative
transfer is made at phi = 0.005 (excess 1.0 %), and at phi = 0.02 the table is checked against
the finite-size model, with a chi-square test that also rejects the point-scatterer formula.

Both runs use the default tile (64 radii): a 24-radius tile adds periodic "ghost" shadow hiding
between the incoming ray and images of the outgoing one, visible at theta_i >= 60 deg.
"""

import numpy as np
import pytest

from microsim import models
from microsim.models.radiative_transfer import single_scattering
from microsim.testing.bounds import chi2_bound

ALBEDO = 0.9
REALIZATIONS = 16
THETA_I = [0.0, 30.0, 60.0]
pytestmark = pytest.mark.slow  # 2 x 3.6 M paths


def single_scattering_table(simulate, phi):
    return simulate({
        "scene": {"kind": "poisson_spheres", "volume_fraction": phi},
        "material": {"kind": "lambert", "albedo": ALBEDO},
        "illumination": {"theta_i_deg": THETA_I},
        "sensor": {"cells": 100},
        "run": {"paths": 1_200_000, "realizations": REALIZATIONS, "seed": 3, "max_order": 1},
    }, workers=2)


def point_scatterers(sensor, wi):
    """c p(-wi.wo) / (mu_i + mu_o), Eq. 10, averaged over each cell (conventions §2)."""
    return sensor.cell_average(lambda wo: single_scattering(wi, wo, ALBEDO), 6, 6)


def away_from_retro(table, wi):
    return np.degrees(np.arccos(np.clip(table.direction @ wi, -1, 1))) > 10.0


def test_order_1_tends_to_radiative_transfer_for_dilute_spheres(simulate):
    table = single_scattering_table(simulate, 0.005)
    assert np.all(table.brdf_order[:, 1:, :] == 0.0)
    for i, wi in enumerate(table.wi):
        away = away_from_retro(table, wi)
        relative = table.brdf_order[i, 0, away] / point_scatterers(table.sensor, wi)[away] - 1.0
        assert np.median(np.abs(relative)) <= 0.03


def test_order_1_at_phi_002_follows_the_finite_size_model_not_point_scatterers(simulate):
    table = single_scattering_table(simulate, 0.02)
    model = models.create("boolean_spheres_single", albedo=ALBEDO, volume_fraction=0.02)
    order_1, stderr = table.brdf_order[:, 0, :], table.arrays["brdf_order_stderr"][:, 0, :]
    bound = chi2_bound(table.sensor.n_cells, REALIZATIONS)
    for i, wi in enumerate(table.wi):
        finite = table.sensor.cell_average(lambda wo: model(wi, wo), 6, 6)
        points = point_scatterers(table.sensor, wi)
        away = away_from_retro(table, wi)
        assert np.mean(((order_1[i] - finite) / stderr[i]) ** 2) <= bound  # every cell, retro included
        assert np.median(np.abs(order_1[i, away] / finite[away] - 1.0)) <= 0.03
        assert np.mean(((order_1[i, away] - points[away]) / stderr[i, away]) ** 2) > bound
