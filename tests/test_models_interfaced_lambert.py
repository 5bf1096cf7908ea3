"""Interfaced Lambertian microfacets (Meneveaux et al. 2015): flat and rough forms."""

import math

import numpy as np
import pytest

from microsim import models
from microsim.core.frames import direction
from microsim.models import interfaced_lambert as il
from microsim.models.microfacet import specular_brdf
from microsim.models.quadrature import directional_albedo
from microsim.physics import distributions as nd
from microsim.physics import fresnel
from microsim.physics.fresnel import fresnel_dielectric_array
from microsim.testing.models import assert_rejected, assert_zero_below_horizon, random_pairs


def _gl(n, a, b):
    x, w = np.polynomial.legendre.leggauss(n)
    return a + 0.5 * (b - a) * (x + 1.0), 0.5 * (b - a) * w


def r_e_by_quadrature(eta):
    """integral_0^{pi/2} F(theta) sin(2 theta) d(theta): composite Gauss-Legendre in theta, 100
    even segments up to pi/2 - 0.1 then 60 geometric ones closing on pi/2 (to 1e-12), where F
    rises to 1 over a layer of width ~ sqrt(eta^2 - 1)."""
    near_grazing = 0.5 * math.pi - np.geomspace(0.1, 1e-12, 60)[1:]
    edges = np.concatenate([np.linspace(0.0, 0.5 * math.pi - 0.1, 101), near_grazing, [0.5 * math.pi]])
    x, w = np.polynomial.legendre.leggauss(20)
    a, b = edges[:-1, None], edges[1:, None]
    theta = a + 0.5 * (b - a) * (x + 1.0)
    return float(np.sum(0.5 * (b - a) * w * fresnel_dielectric_array(np.cos(theta), eta) * np.sin(2 * theta)))


@pytest.mark.parametrize("eta", [1.01, 1.05, 1.2, 1.33, 1.5, 2.0, 3.0, 5.0, 10.0])
def test_molenaar_external_reflectance(eta):
    assert fresnel.external_diffuse_reflectance(eta) == pytest.approx(r_e_by_quadrature(eta), rel=1e-9)


def test_external_reflectance_near_one():
    """Below 1.01 the defining integral replaces Eq. 10; it is continuous and 0 at eta = 1."""
    assert fresnel.external_diffuse_reflectance(1.0) == 0.0
    assert fresnel.external_diffuse_reflectance(1.01 - 1e-12) == pytest.approx(fresnel.external_diffuse_reflectance(1.01), rel=1e-9)
    for eta in (1.0 + 1e-9, 1.001, 1.005):
        assert fresnel.external_diffuse_reflectance(eta) == pytest.approx(r_e_by_quadrature(eta), rel=1e-6, abs=1e-15)
    assert fresnel.internal_diffuse_reflectance(1.0) == 0.0


@pytest.mark.parametrize("albedo", [0.0, 0.4, 1.0])
def test_flat_at_index_one_is_lambert(albedo):
    wi, wo = random_pairs(2000, 4)
    model = models.create("interfaced_lambert", albedo=albedo, eta=1.0)
    np.testing.assert_allclose(model(wi, wo), models.create("lambert", albedo=albedo)(wi, wo), rtol=1e-15, atol=0.0)
    assert np.all(model.specular_delta_reflectance(wi) == 0.0)


@pytest.mark.parametrize("eta", [1.0, 1.1, 1.5, 2.5])
@pytest.mark.parametrize("albedo", [0.3, 1.0])
def test_flat_energy_balance(eta, albedo):
    """Body albedo = T(mu_i) K_d (1 - r_i) / (1 - r_i K_d) (Eq. 8-10); with K_d = 1 it closes the
    balance with the mirror reflection F(mu_i) exactly. Quadrature 64 x 128 on a smooth integrand."""
    model = models.create("interfaced_lambert", albedo=albedo, eta=eta)
    wi = direction(np.radians([0.0, 40.0, 70.0, 85.0, 89.9]))
    r_i = fresnel.internal_diffuse_reflectance(eta)
    t_i = 1.0 - fresnel_dielectric_array(wi[:, 2], eta)
    body = directional_albedo(model, wi)
    np.testing.assert_allclose(body, t_i * albedo * (1.0 - r_i) / (1.0 - r_i * albedo), rtol=1e-8, atol=1e-14)
    np.testing.assert_allclose(model.specular_delta_reflectance(wi), 1.0 - t_i, rtol=1e-12)
    assert np.all(body + model.specular_delta_reflectance(wi) <= 1.0 + 1e-8)


def _rough_cases():
    for dist in nd.DISTRIBUTIONS:
        for gaf in nd.GAFS:
            rough = [dict(roughness=0.15)] if dist == "gaussian" else [dict(roughness=0.3), dict(roughness_x=0.1, roughness_y=0.5)]
            for r in rough:
                yield dict(distribution=dist, gaf=gaf, **r)


@pytest.mark.parametrize("params", list(_rough_cases()))
def test_rough_reciprocal(params):
    model = models.create("interfaced_lambert", albedo=0.7, eta=1.5, **params)
    assert model.reciprocal
    wi, wo = random_pairs(1000, 4)
    np.testing.assert_allclose(model(wi, wo), model(wo, wi), rtol=1e-10, atol=0.0)


def test_flat_reciprocal():
    model = models.create("interfaced_lambert", albedo=0.7, eta=1.5)
    wi, wo = random_pairs(2000, 4)
    np.testing.assert_allclose(model(wi, wo), model(wo, wi), rtol=1e-14, atol=0.0)


@pytest.mark.parametrize("params", [p for p in _rough_cases() if "roughness" in p])
def test_zero_albedo_is_the_specular_microfacet_model(params):
    wi, wo = random_pairs(500, 4)
    model = models.create("interfaced_lambert", albedo=0.0, eta=1.33, **params)
    np.testing.assert_array_equal(model(wi, wo), models.create("microfacet", eta=1.33, **params)(wi, wo))


def body_reference(params, eta, wi, wo, n=800, n_az=1024):
    """Eq. 12 integral T T D G <i.m><o.m> / (mu_i mu_o) dm by an independent rule: polar
    coordinates in slopes scaled by the distribution's width, radius tan(beta)."""
    dist, gaf = params["distribution"], params["gaf"]
    ax = params.get("roughness", params.get("roughness_x"))
    ay = params.get("roughness", params.get("roughness_y"))
    sx, sy = (math.sqrt(2.0) * ax,) * 2 if dist == "gaussian" else (ax, ay)
    beta, wb = _gl(n, 0.0, 0.5 * math.pi)
    psi = (np.arange(n_az) + 0.5) * 2 * math.pi / n_az
    b, p = np.meshgrid(beta, psi, indexing="ij")
    rho = np.tan(b)
    m = np.stack([-sx * rho * np.cos(p), -sy * rho * np.sin(p), np.ones_like(rho)], -1)
    m /= np.linalg.norm(m, axis=-1, keepdims=True)
    # D(m) d(omega_m) = D(m) cos^3(theta_m) d^2 p
    dens = nd.ndf(dist, ax, ay, m) * m[..., 2] ** 3 * sx * sy * rho / np.cos(b) ** 2 * wb[:, None] * 2 * math.pi / n_az
    m, dens = m.reshape(-1, 3), dens.reshape(-1)
    out = []
    for i, o in zip(wi, wo):
        im, om = m @ i, m @ o
        g = nd.masking_shadowing(gaf, dist, ax, ay, np.broadcast_to(i, m.shape), np.broadcast_to(o, m.shape), m)
        t = (1 - fresnel_dielectric_array(np.maximum(im, 0), eta)) * (1 - fresnel_dielectric_array(np.maximum(om, 0), eta))
        out.append(np.sum(np.where((im > 0) & (om > 0), t * g * im * om, 0.0) * dens) / (i[2] * o[2]))
    return np.array(out)


@pytest.mark.parametrize(
    "params",
    [
        dict(distribution="beckmann", gaf="smith", roughness=0.05),
        dict(distribution="ggx", gaf="smith_height_correlated", roughness_x=0.3, roughness_y=1.0),
        dict(distribution="gaussian", gaf="torrance_sparrow", roughness=0.5),
        dict(distribution="beckmann", gaf="torrance_sparrow", roughness=1.0),
    ],
)
def test_body_quadrature_against_independent_rule(params):
    """The fixed 48 x 96 facet rule of the body term (Eq. 12) within 1e-3 of a fine slope-space
    rule for theta_i, theta_o <= 80 deg (measured here: <= 4.1e-4, from the kinks of
    Torrance-Sparrow; 2e-5 or less with the Smith GAFs)."""
    eta, albedo = 1.5, 0.6
    model = models.create("interfaced_lambert", albedo=albedo, eta=eta, **params)
    t_i, t_o, p = np.meshgrid(np.radians([0.0, 45.0, 80.0]), np.radians([10.0, 60.0, 80.0]), [0.0, 2.0, math.pi], indexing="ij")
    wi, wo = direction(t_i, 0.3).reshape(-1, 3), direction(t_o, 0.3 + p).reshape(-1, 3)
    ax = params.get("roughness", params.get("roughness_x"))
    ay = params.get("roughness", params.get("roughness_y"))
    body = model(wi, wo) - specular_brdf(wi, wo, params["distribution"], ax, ay, params["gaf"], eta)
    reference = model.body_scale * body_reference(params, eta, wi, wo)
    np.testing.assert_allclose(body, reference, rtol=1e-3)


def test_rough_tends_to_flat():
    """At the smallest roughness (1e-4) the body term is the flat one (Eq. 8 at m = n) to 1e-5
    (the deviation is O(roughness^2) plus the quadrature error; measured 2.2e-7)."""
    wi, wo = random_pairs(300, 4, top=80.0)
    flat = models.create("interfaced_lambert", albedo=0.6, eta=1.5)
    rough = models.create("interfaced_lambert", albedo=0.6, eta=1.5, roughness=nd.ROUGHNESS_MIN)
    body = rough(wi, wo) - specular_brdf(wi, wo, "beckmann", nd.ROUGHNESS_MIN, nd.ROUGHNESS_MIN, "smith", 1.5)
    np.testing.assert_allclose(body, flat(wi, wo), rtol=1e-5)


def specular_albedo(model, wi, n):
    """integral f_s mu_o d(omega_o) over facet normals (see test_models_microfacet.facet_albedo)."""
    x, w = _gl(n, 0.0, 1.0)
    m = nd.sample(model.distribution, model.roughness_x, model.roughness_y, x[:, None], x[None, :]).reshape(-1, 3)
    weight = (w[:, None] * w[None, :]).reshape(-1)
    d = nd.ndf(model.distribution, model.roughness_x, model.roughness_y, m)
    im = m @ wi
    o = 2.0 * im[:, None] * m - wi
    ok = (o[:, 2] > 0.0) & (im > 0.0)
    o = np.where(ok[:, None], o, np.array([0.0, 0.0, 1.0]))
    args = (model.distribution, model.roughness_x, model.roughness_y, model.gaf, model.eta)
    f = specular_brdf(np.broadcast_to(wi, o.shape).copy(), o, *args)
    return float(np.sum(np.where(ok, f * o[:, 2] * 4.0 * im / (d * m[:, 2]), 0.0) * weight))


@pytest.mark.parametrize(
    "params",
    [
        dict(distribution="beckmann", gaf="smith", roughness=0.1, eta=1.5),
        dict(distribution="beckmann", gaf="torrance_sparrow", roughness=3.0, eta=3.0),
        dict(distribution="ggx", gaf="smith_height_correlated", roughness=0.5, eta=1.5),
        dict(distribution="ggx", gaf="smith", roughness_x=0.1, roughness_y=1.0, eta=2.0),
        dict(distribution="gaussian", gaf="torrance_sparrow", roughness=0.3, eta=1.2),
        dict(distribution="gaussian", gaf="smith", roughness=0.2, eta=1.0),
    ],
)
def test_rough_directional_albedo_at_most_one(params):
    """White substrate (K_d = 1): body albedo (project rule) + specular albedo (facet-space rule)
    <= 1 up to 89.9 deg; tolerance = the change of each rule on doubling its resolution."""
    model = models.create("interfaced_lambert", albedo=1.0, **params)
    body_only = _Body(model)
    for theta in np.radians([0.0, 60.0, 85.0, 89.9]):
        wi = direction(theta, 0.2)
        body = [directional_albedo(body_only, wi, n, 2 * n) for n in (32, 64)]
        spec = [specular_albedo(model, wi, n) for n in (128, 256)]
        tol = abs(body[1] - body[0]) + abs(spec[1] - spec[0])
        assert body[1] + spec[1] <= 1.0 + tol, (params, math.degrees(theta), body, spec)


class _Body:
    """The body term (Eq. 12) of a rough interfaced_lambert model, callable like a model."""

    def __init__(self, model):
        self.model = model

    def __call__(self, wi, wo):
        m = self.model
        wi, wo = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wo, float))
        total = m(wi, wo)
        flat_i, flat_o = wi.reshape(-1, 3).copy(), wo.reshape(-1, 3).copy()
        spec = np.zeros(flat_i.shape[0])
        up = (flat_i[:, 2] > 0) & (flat_o[:, 2] > 0)
        spec[up] = specular_brdf(flat_i[up], flat_o[up], m.distribution, m.roughness_x, m.roughness_y, m.gaf, m.eta)
        return total - spec.reshape(total.shape)


def test_finite_at_grazing_and_extremes():
    angles = np.radians([0.0, 60.0, 89.0, 89.999999]).tolist() + [0.5 * math.pi]
    t_i, t_o, p = np.meshgrid(angles, angles, [0.0, 1.0, math.pi], indexing="ij")
    wi, wo = direction(t_i, 0.0), direction(t_o, p)
    for eta in (1.0, 1.0 + 1e-12, 10.0):
        for albedo in (0.0, 1.0):
            assert np.all(np.isfinite(models.create("interfaced_lambert", albedo=albedo, eta=eta)(wi, wo)))
            for dist, gaf, r in (
                ("beckmann", "smith", nd.ROUGHNESS_MIN),
                ("ggx", "smith_height_correlated", nd.ROUGHNESS_MAX),
                ("gaussian", "torrance_sparrow", nd.ROUGHNESS_MAX),
                ("gaussian", "smith", 0.2),
            ):
                f = models.create("interfaced_lambert", albedo=albedo, eta=eta, distribution=dist, gaf=gaf, roughness=r)(wi, wo)
                assert np.all(np.isfinite(f)) and np.all(f >= 0.0), (eta, albedo, dist, gaf, r)
    model = models.create("interfaced_lambert", albedo=0.5, roughness=0.3)
    assert_zero_below_horizon(model, direction(0.1), direction(np.radians(91.0)))


@pytest.mark.parametrize(
    "params, keys",
    [
        (dict(), ["albedo"]),
        (dict(albedo=1.1), ["albedo"]),
        (dict(albedo=0.5, eta=0.9), ["eta"]),
        (dict(albedo=0.5, roughness=5e-5), ["roughness"]),
        (dict(albedo=0.5, roughness_x=0.0, roughness_y=0.2), ["roughness_x"]),
        (dict(albedo=0.5, roughness_x=0.2), ["roughness_x", "roughness_y"]),
        (dict(albedo=0.5, roughness=0.2, roughness_x=0.2), ["roughness", "roughness_x"]),
        (dict(albedo=0.5, roughness=0.2, distribution="phong"), ["distribution"]),
        (dict(albedo=0.5, roughness=0.2, gaf="none"), ["gaf"]),
        (dict(albedo=0.5, distribution="gaussian", roughness_x=0.1, roughness_y=0.3), ["roughness_x", "roughness_y"]),
        (dict(albedo=0.5, distribution="gaussian", roughness=0.5), ["gaf", "roughness"]),
        (dict(albedo=0.5, kd=0.5), ["kd"]),
    ],
)
def test_bad_parameters(params, keys):
    assert_rejected("interfaced_lambert", params, keys)
