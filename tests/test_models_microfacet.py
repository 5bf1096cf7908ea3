"""Microfacet distributions, GAFs and the specular ``microfacet`` model.

Quadratures here are independent of the code under test: slope-space polar rules adapted to
the distribution's width (resolving roughness 1e-2 and the heavy GGX tail), not the facet
sampling of the models, except where ``sample`` itself is what is checked.
"""

import math

import numpy as np
import pytest
from scipy.special import erf

from microsim import models
from microsim.core.frames import direction
from microsim.models.microfacet import specular_brdf
from microsim.models.quadrature import directional_albedo
from microsim.physics import distributions as nd
from microsim.physics.fresnel import fresnel, fresnel_array, fresnel_conductor_array, fresnel_dielectric_array
from microsim.testing.models import assert_rejected, assert_zero_below_horizon, random_pairs

ISOTROPIC = [0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0]
ANISOTROPIC = [(0.01, 0.1), (0.05, 1.0), (1.0, 0.1), (0.3, 3.0), (0.01, 3.0)]
GAUSSIAN_SMITH = [0.01, 0.05, 0.1, 0.2]


def _gl(n, a, b):
    x, w = np.polynomial.legendre.leggauss(n)
    return a + 0.5 * (b - a) * (x + 1.0), 0.5 * (b - a) * w


def _slope_scales(distribution, ax, ay):
    """Slope-space scales of the distribution (Beckmann-equivalent alpha = sqrt(2) sigma)."""
    return (math.sqrt(2.0) * ax,) * 2 if distribution == "gaussian" else (ax, ay)


def _normal_from_slopes(px, py):
    m = np.stack([-px, -py, np.ones_like(px)], axis=-1)
    return m / np.linalg.norm(m, axis=-1, keepdims=True)


def _slope_space_rule(distribution, ax, ay, n_beta, n_psi):
    """Normals m and solid-angle weights d_omega on a polar grid of scaled slopes (tan beta, psi).

    d_omega = m_z^3 sx sy rho / cos^2(beta) d_beta d_psi: the slope-space Jacobian (dm = m_z^3 d slope).
    """
    sx, sy = _slope_scales(distribution, ax, ay)
    beta, wb = _gl(n_beta, 0.0, 0.5 * math.pi)
    psi = (np.arange(n_psi) + 0.5) * 2.0 * math.pi / n_psi
    b, p = np.meshgrid(beta, psi, indexing="ij")
    rho = np.tan(b)
    m = _normal_from_slopes(sx * rho * np.cos(p), sy * rho * np.sin(p))
    return m, m[..., 2] ** 3 * sx * sy * rho / np.cos(b) ** 2 * wb[:, None] * 2.0 * math.pi / n_psi


def projected_area_integral(distribution, ax, ay, n_tilt=400, n_azimuth=512):
    """integral D(m) (m.n) d(omega_m) = integral P22(p) d^2 p, P22 = D cos^4(theta_m).

    Polar coordinates in slopes scaled by the distribution's width, radius tan(beta) with
    Gauss-Legendre in beta on (0, pi/2) and the midpoint rule in azimuth.
    """
    m, d_omega = _slope_space_rule(distribution, ax, ay, n_tilt, n_azimuth)
    return float(np.sum(nd.ndf(distribution, ax, ay, m) * m[..., 2] * d_omega))


def visible_area_integral(distribution, ax, ay, o, ndf=None, n=128):
    """integral max(0, o.m) D(m) d(omega_m), by slopes: sin(theta_o) integral over the half plane
    q < cot(theta_o) of (cot(theta_o) - q) P22(p) d^2 p, q the slope along o's azimuth.

    Coordinates (u, w) in which an elliptic P22 is isotropic (q = alpha_o u, the conditional
    mean removed from the perpendicular slope), then polar coordinates with radius tan(beta);
    the half-plane edge u = a is a boundary of the polar rule, so no kink is integrated over.
    """
    ndf = ndf or nd.ndf
    sx, sy = _slope_scales(distribution, ax, ay)
    st, ct = math.hypot(o[0], o[1]), o[2]
    e = np.array([o[0], o[1]]) / st if st > 0.0 else np.array([1.0, 0.0])
    ep = np.array([-e[1], e[0]])
    ao2 = sx**2 * e[0] ** 2 + sy**2 * e[1] ** 2
    ao = math.sqrt(ao2)
    cov = (sy**2 - sx**2) * e[0] * e[1]
    s = sx * sy / ao
    a = ct / (st * ao) if st > 0.0 else math.inf
    total = 0.0
    for lo, hi in ((-0.5 * math.pi, 0.5 * math.pi), (0.5 * math.pi, 1.5 * math.pi)):
        psi, wpsi = _gl(n, lo, hi)
        bmax = np.arctan(a / np.cos(psi)) if (lo < 0.0 and math.isfinite(a)) else np.full(n, 0.5 * math.pi)
        t, wt = _gl(n, 0.0, 1.0)
        b = bmax[:, None] * t[None, :]
        wb = bmax[:, None] * wt[None, :]
        r = np.tan(b)
        u, w = r * np.cos(psi)[:, None], r * np.sin(psi)[:, None]
        q = ao * u
        qp = (cov / ao2) * q + s * w
        m = _normal_from_slopes(q * e[0] + qp * ep[0], q * e[1] + qp * ep[1])
        p22 = ndf(distribution, ax, ay, m) * m[..., 2] ** 4
        total += float(np.sum((ct - st * q) * p22 * ao * s * r / np.cos(b) ** 2 * wb * wpsi[:, None]))
    return total


def _cases():
    for dist in ("beckmann", "ggx"):
        for a in ISOTROPIC:
            yield dist, a, a
        for ax, ay in ANISOTROPIC:
            yield dist, ax, ay


@pytest.mark.parametrize("distribution, ax, ay", list(_cases()))
def test_ndf_normalised_in_projected_area(distribution, ax, ay):
    assert abs(projected_area_integral(distribution, ax, ay) - 1.0) < 1e-4


@pytest.mark.parametrize("sigma", ISOTROPIC)
def test_gaussian_ndf_normalised(sigma):
    """Eq. 13 in polar angle: composite Gauss-Legendre with breaks at sigma * 2^k."""
    top = nd.gaussian_theta_max(sigma)
    edges = np.unique(np.clip(np.concatenate([[0.0], sigma * 2.0 ** np.arange(-3, 5)]), 0.0, top))
    total = 0.0
    for lo, hi in zip(edges[:-1], edges[1:]):
        theta, w = _gl(64, lo, hi)
        m = np.stack([np.sin(theta), 0.0 * theta, np.cos(theta)], axis=-1)
        total += np.sum(w * 2.0 * math.pi * nd.ndf("gaussian", sigma, sigma, m) * np.cos(theta) * np.sin(theta))
    assert abs(total - 1.0) < 1e-4


@pytest.mark.parametrize("sigma", [1e-4, 0.01, 0.3, 1.0, 3.0, 10.0])
def test_gaussian_normalisation_matches_closed_form(sigma):
    """1/C = 2 pi Im[...] from the complex error function (completing the square)."""
    z1 = (0.5 * math.pi - 1j * sigma**2) / (sigma * math.sqrt(2.0))
    z0 = -1j * sigma / math.sqrt(2.0)
    inner = math.exp(-0.5 * sigma**2) * sigma * math.sqrt(0.5 * math.pi) * (erf(z1) - erf(z0)).imag
    assert nd.gaussian_normalisation(sigma) * 2.0 * math.pi * inner == pytest.approx(1.0, rel=1e-10)


def _g1_cases():
    yield from _cases()
    for s in GAUSSIAN_SMITH:
        yield "gaussian", s, s


@pytest.mark.parametrize("distribution, ax, ay", list(_g1_cases()))
def test_smith_g1_is_projected_area(distribution, ax, ay):
    """G1(o) = cos(theta_o) / integral max(0, o.m) D(m) dm (Eq. 18): Lambda is the exact Smith one."""
    for theta in np.radians([0.5, 30.0, 60.0, 80.0, 89.0, 89.9]):
        for phi in (0.0, 0.7, 2.0):
            o = direction(theta, phi)
            expected = o[2] / visible_area_integral(distribution, ax, ay, o)
            assert nd.smith_g1(distribution, ax, ay, o[None])[0] == pytest.approx(expected, rel=1e-4)


def test_printed_ggx_eq20_fails_smith_identity():
    """Eq. 20 as printed (sigma_y under cos^2 phi) is our GGX with the axes exchanged, and
    with the Lambda of Eq. 21 it misses the projected-area identity by far more than 1e-4."""
    ax, ay = 0.1, 1.0
    rng = np.random.default_rng(11)
    m = direction(rng.uniform(0.0, 1.5, 200), rng.uniform(0.0, 2 * math.pi, 200))
    tan2 = (1.0 - m[:, 2] ** 2) / m[:, 2] ** 2
    cos2, sin2 = np.cos(np.arctan2(m[:, 1], m[:, 0])) ** 2, np.sin(np.arctan2(m[:, 1], m[:, 0])) ** 2
    printed = 1.0 / (math.pi * ax * ay * m[:, 2] ** 4 * (1.0 + tan2 * (cos2 / ay**2 + sin2 / ax**2)) ** 2)
    np.testing.assert_allclose(printed, nd.ndf("ggx", ay, ax, m), rtol=1e-12)
    o = direction(math.radians(70.0), 0.0)
    g1_printed_ndf = o[2] / visible_area_integral("ggx", ay, ax, o)
    assert abs(nd.smith_g1("ggx", ax, ay, o[None])[0] / g1_printed_ndf - 1.0) > 1e-2


@pytest.mark.parametrize(
    "distribution, ax, ay",
    [("beckmann", 0.05, 0.8), ("ggx", 0.2, 0.6), ("gaussian", 0.01, 0.01), ("gaussian", 0.5, 0.5), ("gaussian", 3.0, 3.0)],
)
def test_sample_has_density_d_cos(distribution, ax, ay):
    """Moments of m under ``sample`` (fixed 128 x 128 product rule in xi) equal those of D(m)(m.n).

    Tolerance 1e-5: the xi-rule converges slowly at xi1 -> 1 (logarithmic / square-root ends).
    """
    x, w = _gl(128, 0.0, 1.0)
    m = nd.sample(distribution, ax, ay, x[:, None], x[None, :])
    weight = w[:, None] * w[None, :]
    mm, d_omega = _slope_space_rule(distribution, ax, ay, 400, 1024)
    dens = nd.ndf(distribution, ax, ay, mm) * mm[..., 2] * d_omega
    for g in (lambda v: v[..., 2], lambda v: v[..., 0] ** 2, lambda v: v[..., 1] ** 2, lambda v: v[..., 0] * v[..., 1]):
        assert np.sum(g(m) * weight) == pytest.approx(np.sum(g(mm) * dens), abs=1e-5)
    assert np.allclose(np.linalg.norm(m, axis=-1), 1.0) and np.all(m[..., 2] > 0.0)


def facet_rule(distribution, ax, ay, n):
    """Normals and weights with sum w g(m) = integral g(m) D(m)(m.n) dm, via ``sample``."""
    x, w = _gl(n, 0.0, 1.0)
    m = nd.sample(distribution, ax, ay, x[:, None], x[None, :]).reshape(-1, 3)
    return m, (w[:, None] * w[None, :]).reshape(-1)


def facet_albedo(gaf, distribution, ax, ay, wi, rule):
    """integral over o of D G F(=1) / (4 mu_i mu_o) mu_o d(omega_o), in facet normals:
    integral D(m) G(i, o(m), m) <i.m> / mu_i dm with o(m) the mirror direction (o.z > 0),
    d(omega_o) = 4 <i.m> d(omega_m)."""
    m, weight = rule
    im = m @ wi
    o = 2.0 * im[:, None] * m - wi
    ok = (o[:, 2] > 0.0) & (im > 0.0)
    o = np.where(ok[:, None], o, np.array([0.0, 0.0, 1.0]))
    g = nd.masking_shadowing(gaf, distribution, ax, ay, wi, o, m)
    return float(np.sum(np.where(ok, g * im / (wi[2] * m[:, 2]), 0.0) * weight))


@pytest.mark.parametrize("gaf", nd.GAFS)
def test_white_furnace(gaf):
    """Directional albedo with F = 1 is <= 1 for every GAF (roughness 0.01 to 3, anisotropic too).

    The facet-space rule has no trouble with narrow lobes; its error is estimated by the
    difference between 160^2 and 320^2 nodes, and that estimate is the tolerance.
    """
    cases = [("beckmann", a, a) for a in (0.01, 0.1, 1.0, 3.0)] + [("ggx", a, a) for a in (0.01, 0.3, 3.0)]
    cases += [("beckmann", 0.05, 0.8), ("ggx", 1.0, 0.1)]
    cases += [("gaussian", s, s) for s in ((0.05, 0.2) if gaf != "torrance_sparrow" else (0.05, 0.5, 3.0))]
    for dist, ax, ay in cases:
        fine, coarse = facet_rule(dist, ax, ay, 320), facet_rule(dist, ax, ay, 160)
        for theta in np.radians([0.0, 45.0, 75.0, 85.0, 89.9]):
            wi = direction(theta, 0.4)
            a_fine = facet_albedo(gaf, dist, ax, ay, wi, fine)
            error = abs(a_fine - facet_albedo(gaf, dist, ax, ay, wi, coarse))
            assert a_fine <= 1.0 + error + 1e-12, (dist, ax, ay, math.degrees(theta), a_fine, error)


@pytest.mark.parametrize(
    "distribution, ax, ay", [("beckmann", 0.3, 0.3), ("ggx", 1.0, 0.2), ("gaussian", 0.5, 0.5), ("beckmann", 3.0, 3.0)]
)
def test_vcavity_masking_is_normalised(distribution, ax, ay):
    """integral D(m) G1_V(i, m) <i.m> dm = mu_i for the Torrance-Sparrow masking (Eq. 14 with o = i),
    so G_TS <= G1_V bounds its white-furnace albedo by 1 exactly (the facet-space furnace test
    above only resolves it to its quadrature error at grazing incidence)."""
    m, d_omega = _slope_space_rule(distribution, ax, ay, 200, 256)
    dens = nd.ndf(distribution, ax, ay, m) * d_omega
    for theta in np.radians([0.0, 30.0, 60.0, 85.0, 89.9]):
        wi = direction(theta, 0.3)
        wb_i = np.broadcast_to(wi, m.shape)
        g = nd.masking_shadowing("torrance_sparrow", distribution, ax, ay, wb_i, wb_i, m)
        assert np.sum(g * np.maximum(m @ wi, 0.0) * dens) == pytest.approx(wi[2], rel=1e-10)


def test_height_correlated_bounds():
    """G1(i) G1(o) <= 1 / (1 + Lambda_i + Lambda_o) <= min(G1(i), G1(o)) on random pairs."""
    rng = np.random.default_rng(3)
    wi = direction(np.radians(rng.uniform(0, 89.9, 500)), rng.uniform(0, 2 * math.pi, 500))
    wo = direction(np.radians(rng.uniform(0, 89.9, 500)), rng.uniform(0, 2 * math.pi, 500))
    m = np.broadcast_to([0.0, 0.0, 1.0], wi.shape)
    for dist, a in (("beckmann", 0.3), ("ggx", 1.0), ("gaussian", 0.2)):
        sep = nd.masking_shadowing("smith", dist, a, a, wi, wo, m)
        hc = nd.masking_shadowing("smith_height_correlated", dist, a, a, wi, wo, m)
        g1 = np.minimum(nd.smith_g1(dist, a, a, wi), nd.smith_g1(dist, a, a, wo))
        assert np.all(sep <= hc + 1e-15) and np.all(hc <= g1 + 1e-15)


def _model_cases():
    for dist in nd.DISTRIBUTIONS:
        for gaf in nd.GAFS:
            rough = [dict(roughness=0.2)] if dist == "gaussian" else [dict(roughness=0.2), dict(roughness_x=0.1, roughness_y=0.6)]
            for r in rough:
                for fres in (dict(eta=1.5), dict(eta=0.2, k=3.0)):
                    yield dict(distribution=dist, gaf=gaf, **r, **fres)


@pytest.mark.parametrize("params", list(_model_cases()))
def test_microfacet_reciprocal(params):
    model = models.create("microfacet", **params)
    assert model.reciprocal
    wi, wo = random_pairs(2000, 5)
    a, b = model(wi, wo), model(wo, wi)
    assert np.count_nonzero(a) > 1000
    np.testing.assert_allclose(a, b, rtol=1e-10, atol=0.0)


@pytest.mark.parametrize("params", list(_model_cases()))
def test_microfacet_directional_albedo_at_most_one(params):
    """The project quadrature (64 x 128) for roughness >= 0.1, incidence up to 89.9 deg."""
    model = models.create("microfacet", **params)
    wi = direction(np.radians([0.0, 30.0, 60.0, 80.0, 89.0, 89.9]), 0.3)
    assert np.all(directional_albedo(model, wi) <= 1.0)


def test_microfacet_matches_definition():
    """f = D(h) G F(i.h) / (4 mu_i mu_o) evaluated from the distribution module's parts."""
    model = models.create("microfacet", distribution="ggx", roughness_x=0.3, roughness_y=0.1, gaf="smith", eta=1.33)
    wi, wo = random_pairs(50, 7)
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=-1, keepdims=True)
    d = nd.ndf("ggx", 0.3, 0.1, h)
    g = nd.smith_g1("ggx", 0.3, 0.1, wi) * nd.smith_g1("ggx", 0.3, 0.1, wo)
    f = fresnel_dielectric_array(np.sum(wi * h, axis=-1), 1.33)
    np.testing.assert_allclose(model(wi, wo), d * g * f / (4 * wi[:, 2] * wo[:, 2]), rtol=1e-12)
    np.testing.assert_allclose(specular_brdf(wi, wo, "ggx", 0.3, 0.1, "smith", 1.33), model(wi, wo), rtol=1e-15)


@pytest.mark.parametrize("eta, k", [(1.5, 0.0), (0.7, 0.0), (1.0152, 6.6273), (0.2, 3.0)])
def test_fresnel_dispatch_is_dielectric_for_k_zero_else_conductor(eta, k):
    """microsim.physics.fresnel.fresnel, the one dispatch every model uses, picks its branch exactly
    (eta = 0.7: total internal reflection below the critical angle)."""
    cos_i = np.linspace(0.0, 1.0, 101)
    expected = fresnel_dielectric_array(cos_i, eta) if k == 0.0 else fresnel_conductor_array(cos_i, eta, k)
    assert np.array_equal(fresnel_array(cos_i, eta, k), expected)
    assert [fresnel(c, eta, k) for c in cos_i] == expected.tolist()


def test_microfacet_finite_at_grazing_and_extremes():
    grazing = np.radians([0.0, 45.0, 89.0, 89.999999]).tolist() + [0.5 * math.pi]
    t_i, t_o, p = np.meshgrid(grazing, grazing, [0.0, 1.0, math.pi], indexing="ij")
    wi, wo = direction(t_i, 0.0), direction(t_o, p)
    for dist in nd.DISTRIBUTIONS:
        for gaf in nd.GAFS:
            for a in (nd.ROUGHNESS_MIN, 1.0, nd.ROUGHNESS_MAX):
                if dist == "gaussian" and gaf != "torrance_sparrow" and a > nd.GAUSSIAN_SMITH_MAX:
                    continue
                for fres in (dict(eta=1e-3), dict(eta=100.0), dict(eta=1.0, k=100.0)):
                    f = models.create("microfacet", distribution=dist, gaf=gaf, roughness=a, **fres)(wi, wo)
                    assert np.all(np.isfinite(f)) and np.all(f >= 0.0), (dist, gaf, a, fres)
    model = models.create("microfacet", roughness=0.3)
    assert_zero_below_horizon(model, direction(0.2), direction(np.radians(100.0)))


@pytest.mark.parametrize(
    "params, keys",
    [
        (dict(), ["roughness"]),
        (dict(roughness=0.0), ["roughness"]),
        (dict(roughness=11.0), ["roughness"]),
        (dict(roughness_x=0.2), ["roughness_x", "roughness_y"]),
        (dict(roughness=0.2, roughness_y=0.3), ["roughness", "roughness_y"]),
        (dict(roughness=0.2, distribution="cauchy"), ["distribution"]),
        (dict(roughness=0.2, gaf="schlick"), ["gaf"]),
        (dict(roughness=0.2, eta=0.0), ["eta"]),
        (dict(roughness=0.2, k=-1.0), ["k"]),
        (dict(distribution="gaussian", roughness_x=0.1, roughness_y=0.2), ["roughness_x", "roughness_y"]),
        (dict(distribution="gaussian", roughness=0.3, gaf="smith"), ["gaf", "roughness"]),
        (dict(roughness=0.2, albedo=0.5), ["albedo"]),
    ],
)
def test_microfacet_bad_parameters(params, keys):
    assert_rejected("microfacet", params, keys)


def test_gaussian_smith_lambda_refused_where_it_diverges():
    with pytest.raises(ValueError, match="gaussian"):
        nd.smith_lambda("gaussian", 0.3, 0.3, direction(0.5)[None])
