"""The full Oren-Nayar model (Oren & Nayar 1994): limits, reciprocity, energy, an independent transcription."""

import math

import numpy as np
import pytest

from microsim import models
from microsim.core.frames import direction
from microsim.models.quadrature import directional_albedo

SIGMAS = [0.0, 0.05, 0.3, 1.0, math.pi / 2 - 1e-6]


def _reference(theta_i, phi_i, theta_o, phi_o, rho, sigma, terms="full"):
    """Angle-form transcription of the published L1 + L2 (L1 alone: ``terms="direct"``), as in
    KimuraRyo/libbsdf OrenNayar.h."""
    cos_phi = np.cos(phi_o - phi_i)
    alpha, beta = np.maximum(theta_i, theta_o), np.minimum(theta_i, theta_o)
    s2 = sigma * sigma
    c1 = 1 - 0.5 * s2 / (s2 + 0.33)
    c2 = 0.45 * s2 / (s2 + 0.09) * np.where(cos_phi >= 0, np.sin(alpha), np.sin(alpha) - (2 * beta / np.pi) ** 3)
    c3 = 0.125 * s2 / (s2 + 0.09) * (4 * alpha * beta / np.pi**2) ** 2
    l1 = rho / np.pi * (c1 + cos_phi * c2 * np.tan(beta) + (1 - np.abs(cos_phi)) * c3 * np.tan((alpha + beta) / 2))
    l2 = 0.17 * rho**2 / np.pi * s2 / (s2 + 0.13) * (1 - cos_phi * (2 * beta / np.pi) ** 2)
    return l1 + l2 if terms == "full" else l1


def _angles(n, seed):
    rng = np.random.default_rng(seed)
    theta = np.arccos(rng.uniform(0.001, 1.0, (2, n)))
    theta[:, :10] = np.radians(89.9)
    return theta, rng.uniform(0.0, 2.0 * np.pi, (2, n))


@pytest.mark.parametrize("terms", ["full", "direct"])
@pytest.mark.parametrize("sigma", SIGMAS)
def test_matches_independent_transcription(sigma, terms):
    theta, phi = _angles(400, 3)
    m = models.create("oren_nayar", albedo=0.7, roughness=sigma, terms=terms)
    f = m(direction(theta[0], phi[0]), direction(theta[1], phi[1]))
    expected = _reference(theta[0], phi[0], theta[1], phi[1], 0.7, sigma, terms)
    np.testing.assert_allclose(f, np.maximum(expected, 0.0), rtol=1e-10)


def test_negative_published_values_are_clamped():
    # Forward plane, both directions at 85 deg, sigma = 1.5, rho = 0.01: the published form is
    # negative (-0.19 rho/pi); everywhere on the grid the model is >= 0 and equals
    # the published form where that is positive.
    t = np.radians(85.0)
    assert _reference(t, 0.0, t, np.pi, 0.01, 1.5) < 0.0
    theta = np.radians(np.linspace(0.0, 89.99, 60))
    ti, to = np.meshgrid(theta, theta, indexing="ij")
    for sigma in SIGMAS:
        for rho in (0.01, 0.5):
            f = models.create("oren_nayar", albedo=rho, roughness=sigma)(direction(ti, 0.0), direction(to, np.pi))
            ref = _reference(ti, 0.0, to, np.pi, rho, sigma)
            np.testing.assert_allclose(f, np.maximum(ref, 0.0), rtol=1e-10, atol=1e-300)


@pytest.mark.parametrize("sigma", SIGMAS)
@pytest.mark.parametrize("rho", [0.5, 1.0])
def test_reciprocity(sigma, rho):
    m = models.create("oren_nayar", albedo=rho, roughness=sigma)
    assert m.reciprocal
    theta, phi = _angles(500, 11)
    wi, wo = direction(theta[0], phi[0]), direction(theta[1], phi[1])
    np.testing.assert_allclose(m(wi, wo), m(wo, wi), rtol=1e-10)


def test_sigma_zero_is_lambert():
    theta, phi = _angles(300, 5)
    wi, wo = direction(theta[0], phi[0]), direction(theta[1], phi[1])
    for rho in (0.0, 0.3, 1.0):
        on = models.create("oren_nayar", albedo=rho, roughness=0.0)(wi, wo)
        np.testing.assert_array_equal(on, models.create("lambert", albedo=rho)(wi, wo))


def test_directional_albedo_bounded():
    # Quadrature error of the 64 x 128 rule on this kinked integrand: < 4e-5 (checked against
    # 512 x 1024); the largest albedo at rho = 0.95 is 0.9942, well inside the bound.
    wi = direction(np.radians([0.0, 30.0, 60.0, 80.0, 85.0, 89.0, 89.9]))
    rho_max = models.get("oren_nayar").energy_conserving_albedo_max
    for rho in (0.0, 0.5, 0.9, rho_max):
        for sigma in SIGMAS:
            a = directional_albedo(models.create("oren_nayar", albedo=rho, roughness=sigma), wi)
            assert np.all(a >= 0.0) and np.all(a <= 1.0)
    # The published approximation is not energy conserving at rho = 1 (grazing, small sigma):
    # albedo 1.0500 at sigma = 0.3, theta_i = 89.9 deg.
    a = directional_albedo(models.create("oren_nayar", albedo=1.0, roughness=0.3), wi)
    assert a[-1] == pytest.approx(1.05, abs=2e-3)


@pytest.mark.parametrize("sigma", SIGMAS)
@pytest.mark.parametrize("rho", [0.0, 1.0])
def test_finite_at_grazing_and_zero_below_horizon(sigma, rho):
    m = models.create("oren_nayar", albedo=rho, roughness=sigma)
    t = np.array([1e-12, 1e-200, 1.0, 1e-6])
    wi = np.stack([np.sqrt(1 - t * t), np.zeros(4), t], axis=-1)
    wo = np.stack([-np.sqrt(1 - t[::-1] ** 2), np.zeros(4), t[::-1]], axis=-1)
    for a, b in ((wi, wo), (wi, wi), (wi, wo[:, [1, 0, 2]])):
        f = m(a, b)
        assert np.all(np.isfinite(f)) and np.all(f >= 0.0)
    assert np.all(m(wi, -wo) == 0.0)


def test_parameter_domain():
    for bad in ({"albedo": 1.2, "roughness": 0.3}, {"albedo": 0.5, "roughness": -0.1}, {"albedo": 0.5, "roughness": math.pi / 2}):
        with pytest.raises(ValueError):
            models.create("oren_nayar", **bad)
    with pytest.raises(ValueError, match="roughness"):
        models.create("oren_nayar", albedo=0.5)
