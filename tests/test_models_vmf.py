"""The vMF diffuse BRDF (d'Eon and Weidlich 2024): limits, cross section, Fourier convention, energy."""

import math

import numpy as np
import pytest
from scipy.special import i0e

from microsim import models
from microsim.core.frames import direction
from microsim.models import vmf_diffuse as vmf
from microsim.models.quadrature import directional_albedo, hemisphere_rule
from microsim.testing.models import assert_rejected, random_pairs

ROUGHNESS = [0.0, 1e-6, 0.02, 0.0489, 0.05, 0.1, 0.2, 0.3, 0.352, 0.36, 0.5, 0.7, 0.9, 1.0 - 1e-12, 1.0]


def _gl(n, a, b):
    x, w = np.polynomial.legendre.leggauss(n)
    return a + 0.5 * (b - a) * (x + 1.0), 0.5 * (b - a) * w


def sigma_eq3(u, alpha, n=64):
    """Eq. 3 with 0F1~(;1;x) = I0(2 sqrt(x)) and xi = sin^2(beta):
    csch(k) / (2 alpha^2) integral_0^{pi/2} e^{k u cos(beta)} I0(k sqrt(1-u^2) sin(beta)) sin(2 beta) d(beta),
    k = 2 / alpha^2, with the exponentials combined (exponent k (cos(beta - theta_u) - 1) <= 0)
    and Gauss-Legendre on segments that resolve the peak at beta = theta_u (width ~ alpha)."""
    k = 2.0 / alpha**2
    theta_u = math.acos(u)
    peak = min(theta_u, 0.5 * math.pi)
    breaks = peak + alpha * np.array([-16, -8, -4, -2, -1, -0.5, 0, 0.5, 1, 2, 4, 8, 16])
    edges = np.unique(np.clip(np.concatenate([[0.0, 0.5 * math.pi], breaks]), 0.0, 0.5 * math.pi))
    x, w = np.polynomial.legendre.leggauss(n)
    a, b = edges[:-1, None], edges[1:, None]
    beta = a + 0.5 * (b - a) * (x + 1.0)
    z = k * np.sin(beta) * math.sin(theta_u)
    integrand = np.exp(k * (np.cos(beta - theta_u) - 1.0)) * i0e(z) * np.sin(2.0 * beta)
    return float(np.sum(0.5 * (b - a) * w * integrand)) * 2.0 / (1.0 - math.exp(-2.0 * k)) / (2.0 * alpha**2)


U_GRID = np.linspace(-1.0, 1.0, 41)

#: Branch tolerances for sigma: the paper states no accuracy for Eq. 4-6; we require the two
#: analytic forms (Eq. 4, 6) within 3e-3 (0.3 % of sigma's range [0, 1]) and the fit Eq. 5
#: within 3e-2. Measured: 9.4e-4, 2.4e-2 and 2.0e-3.
SIGMA_TOL = {"eq4": 3e-3, "eq5": 3e-2, "eq6": 3e-3}
BRANCH_ALPHAS = {
    "eq4": [0.01, 0.05, 0.1, 0.2, 0.2499],
    "eq5": [0.25, 0.4, 0.6, 0.8, 0.8999],
    "eq6": [0.9, 1.2, 2.0, 5.0, 30.0],
}


@pytest.mark.parametrize("branch", list(BRANCH_ALPHAS))
def test_cross_section_against_exact_integral(branch):
    for alpha in BRANCH_ALPHAS[branch]:
        exact = np.array([sigma_eq3(u, alpha) for u in U_GRID])
        assert np.max(np.abs(vmf.cross_section(U_GRID, alpha) - exact)) < SIGMA_TOL[branch], alpha


def test_sigma_eq3_is_the_projected_area():
    """Eq. 3 (our evaluation) equals integral D^vMF(m) <u.m> dm computed on the sphere, in a
    frame with its pole on the direction (cosine c' = u.m in (0, 1), so <u.m> has no kink)."""
    alpha = 0.7
    k = 2.0 / alpha**2
    c, wc = _gl(200, 0.0, 1.0)
    phi = (np.arange(256) + 0.5) * 2 * math.pi / 256
    for u in (-0.8, 0.0, 0.6):
        s_u = math.sqrt(1 - u * u)
        m_z = np.outer(c, np.full_like(phi, u)) + np.outer(np.sqrt(1 - c**2), np.cos(phi)) * s_u
        dens = k / (2 * math.pi * (1 - math.exp(-2 * k))) * np.exp(k * (m_z - 1))
        total = np.sum(c[:, None] * dens * wc[:, None]) * 2 * math.pi / 256
        assert sigma_eq3(u, alpha) == pytest.approx(total, rel=1e-10)


def test_cross_section_limits_and_symmetry():
    u = np.linspace(-1, 1, 201)
    np.testing.assert_array_equal(vmf.cross_section(u, 0.0), np.maximum(u, 0.0))
    np.testing.assert_allclose(vmf.cross_section(u, 1e-3), np.maximum(u, 0.0), atol=1e-3)
    np.testing.assert_array_equal(vmf.cross_section(u, math.inf), np.full_like(u, 0.25))
    np.testing.assert_allclose(vmf.cross_section(u, 1e4), 0.25, atol=1e-8)
    for alpha in (0.05, 0.2, 0.3, 0.6, 0.89, 0.9, 1.5, 10.0, 1e3):
        odd = 0.5 * (vmf.cross_section(u, alpha) - vmf.cross_section(-u, alpha))
        np.testing.assert_allclose(odd, u * odd[-1], atol=1e-12)
        x = 2.0 / alpha**2
        if alpha < 0.25 or 0.9 <= alpha <= 10.0:
            np.testing.assert_allclose(odd[-1], 0.5 * (1.0 / math.tanh(x) - 1.0 / x), rtol=1e-9)
    assert odd[-1] == pytest.approx(x / 6.0, rel=1e-9)


def test_cross_section_continuity_at_branch_ends():
    """The jump at alpha = 0.25 and 0.9 is bounded by the two branches' errors (measured 6.7e-3, 1.7e-2)."""
    u = np.linspace(-1, 1, 401)
    for edge, left, right in ((0.25, "eq4", "eq5"), (0.9, "eq5", "eq6")):
        jump = np.max(np.abs(vmf.cross_section(u, edge) - vmf.cross_section(u, edge * (1 - 1e-12))))
        assert jump < SIGMA_TOL[left] + SIGMA_TOL[right]


def _lambert(albedo):
    return models.create("lambert", albedo=albedo)


@pytest.mark.parametrize("albedo", [0.0, 0.3, 0.8, 1.0])
def test_zero_roughness_is_lambert(albedo):
    wi, wo = random_pairs(3000, 2)
    lambert = _lambert(albedo)(wi, wo)
    for params in (dict(albedo=albedo), dict(kd=albedo)):
        f = models.create("vmf_diffuse", roughness=0.0, **params)(wi, wo)
        np.testing.assert_allclose(f, lambert, rtol=1e-15, atol=0.0)


@pytest.mark.parametrize("roughness", ROUGHNESS)
def test_reciprocal(roughness):
    model = models.create("vmf_diffuse", albedo=0.7, roughness=roughness)
    assert model.reciprocal
    wi, wo = random_pairs(3000, 2)
    np.testing.assert_allclose(model(wi, wo), model(wo, wi), rtol=1e-10, atol=0.0)


def exact_single_scattering(r, wi, wo, n=150):
    """Single scattering of the vMF flake half space (Sec. 3.3, Eq. 8 with the exact kernel):
    integral D(m) <i.m><o.m> dm / (pi (mu_o sigma(mu_i) + mu_i sigma(-mu_o))), every integral on
    the sphere by Gauss-Legendre in cos(theta_m) and the midpoint rule in phi_m."""
    alpha = vmf.alpha_from_roughness(r)
    c, wc = _gl(n, -1.0, 1.0)
    phi = (np.arange(2 * n) + 0.5) * math.pi / n
    cc, pp = np.meshgrid(c, phi, indexing="ij")
    s = np.sqrt(1 - cc**2)
    m = np.stack([s * np.cos(pp), s * np.sin(pp), cc], -1).reshape(-1, 3)
    if math.isinf(alpha):
        dens = np.full(m.shape[0], 1.0 / (4.0 * math.pi))
    else:
        k = 2.0 / alpha**2
        dens = k / (2 * math.pi * (1 - math.exp(-2 * k))) * np.exp(k * (m[:, 2] - 1.0))
    weight = (wc[:, None] * np.full(2 * n, math.pi / n)).reshape(-1) * dens
    ci, co = np.maximum(m @ wi.T, 0.0), np.maximum(m @ wo.T, 0.0)
    kernel = np.sum(ci * co * weight[:, None], axis=0)
    sigma_i = np.sum(ci * weight[:, None], axis=0)
    sigma_mo = np.sum(np.maximum(-(m @ wo.T), 0.0) * weight[:, None], axis=0)
    return kernel / (math.pi * (wo[:, 2] * sigma_i + wi[:, 2] * sigma_mo))


@pytest.mark.parametrize("roughness", [0.5, 1.0])
def test_first_order_matches_exact_single_scattering(roughness):
    """Order 1 against the exact single scattering of the flake medium. With the
    Horak-Chandrasekhar factor 2 on the cos(phi), cos(2 phi) modes the median error is 0.8 %
    (r = 0.5) and 2.6 % (r = 1); read without it, 7.3 % and 10.1 %. The bound, 4 %, is the
    "few %" of the paper's Fig. 4 error images and separates the two readings."""
    theta = np.radians([10.0, 40.0, 60.0, 75.0])
    t_i, t_o, p = np.meshgrid(theta, theta, np.linspace(0, math.pi, 7), indexing="ij")
    wi, wo = direction(t_i, 0.0).reshape(-1, 3), direction(t_o, p).reshape(-1, 3)
    fit = models.create("vmf_diffuse", albedo=1.0, roughness=roughness).orders(wi, wo)[0]
    rel = np.abs(fit / exact_single_scattering(roughness, wi, wo) - 1.0)
    assert np.median(rel) < 0.04


@pytest.mark.parametrize("albedo", [0.3, 0.6, 0.9])
def test_directional_albedo_at_most_one(albedo):
    """Albedo <= 1 for c <= 0.9 on r in [0, 1], incidence up to 89.9 deg (largest: 0.904)."""
    wi = direction(np.radians([0.0, 30.0, 60.0, 80.0, 89.0, 89.9]))
    for r in np.linspace(0.0, 1.0, 11):
        assert np.all(directional_albedo(models.create("vmf_diffuse", albedo=albedo, roughness=r), wi, 48, 64) <= 1.0)


@pytest.mark.xfail(
    strict=True, reason="published f_m fit: white albedo up to 1.14 at r = 0.95, theta_i = 89.9 deg (c >= 0.97 exceeds 1)"
)
def test_directional_albedo_at_most_one_near_white():
    model = models.create("vmf_diffuse", albedo=1.0, roughness=0.95)
    assert directional_albedo(model, direction(math.radians(89.9))) <= 1.0


def test_orders_sum_to_brdf_and_vanish_below_horizon():
    model = models.create("vmf_diffuse", albedo=0.8, roughness=0.6)
    wi, wo = random_pairs(200, 2)
    orders = model.orders(wi, wo)
    assert orders.shape == (4, 200)
    np.testing.assert_allclose(orders.sum(axis=0), model(wi, wo), rtol=1e-14)
    below = direction(np.radians(95.0))
    assert np.all(model.orders(below, wo[:3]) == 0.0) and np.all(model(wi[:3], below) == 0.0)


def test_higher_orders_vanish_at_zero_roughness_and_are_non_negative():
    u = np.linspace(1e-6, 1.0, 50)
    ui, uo = np.meshgrid(u, u)
    for c in (0.0, 0.2, 0.5, 0.9, 1.0):
        assert np.all(vmf.higher_orders(c, 0.0, ui, uo) == 0.0)
        for r in np.linspace(0, 1, 21):
            assert np.all(vmf.higher_orders(c, r, ui, uo) >= 0.0)


def test_kd_remap():
    """Section 5: c = kd at r = 0, c(kd = 1) = 1, c(0) = 0, increasing in kd."""
    kd = np.linspace(0.0, 1.0, 101)
    for r in (0.0, 0.1, 0.5, 1.0):
        c = np.array([vmf.albedo_from_kd(k, r) for k in kd])
        assert c[0] == 0.0 and c[-1] == pytest.approx(1.0, abs=1e-15) and np.all(np.diff(c) > 0.0)
        if r == 0.0:
            np.testing.assert_array_equal(c, kd)
    assert models.create("vmf_diffuse", kd=0.5, roughness=0.5).albedo == vmf.albedo_from_kd(0.5, 0.5)


@pytest.mark.skipif("lambert_sphere" not in models.available(), reason="lambert_sphere model not present")
@pytest.mark.parametrize("albedo", [0.3, 0.6, 0.8])
def test_full_roughness_approaches_lambert_sphere(albedo):
    """At r = 1 the model approximates the Lambert-sphere BRDF, with less accuracy than that
    paper's fit (Sec. 6); no number is given. We require 5 % (median over the hemisphere,
    theta <= 80 deg) and 5 % in directional albedo."""
    vm = models.create("vmf_diffuse", albedo=albedo, roughness=1.0)
    ls = models.create("lambert_sphere", albedo=albedo)
    wo, wt = hemisphere_rule(48, 96)
    keep = wo[:, 2] > math.cos(math.radians(80.0))
    for theta in np.radians([0.0, 30.0, 60.0, 80.0]):
        wi = np.broadcast_to(direction(theta, 0.0), wo.shape)
        f_v, f_l = vm(wi, wo), ls(wi, wo)
        assert np.median(np.abs(f_v[keep] / f_l[keep] - 1.0)) < 0.05
        assert np.sum(f_v * wo[:, 2] * wt) == pytest.approx(np.sum(f_l * wo[:, 2] * wt), rel=0.05)


def test_finite_at_grazing_and_extremes():
    angles = np.radians([0.0, 60.0, 89.0, 89.999999]).tolist() + [0.5 * math.pi]
    t_i, t_o, p = np.meshgrid(angles, angles, [0.0, 1.0, math.pi], indexing="ij")
    wi, wo = direction(t_i, 0.0), direction(t_o, p)
    for r in ROUGHNESS:
        for c in (0.0, 1e-9, 0.5, 1.0):
            f = models.create("vmf_diffuse", albedo=c, roughness=r)(wi, wo)
            assert np.all(np.isfinite(f)), (r, c)


@pytest.mark.parametrize(
    "params, keys",
    [
        (dict(roughness=0.5), ["albedo", "kd"]),
        (dict(albedo=0.5, kd=0.5, roughness=0.5), ["albedo", "kd"]),
        (dict(albedo=0.5), ["roughness"]),
        (dict(kd=0.5), ["roughness"]),
        (dict(albedo=1.2, roughness=0.5), ["albedo"]),
        (dict(albedo=0.5, roughness=1.5), ["roughness"]),
        (dict(albedo=0.5, roughness=-0.1), ["roughness"]),
        (dict(kd=-0.1, roughness=0.5), ["kd"]),
        (dict(albedo=0.5, roughness=0.5, eta=1.5), ["eta"]),
    ],
)
def test_bad_parameters(params, keys):
    assert_rejected("vmf_diffuse", params, keys)
