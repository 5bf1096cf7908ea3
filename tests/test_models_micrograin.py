"""Checks of ``micrograin`` (Lucas et al. 2024) and ``micrograin_smith`` (Lucas et al. 2023).

Geometry is checked against explicit half-ellipsoids (ray casting among Poisson grains, and a
hit-test of the unit sphere); the model against its own definition (Eq. 21 integrated directly
over true-space normals), reciprocity, energy and the tau0 -> 0 limit.
"""

import functools
import math

import numba
import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import roots_legendre

from microsim import models
from microsim.cli import main
from microsim.core.frames import direction
from microsim.models import micrograin_geometry as geo
from microsim.models.quadrature import directional_albedo
from microsim.physics.boolean_model import (
    grain_density,
    grain_extinction,
    unit_space_direction,
    unit_space_direction_array,
    unit_space_height,
    unit_space_height_array,
)
from microsim.physics.fresnel import fresnel_array, fresnel_conductor_array
from microsim.testing.models import assert_rejected, assert_zero_below_horizon

LAMBERT_BULK = dict(bulk="lambert", bulk_albedo=0.6)
MODEL_CASES = [
    dict(tau0=0.3, beta=1.0, albedo=0.8, **LAMBERT_BULK),
    dict(tau0=0.7, beta_x=0.3, beta_y=3.0, albedo=0.5, **LAMBERT_BULK),
    dict(tau0=0.5, beta=0.4, albedo=0.6, eta=1.5, **LAMBERT_BULK),
    dict(tau0=0.5, beta_x=2.0, beta_y=0.5, albedo=0.6, eta=1.5, **LAMBERT_BULK),
    dict(tau0=0.4, beta=2.0, albedo=0.0, eta=1.0152, k=6.6273),
    dict(tau0=0.2, beta=1.0, albedo=0.8, gaf="uncorrelated", **LAMBERT_BULK),
]


def random_directions(rng, n, mu_min=math.cos(math.radians(89.9))):
    mu = rng.uniform(mu_min, 1.0, n)
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    s = np.sqrt(1.0 - mu**2)
    return np.stack([s * np.cos(phi), s * np.sin(phi), mu], axis=-1)


def smith_case(case):
    return {key: value for key, value in case.items() if key != "gaf"}


# ---------------------------------------------------------------- Boolean-model relations


@pytest.mark.parametrize("tau0, beta_x, beta_y", [(1e-4, 1.0, 1.0), (0.3, 0.5, 2.0), (0.9999, 1e-3, 1e3)])
def test_grain_density_gives_the_filling_factor(tau0, beta_x, beta_y):
    """tau0 = 1 - exp(-rho pi / (beta_x beta_y)) (Eq. 8, conventions §5.3) at rho = grain_density,
    and lambda = pi rho in unit space (beta_x = beta_y = 1)."""
    rho = grain_density(tau0, beta_x, beta_y)
    assert -math.expm1(-rho * math.pi / (beta_x * beta_y)) == pytest.approx(tau0, rel=1e-12)
    assert grain_extinction(tau0) == pytest.approx(math.pi * grain_density(tau0, 1.0, 1.0), rel=1e-15)


def test_unit_space_maps_take_grains_to_unit_half_spheres():
    """E maps the point p of the grain beta_x^2 x^2 + beta_y^2 y^2 + z^2 = 1 to q = E p on the unit
    sphere: the true normal m ~ E^2 p has height h' = q_z, and a direction t tangent at p
    (m.t = 0) stays tangent, t'.q = 0. The scalar kernels equal the array forms."""
    rng = np.random.default_rng(4)
    beta_x, beta_y = 0.4, 2.5
    scale = np.array([beta_x, beta_y, 1.0])
    q = random_directions(rng, 50, mu_min=0.0)
    m = q * scale
    m /= np.linalg.norm(m, axis=-1, keepdims=True)
    heights = unit_space_height_array(m, beta_x, beta_y)
    np.testing.assert_allclose(heights, q[:, 2], rtol=1e-13, atol=1e-15)
    tangent = np.cross(m, rng.normal(size=q.shape))
    tangent /= np.linalg.norm(tangent, axis=-1, keepdims=True)
    mapped = unit_space_direction_array(tangent, beta_x, beta_y)
    np.testing.assert_allclose(np.linalg.norm(mapped, axis=-1), 1.0, rtol=1e-15)
    np.testing.assert_allclose(np.sum(mapped * q, axis=-1), 0.0, atol=1e-14)
    for j in range(q.shape[0]):
        assert unit_space_direction(*tangent[j], beta_x, beta_y) == tuple(mapped[j])
        assert unit_space_height(*m[j], beta_x, beta_y) == heights[j]


# ---------------------------------------------------------------- explicit geometry (test d)


@numba.njit(cache=True)
def _ray_is_free(h, dx, dy, dz, cx, cy, n, bx2, by2):
    """True if the ray from (0, 0, h) towards d misses every half-ellipsoid of centre (cx, cy, 0).

    Ellipsoid bx2 (x - cx)^2 + by2 (y - cy)^2 + z^2 <= 1; the ray starts outside all of them and
    rises (dz > 0, h >= 0), so only the upper halves can be met: a hit needs a real root s > 0.
    """
    for j in range(n):
        px = -cx[j]
        py = -cy[j]
        a = bx2 * dx * dx + by2 * dy * dy + dz * dz
        b = bx2 * px * dx + by2 * py * dy + h * dz
        c = bx2 * px * px + by2 * py * py + h * h - 1.0
        if b < 0.0 and b * b - a * c >= 0.0:
            return False
    return True


@numba.njit(cache=True)
def _poisson_visibility(seed, n_void, tau0, beta_x, beta_y, h, d1, d2):
    """Counts (free, void, tried) for points (0, 0, h) among fresh Poisson grain layers.

    Grains: centres Poisson with density rho = grain_density(tau0, beta_x, beta_y) (conventions §5.3)
    in the box of every centre whose grain can contain the point or meet either ray below
    z = 1. A point inside a grain is rejected (G^dist is conditioned on the void, Eq. 16).
    """
    np.random.seed(seed)
    rho = grain_density(tau0, beta_x, beta_y)
    half_x = 1.0 / beta_x + (1.0 - h) * max(abs(d1[0]) / d1[2], abs(d2[0]) / d2[2])
    half_y = 1.0 / beta_y + (1.0 - h) * max(abs(d1[1]) / d1[2], abs(d2[1]) / d2[2])
    mean = rho * 4.0 * half_x * half_y
    bx2 = beta_x * beta_x
    by2 = beta_y * beta_y
    cx = np.empty(int(mean + 20.0 * math.sqrt(mean) + 100.0))
    cy = np.empty_like(cx)
    free = 0
    void = 0
    tried = 0
    while void < n_void:
        tried += 1
        n = np.random.poisson(mean)
        if n > cx.shape[0]:
            raise ValueError("grain buffer too small")
        inside = False
        for j in range(n):
            cx[j] = np.random.uniform(-half_x, half_x)
            cy[j] = np.random.uniform(-half_y, half_y)
            inside = inside or bx2 * cx[j] ** 2 + by2 * cy[j] ** 2 + h * h <= 1.0
        if inside:
            continue
        void += 1
        if _ray_is_free(h, d1[0], d1[1], d1[2], cx, cy, n, bx2, by2) and _ray_is_free(
            h, d2[0], d2[1], d2[2], cx, cy, n, bx2, by2
        ):
            free += 1
    return free, void, tried


N_VOID = 60_000  # standard error sqrt(p (1 - p) / N) <= 0.0020 for every estimate below
MC_TOL = 0.01

G1_CASES = [  # tau0, beta_x, beta_y, (theta_deg, phi_deg), h
    (0.3, 1.0, 1.0, (60, 0), 0.0),
    (0.6, 1.0, 1.0, (75, 0), 0.3),
    (0.2, 0.5, 0.5, (80, 0), 0.5),
    (0.5, 3.0, 3.0, (45, 0), 0.2),
    (0.9, 1.0, 1.0, (50, 0), 0.6),
    (0.4, 0.4, 2.0, (70, 30), 0.3),
    (0.4, 0.4, 2.0, (70, 120), 0.0),
]


@pytest.mark.parametrize("tau0, beta_x, beta_y, angles, h", G1_CASES)
def test_g1_distant_matches_ray_casting(tau0, beta_x, beta_y, angles, h):
    d = direction(*np.radians(angles))
    free, void, _ = _poisson_visibility(7, N_VOID, tau0, beta_x, beta_y, h, d, d)
    estimate = free / void
    stderr = math.sqrt(estimate * (1.0 - estimate) / void)
    closed = float(geo.g1_distant(d, h, tau0, beta_x, beta_y))
    print(f"G1dist {tau0, beta_x, beta_y, angles, h}: ray casting {estimate:.4f} +- {stderr:.4f}, Eq. 16 {closed:.4f}")
    assert stderr < 0.25 * MC_TOL
    assert abs(estimate - closed) < MC_TOL


VP_CASES = [  # tau0, beta_x, beta_y, i (theta, phi), o (theta, phi)
    (0.3, 1.0, 1.0, (60, 0), (70, 180)),
    (0.5, 1.0, 1.0, (70, 0), (70, 20)),
    (0.5, 1.0, 1.0, (80, 0), (80, 0)),
    (0.3, 2.0, 2.0, (75, 0), (75, 5)),
    (0.4, 0.4, 2.0, (65, 30), (75, 100)),
]


@pytest.mark.parametrize("tau0, beta_x, beta_y, i_angles, o_angles", VP_CASES)
def test_pore_visibility_matches_ray_casting(tau0, beta_x, beta_y, i_angles, o_angles):
    wi = direction(*np.radians(i_angles))
    wo = direction(*np.radians(o_angles))
    free, _, tried = _poisson_visibility(11, N_VOID, tau0, beta_x, beta_y, 0.0, wi, wo)
    estimate = free / tried
    stderr = math.sqrt(estimate * (1.0 - estimate) / tried)
    closed = float(geo.pore_visibility(wi, wo, tau0, beta_x, beta_y))
    uncorrelated = float(geo.pore_visibility(wi, wo, tau0, beta_x, beta_y, correlated=False))
    print(f"V_p {tau0, beta_x, beta_y, i_angles, o_angles}: ray casting {estimate:.4f} +- {stderr:.4f}, "
          f"Eq. 23 {closed:.4f} (uncorrelated {uncorrelated:.4f})")
    assert stderr < 0.25 * MC_TOL
    assert abs(estimate - closed) < MC_TOL


@pytest.mark.parametrize("tau0, beta_x, beta_y, i_angles, o_angles, h", [
    (0.5, 1.0, 1.0, (70, 0), (60, 40), 0.3),
    (0.4, 0.5, 2.0, (70, 10), (75, 60), 0.2),
    (0.6, 1.0, 1.0, (75, 0), (75, 10), 0.2),
])
def test_g_distant_at_height_matches_ray_casting(tau0, beta_x, beta_y, i_angles, o_angles, h):
    wi = direction(*np.radians(i_angles))
    wo = direction(*np.radians(o_angles))
    free, void, _ = _poisson_visibility(13, N_VOID, tau0, beta_x, beta_y, h, wi, wo)
    estimate = free / void
    closed = float(geo.g_distant(wi, wo, h, tau0, beta_x, beta_y))
    print(f"Gdist {tau0, beta_x, beta_y, i_angles, o_angles, h}: ray casting {estimate:.4f}, Eq. 19 {closed:.4f}")
    assert abs(estimate - closed) < MC_TOL


def test_retro_correlation_is_resolved():
    """Near retro-reflection the uncorrelated V_p (Eq. 17) misses the ray-cast value by >> 1%."""
    wi = direction(np.radians(80.0), 0.0)
    free, _, tried = _poisson_visibility(17, N_VOID, 0.5, 1.0, 1.0, 0.0, wi, wi)
    estimate = free / tried
    assert abs(estimate - float(geo.pore_visibility(wi, wi, 0.5, 1.0, 1.0, correlated=False))) > 5 * MC_TOL
    assert abs(estimate - float(geo.pore_visibility(wi, wi, 0.5, 1.0, 1.0))) < MC_TOL


@pytest.mark.parametrize("tau0", [1e-4, 0.3, 0.9999])
def test_pore_visibility_at_normal_incidence(tau0):
    n = np.array([0.0, 0.0, 1.0])
    assert float(geo.pore_visibility(n, n, tau0, 0.7, 1.9)) == pytest.approx(1.0 - tau0, rel=1e-14)


# ---------------------------------------------------------------- shadow areas (App. A-C)


def _polar_radius_by_bisection(psi, h, d, r_max):
    """Boundary radius of {p : the ray from (p, h) towards d meets the unit ball} along psi."""
    q = np.stack([np.cos(psi), np.sin(psi)], axis=-1)
    lo = np.zeros_like(psi)
    hi = np.full_like(psi, r_max)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        p = np.concatenate([mid[:, None] * q, np.full((psi.size, 1), h)], axis=-1)
        b = p @ d
        c = np.sum(p * p, axis=-1) - 1.0
        hit = (c <= 0.0) | ((b <= 0.0) & (b * b - c >= 0.0))
        lo = np.where(hit, mid, lo)
        hi = np.where(hit, hi, mid)
    return 0.5 * (lo + hi)


@pytest.mark.parametrize("i_angles, o_angles, h", [
    ((60, 0), (60, 0), 0.3),
    ((60, 0), (70, 180), 0.2),
    ((75, 10), (65, 50), 0.3),
    ((80, 0), (80, 100), 0.0),
    ((70, 0), (50, 20), 0.5),
    ((88, 0), (60, 5), 0.1),
    ((45, 0), (80, 90), 0.4),
    ((80, 0), (30, 0), 0.2),
])
def test_overlap_area_matches_hit_test(i_angles, o_angles, h):
    """sigma_s and sigma_cap against the area of explicit shadow sets, by polar integration.

    Each shadow set plus the disc is convex (the sphere swept along -w, cut by a plane), so its
    boundary radius along any polar angle is found by bisection on a ray-sphere hit test; areas
    by the trapezoidal rule over 20000 polar angles (relative error ~ 1e-7 for these shapes).
    """
    a = direction(*np.radians(i_angles))
    b = direction(*np.radians(o_angles))
    psi = np.linspace(0.0, 2.0 * np.pi, 20001)
    r_max = 2.0 + 2.0 / min(a[2], b[2])
    ra = _polar_radius_by_bisection(psi, h, a, r_max)
    rb = _polar_radius_by_bisection(psi, h, b, r_max)
    disc = np.pi * (1.0 - h * h)
    area_a = 0.5 * np.trapezoid(ra**2, psi) - disc
    area_b = 0.5 * np.trapezoid(rb**2, psi) - disc
    common = 0.5 * np.trapezoid(np.minimum(ra, rb) ** 2, psi) - disc
    tol = 1e-4 * (area_a + area_b) + 1e-6
    assert geo.shadow_area(math.hypot(a[0], a[1]), a[2], h) == pytest.approx(area_a, abs=tol)
    assert geo.shadow_area(math.hypot(b[0], b[1]), b[2], h) == pytest.approx(area_b, abs=tol)
    assert geo.overlap_area(*a, *b, h) == pytest.approx(common, abs=tol)
    assert geo.overlap_area(*b, *a, h) == pytest.approx(common, abs=tol)


@pytest.mark.parametrize("theta_deg, h", [(30, 0.2), (60, 0.5), (80, 0.1), (89, 0.7), (45, 0.0)])
def test_shadow_area_equals_printed_appendix_a(theta_deg, h):
    """sigma_s = sigma_e - sigma_c - sigma_t exactly as printed in App. A, and App. C at h = 0."""
    t = math.radians(theta_deg)
    theta_m = math.acos(h)
    cos_phi_q = -1.0 / (math.tan(theta_m) * math.tan(t))
    q_x = math.sin(theta_m) * cos_phi_q
    q_y = math.sin(theta_m) * math.sqrt(1.0 - cos_phi_q**2)
    e_x = math.tan(t) * math.cos(theta_m)
    sigma_e = math.acos(-(q_x - e_x) * math.cos(t)) / math.cos(t)
    sigma_c = (math.pi - math.acos(cos_phi_q)) * math.sin(theta_m) ** 2
    sigma_t = abs(e_x * q_y)
    assert geo.shadow_area(math.sin(t), math.cos(t), h) == pytest.approx(sigma_e - sigma_c - sigma_t, rel=1e-12)
    if h == 0.0:
        assert geo.shadow_area(math.sin(t), math.cos(t), h) == pytest.approx(0.5 * math.pi * (1 / math.cos(t) - 1))


def test_no_shadow_above_the_silhouette():
    t = math.radians(40.0)
    assert geo.shadow_area(math.sin(t), math.cos(t), math.sin(t) + 1e-9) == 0.0
    assert geo.shadow_area(0.0, 1.0, 0.0) == 0.0


# ---------------------------------------------------------------- NDF and Smith Lambda


@functools.lru_cache(maxsize=None)
def _hemisphere_product_rule(n_theta, n_phi):
    """Gauss-Legendre in theta on (0, pi/2) x midpoint in phi: (normals (M, 3), weights (M,))."""
    x, w = roots_legendre(n_theta)
    theta = 0.25 * np.pi * (x + 1.0)
    wt = 0.25 * np.pi * w * np.sin(theta)
    phi = (np.arange(n_phi) + 0.5) * 2.0 * np.pi / n_phi
    t, p = np.meshgrid(theta, phi, indexing="ij")
    m = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)
    weight = wt[:, None] * np.full(n_phi, 2.0 * np.pi / n_phi)[None, :]
    return m.reshape(-1, 3), weight.reshape(-1)


@pytest.mark.parametrize("tau0", [1e-4, 0.3, 0.9, 0.9999])
@pytest.mark.parametrize("beta_x, beta_y", [(1.0, 1.0), (0.2, 0.2), (4.0, 4.0), (0.3, 3.0), (2.0, 0.5)])
def test_ndf_is_normalised(tau0, beta_x, beta_y):
    m, weight = _hemisphere_product_rule(400, 256)
    total = np.sum(geo.ndf(m, tau0, beta_x, beta_y) * m[:, 2] * weight)
    assert abs(total - 1.0) < 1e-4


@pytest.mark.parametrize("tau0, beta_x, beta_y", [(0.3, 1.0, 1.0), (0.9, 0.5, 0.5), (0.5, 0.4, 2.0)])
def test_smith_lambda_matches_ndf_projection(tau0, beta_x, beta_y):
    """Lambda(w) = integral D(m) (w.m)+ dm / (w.n) - 1, the NDF integrated over true-space normals.

    This ties the height measure used by the models (p(h') dh' dphi' / 2 pi) to D of Eq. 10-12.
    The kink of (w.m)+ makes the product rule second order: the tolerance is twice the change
    from the (300, 512) to the (600, 1024) rule.
    """
    rules = [_hemisphere_product_rule(600, 1024), _hemisphere_product_rule(300, 512)]
    ndfs = [geo.ndf(m, tau0, beta_x, beta_y) for m, _ in rules]
    for theta, phi in [(0.0, 0.0), (30.0, 20.0), (60.0, 100.0), (80.0, 45.0)]:
        w = direction(math.radians(theta), math.radians(phi))
        fine, coarse = (np.sum(d * np.maximum(m @ w, 0.0) * weight) / w[2] - 1.0 for (m, weight), d in zip(rules, ndfs))
        lam = float(geo.smith_lambda(w, tau0, beta_x, beta_y))
        assert lam == pytest.approx(fine, abs=2.0 * abs(fine - coarse) + 1e-12)


def test_smith_lambda_of_isolated_hemispheres():
    """tau0 -> 0: the normals of hemispheres, uniform per area, give 1 + Lambda = (1 + mu) / (2 mu).

    Lambda - Lambda_0 = O(lambda), so the relative tolerance at tau0 = 1e-4 is 1e-3.
    """
    for theta in [20.0, 50.0, 75.0, 89.0]:
        w = direction(math.radians(theta), 0.0)
        mu = w[2]
        assert float(geo.smith_lambda(w, 1e-4, 1.0, 1.0)) == pytest.approx((1.0 - mu) / (2.0 * mu), rel=1e-3)


# ---------------------------------------------------------------- the micrograin model


def _direct_grain_brdf(model, wi, wo, n):
    """tau0 f^S (Eq. 21 + 22) integrated over true-space normals with an n x 2n product rule."""
    p = model.values
    m, weight = _hemisphere_product_rule(n, 2 * n)
    d = geo.ndf(m, p["tau0"], p["beta_x"], p["beta_y"])
    ci = np.maximum(m @ wi, 0.0)
    co = np.maximum(m @ wo, 0.0)
    keep = (ci > 0.0) & (co > 0.0) & (d > 0.0)
    h = unit_space_height_array(m[keep], p["beta_x"], p["beta_y"])
    g = geo.g_distant(wi, wo, h, p["tau0"], p["beta_x"], p["beta_y"], p["gaf"] == "correlated")
    t = (1.0 - fresnel_array(ci[keep], p["eta"], p["k"])) * (1.0 - fresnel_array(co[keep], p["eta"], p["k"]))
    diffuse = p["albedo"] / np.pi * np.sum(ci[keep] * co[keep] * d[keep] * g * t * weight[keep]) / (wi[2] * wo[2])
    hv = (wi + wo) / np.linalg.norm(wi + wo)
    h_half = unit_space_height_array(hv, p["beta_x"], p["beta_y"])
    specular = (geo.ndf(hv, p["tau0"], p["beta_x"], p["beta_y"])
                * geo.g_distant(wi, wo, h_half, p["tau0"], p["beta_x"], p["beta_y"], p["gaf"] == "correlated")
                * fresnel_array(hv @ wi, p["eta"], p["k"]) / (4.0 * wi[2] * wo[2]))
    return p["tau0"] * (diffuse + specular)


@pytest.mark.parametrize("params", [
    dict(tau0=0.5, beta=1.0, albedo=0.8),
    dict(tau0=0.7, beta_x=0.5, beta_y=2.0, albedo=0.8),
    dict(tau0=0.3, beta_x=1.5, beta_y=0.7, albedo=0.6, eta=1.5),
    dict(tau0=0.6, beta=2.0, albedo=0.8, gaf="uncorrelated"),
])
def test_grain_term_matches_direct_integration(params):
    """The model's Gauss rule for Eq. 21 against a product rule over true-space normals.

    The kinks of chi+(i.m) chi+(o.m) make the product rule second order: the tolerance is the
    difference between n = 500 and n = 250 (an upper bound on the n = 500 error) plus 1e-5
    relative, the accuracy of the model's own rule for these moderate shapes.
    """
    model = models.create("micrograin", **params)
    pairs = [((30, 0), (50, 160)), ((70, 10), (65, 30)), ((80, 0), (40, 200)), ((60, 90), (85, 270))]
    for (ti, pi_), (to, po) in pairs:
        wi = direction(math.radians(ti), math.radians(pi_))
        wo = direction(math.radians(to), math.radians(po))
        fine = _direct_grain_brdf(model, wi, wo, 500)
        coarse = _direct_grain_brdf(model, wi, wo, 250)
        value = float(model(wi, wo))
        assert value == pytest.approx(fine, abs=abs(fine - coarse) + 1e-5 * fine)


@pytest.mark.parametrize("params", MODEL_CASES)
def test_reciprocity(params):
    rng = np.random.default_rng(3)
    wi = random_directions(rng, 300)
    wo = random_directions(rng, 300)
    for name, p in [("micrograin", params), ("micrograin_smith", smith_case(params))]:
        model = models.create(name, **p)
        assert model.reciprocal
        f = model(wi, wo)
        g = model(wo, wi)
        assert np.all(f >= 0.0)
        assert np.all(np.abs(f - g) <= 1e-10 * np.maximum(np.abs(f), np.abs(g)))


ENERGY_CASES = [  # white grains on a white base: the single-scattering albedo must stay below 1
    dict(tau0=0.05, beta=0.2, albedo=1.0, bulk="lambert", bulk_albedo=1.0),
    dict(tau0=0.95, beta=0.2, albedo=1.0, bulk="lambert", bulk_albedo=1.0),
    dict(tau0=0.05, beta=5.0, albedo=1.0, bulk="lambert", bulk_albedo=1.0),
    dict(tau0=0.95, beta=5.0, albedo=1.0, bulk="lambert", bulk_albedo=1.0),
    dict(tau0=0.5, beta_x=0.3, beta_y=3.0, albedo=1.0, bulk="lambert", bulk_albedo=1.0),
]


@pytest.mark.parametrize("params", ENERGY_CASES)
def test_directional_albedo_at_most_one(params):
    """Quadrature error bound: the change from a (24, 48) to a (48, 96) hemisphere rule."""
    theta = np.radians([0.0, 45.0, 75.0, 89.9])
    wi = direction(theta, np.radians(30.0))
    for name, p in [("micrograin", params), ("micrograin_smith", params)]:
        model = models.create(name, **p)
        coarse = directional_albedo(model, wi, 24, 48)
        fine = directional_albedo(model, wi, 48, 96)
        print(name, params, np.round(fine, 5))
        assert np.all(fine <= 1.0 + np.abs(fine - coarse) + 1e-12)
        assert np.all(fine > 0.0)


@pytest.mark.parametrize("name", ["micrograin", "micrograin_smith"])
@pytest.mark.parametrize("grains", [dict(albedo=0.0, eta=1e3, k=1e3), dict(material="mirror")])
def test_directional_albedo_of_mirror_grains_at_most_one(name, grains):
    """Near-perfect conductor and mirror grains on a white base; a dense rule resolves the specular lobe."""
    model = models.create(name, tau0=0.5, beta=0.3, **grains, bulk="lambert", bulk_albedo=1.0)
    wi = direction(np.radians([0.0, 60.0, 85.0]), 0.0)
    coarse = directional_albedo(model, wi, 96, 192)
    fine = directional_albedo(model, wi, 192, 384)
    assert np.all(fine <= 1.0 + np.abs(fine - coarse))


def _first_order_bound(tau0, params, wi, wo):
    """|f - f^B| <= tau0 [f^S + f^B (1 + U / pi)] to first order in tau0 (Eq. 20, 23).

    f - f^B = tau0 f^S + f^B ((1 - tau0) exp(-lambda U / pi) - 1), U <= sigma_s(i', 0) +
    sigma_s(o', 0) = pi / 2 (1 / mu_i' + 1 / mu_o' - 2) (App. C), lambda <= tau0 (1 + tau0). For
    Lambertian grains f^S,d <= K_d / pi (1 + Lambda(i)) / mu_o (drop (o.m) / mu_o <= 1 / mu_o and
    G T <= 1), Lambda at tau0 -> 0 from test_smith_lambda_of_isolated_hemispheres.
    """
    bx, by = params["beta_x"], params["beta_y"]
    mu_i = unit_space_direction_array(wi, bx, by)[..., 2]
    mu_o = unit_space_direction_array(wo, bx, by)[..., 2]
    grains = params["albedo"] / np.pi * np.minimum((1.0 + mu_i) / (2.0 * mu_i) / wo[..., 2],
                                                   (1.0 + mu_o) / (2.0 * mu_o) / wi[..., 2])
    bulk = params["bulk_albedo"] / np.pi * (1.0 + 0.5 * (1.0 / mu_i + 1.0 / mu_o - 2.0))
    return tau0 * (grains + bulk) * (1.0 + 2.0 * tau0)


@pytest.mark.parametrize("params", [
    dict(beta=1.0, albedo=0.8, bulk="lambert", bulk_albedo=0.6),
    dict(beta_x=0.3, beta_y=3.0, albedo=0.5, bulk="lambert", bulk_albedo=0.9),
    dict(beta=4.0, albedo=0.8),
])
def test_small_tau0_tends_to_the_bulk(params):
    """At tau0 = 1e-4, f is within the first-order bound of f^B, and (f - f^B) / tau0 has settled
    to its tau0 -> 0 slope (same at 2e-4 within the second-order bound)."""
    rng = np.random.default_rng(5)
    wi = random_directions(rng, 200, mu_min=math.cos(math.radians(80.0)))
    wo = random_directions(rng, 200, mu_min=math.cos(math.radians(80.0)))
    tau0 = 1e-4
    model = models.create("micrograin", tau0=tau0, **params)
    bulk = model.bulk_albedo / np.pi
    f = model(wi, wo)
    assert np.all(np.abs(f - bulk) <= _first_order_bound(tau0, model.values, wi, wo))
    coefficient = _first_order_bound(tau0, model.values, wi, wo) / tau0
    slope = (f - bulk) / tau0
    slope_2 = (models.create("micrograin", tau0=2 * tau0, **params)(wi, wo) - bulk) / (2 * tau0)
    # second order: every tau0 dependence enters through lambda U / pi <= lambda (1 + U0 / pi)
    mu_i = unit_space_direction_array(wi, model.beta_x, model.beta_y)[..., 2]
    mu_o = unit_space_direction_array(wo, model.beta_x, model.beta_y)[..., 2]
    growth = 1.0 + 0.5 * (1.0 / mu_i + 1.0 / mu_o)
    assert np.all(np.abs(slope_2 - slope) <= 4.0 * tau0 * growth * coefficient)


@pytest.mark.parametrize("name", ["micrograin", "micrograin_smith"])
def test_finite_at_grazing_angles_and_parameter_extremes(name):
    grazing = [0.0, 1e-300, 1e-15, 1e-9, 1e-4, 0.02]
    wi = np.array([[math.sqrt(1 - z * z), 0.0, z] for z in grazing] + [[0.0, 0.0, 1.0]])
    wo = np.array([[-math.sqrt(1 - z * z) * 0.6, math.sqrt(1 - z * z) * 0.8, z] for z in grazing] + [[0.6, 0.0, 0.8]])
    pairs_i = np.concatenate([wi, wi, wi[::-1]])
    pairs_o = np.concatenate([wo, wi, wo])
    for tau0 in [1e-4, 0.9999]:
        for betas in [dict(beta=1e-3), dict(beta=1e3), dict(beta_x=1e-3, beta_y=1e3), dict(beta_x=1e3, beta_y=1e-3)]:
            for material in [dict(albedo=1.0), dict(albedo=1.0, eta=3.0), dict(albedo=0.0, eta=0.2, k=1e3)]:
                model = models.create(name, tau0=tau0, **betas, **material, bulk="lambert", bulk_albedo=1.0)
                f = model(pairs_i, pairs_o)
                assert np.all(np.isfinite(f)) and np.all(f >= 0.0), (tau0, betas, material)
                assert_zero_below_horizon(model, wi[-1], np.array([0.6, 0.0, -0.8]))


@pytest.mark.parametrize("beta", [1.0, 0.3, 3.0])
def test_normal_incidence_and_view(beta):
    """i = o = n: nothing is shadowed or masked, V_p = 1 - tau0, T = 1, and Eq. 21 reduces to
    K_d / pi * integral D (m.n)^2 dm = K_d / pi * int_0^1 p(h) h / |E m'| dh (m.n = h / |E m'|) with
    |E m'| = sqrt(beta^2 (1 - h^2) + h^2), p(h) = 2 lambda h exp(-lambda (1 - h^2)) / tau0 (the
    CDF of Eq. 13 in h); integrated here by adaptive quadrature."""
    tau0, kd, bulk_albedo = 0.4, 0.7, 0.2
    lam = grain_extinction(tau0)
    mean, _ = quad(lambda h: 2 * lam * h * h * math.exp(-lam * (1 - h * h)) / tau0
                   / math.sqrt(beta**2 * (1 - h * h) + h * h), 0.0, 1.0, epsabs=1e-13, epsrel=1e-12)
    model = models.create("micrograin", tau0=tau0, beta=beta, albedo=kd, bulk="lambert", bulk_albedo=bulk_albedo)
    n = np.array([0.0, 0.0, 1.0])
    expected = tau0 * kd / np.pi * mean + (1.0 - tau0) * bulk_albedo / np.pi
    assert float(model(n, n)) == pytest.approx(expected, rel=1e-9)


def test_smith_model_weights():
    """micrograin_smith: 1 - w+ = (1 - tau0)^((1 / mu_i' + 1 / mu_o') / 2) (Eq. 4, 24, 25) with
    Lambertian grains (f^S = K_d / pi): f is the w+ blend of the two constants."""
    model = models.create("micrograin_smith", tau0=0.3, beta=2.0, albedo=0.9, bulk="lambert", bulk_albedo=0.1)
    wi = direction(np.radians(50.0), 0.0)
    wo = direction(np.radians(70.0), np.radians(120.0))
    mu_i = float(unit_space_direction_array(wi, 2.0, 2.0)[2])
    mu_o = float(unit_space_direction_array(wo, 2.0, 2.0)[2])
    bulk_weight = 0.7 ** (0.5 * (1.0 / mu_i + 1.0 / mu_o))
    expected = (1.0 - bulk_weight) * 0.9 / np.pi + bulk_weight * 0.1 / np.pi
    assert float(model(wi, wo)) == pytest.approx(expected, rel=1e-12)
    n = np.array([0.0, 0.0, 1.0])
    assert float(model(n, n)) == pytest.approx((0.3 * 0.9 + 0.7 * 0.1) / np.pi, rel=1e-12)


def test_smith_gaf_forms():
    """Conductor grains, absorbing base: f = w+ D G F / (4 mu_i mu_o), so the ratio of the two
    Smith forms is (1 + L_i)(1 + L_o) / (1 + L_i + L_o) with L = smith_lambda."""
    common = dict(tau0=0.5, beta_x=0.6, beta_y=1.5, albedo=0.0, eta=1.0152, k=6.6273)
    rng = np.random.default_rng(9)
    wi = random_directions(rng, 100, mu_min=0.05)
    wo = random_directions(rng, 100, mu_min=0.05)
    separable = models.create("micrograin_smith", **common)(wi, wo)
    correlated = models.create("micrograin_smith", gaf="height_correlated", **common)(wi, wo)
    li = geo.smith_lambda(wi, 0.5, 0.6, 1.5)
    lo = geo.smith_lambda(wo, 0.5, 0.6, 1.5)
    assert np.allclose(correlated / separable, (1 + li) * (1 + lo) / (1 + li + lo), rtol=1e-12)


@pytest.mark.parametrize("name", ["micrograin", "micrograin_smith"])
@pytest.mark.parametrize("bad, key", [
    (dict(tau0=0.0, beta=1.0, albedo=0.5), "tau0"),
    (dict(tau0=1.0, beta=1.0, albedo=0.5), "tau0"),
    (dict(tau0=0.5, beta=0.0, albedo=0.5), "beta"),
    (dict(tau0=0.5, beta=-1.0, albedo=0.5), "beta"),
    (dict(tau0=0.5, beta_x=1.0, beta_y=1e4, albedo=0.5), "beta_y"),
    (dict(tau0=0.5, beta=1.0, beta_x=1.0, albedo=0.5), "beta"),
    (dict(tau0=0.5, beta_x=1.0, albedo=0.5), "beta"),
    (dict(tau0=0.5, albedo=0.5), "beta"),
    (dict(tau0=0.5, beta=1.0, albedo=1.2), "albedo"),
    (dict(tau0=0.5, beta=1.0), "albedo"),
    (dict(tau0=0.5, beta=1.0, albedo=0.5, eta=0.0), "eta"),
    (dict(tau0=0.5, beta=1.0, albedo=0.5, k=-1.0), "k"),
    (dict(tau0=0.5, beta=1.0, albedo=0.5, k=2.0), "albedo"),
    (dict(tau0=0.5, beta=1.0, albedo=0.5, bulk="mirror"), "bulk"),
    (dict(tau0=0.5, beta=1.0, albedo=0.5, bulk="lambert"), "bulk_albedo"),
    (dict(tau0=0.5, beta=1.0, albedo=0.5, bulk_albedo=0.3), "bulk_albedo"),
    (dict(tau0=0.5, beta=1.0, albedo=0.5, gaf="smith"), "gaf"),
    (dict(tau0=0.5, beta=1.0, albedo=0.5, roughness=0.1), "roughness"),
])
def test_bad_parameters_raise(name, bad, key):
    assert_rejected(name, bad, [key])


def test_beta_alias():
    iso = models.create("micrograin", tau0=0.4, beta=0.7, albedo=0.5)
    explicit = models.create("micrograin", tau0=0.4, beta_x=0.7, beta_y=0.7, albedo=0.5)
    assert (iso.beta_x, iso.beta_y) == (0.7, 0.7)
    assert explicit.beta == 0.7
    assert models.create("micrograin", tau0=0.4, beta_x=0.7, beta_y=0.8, albedo=0.5).beta is None
    rng = np.random.default_rng(1)
    wi, wo = random_directions(rng, 20), random_directions(rng, 20)
    assert np.array_equal(iso(wi, wo), explicit(wi, wo))


# ---------------------------------------------------------------- parameters named as in the scene config

COPPER = dict(eta=1.0152, k=6.6273)
OLD_AND_NEW = [  # (old form, the same in the names of the run config)
    (dict(albedo=0.8, bulk="lambert", bulk_albedo=0.6),
     dict(material="lambert", albedo=0.8, base="lambert", base_albedo=0.6)),
    (dict(albedo=0.8, eta=1.0, k=0.0, bulk="absorber"), dict(material="lambert", albedo=0.8, base="absorber")),
    (dict(albedo=0.0, **COPPER, bulk="lambert", bulk_albedo=0.3),
     dict(material="conductor", **COPPER, base="lambert", base_albedo=0.3)),
    (dict(albedo=0.0, **COPPER), dict(material="conductor", **COPPER)),
    (dict(**COPPER), dict(material="conductor", **COPPER)),
    (dict(albedo=0.6, eta=1.5, bulk="lambert", bulk_albedo=0.6),
     dict(material="interfaced_lambert", albedo=0.6, eta=1.5, base="lambert", base_albedo=0.6)),
    (dict(albedo=0.6, eta=1.5, k=0.0), dict(material="interfaced_lambert", albedo=0.6, eta=1.5, k=0.0)),
    (dict(albedo=0.6, eta=1.5, bulk_albedo=0.0), dict(material="interfaced_lambert", albedo=0.6, eta=1.5)),
]


@pytest.mark.parametrize("name", ["micrograin", "micrograin_smith"])
@pytest.mark.parametrize("shape", [dict(beta=0.8), dict(beta_x=0.5, beta_y=2.0)])
@pytest.mark.parametrize("old, new", OLD_AND_NEW)
def test_config_names_equal_the_old_names(name, shape, old, new):
    """The names of the run config and the old ones give the same resolved parameters and the
    same values, bit for bit; mixing an old grain form with the new base names too."""
    rng = np.random.default_rng(21)
    wi, wo = random_directions(rng, 300), random_directions(rng, 300)
    a = models.create(name, tau0=0.45, **shape, **old)
    b = models.create(name, tau0=0.45, **shape, **new)
    assert a.values == b.values
    assert np.array_equal(a(wi, wo), b(wi, wo))
    grains_old = {key: v for key, v in old.items() if not key.startswith("bulk")}
    base_new = {key: v for key, v in new.items() if key.startswith("base")}
    mixed = models.create(name, tau0=0.45, **shape, **grains_old, **base_new)
    assert mixed.values == b.values
    assert np.array_equal(mixed(wi, wo), b(wi, wo))


def test_resolved_values_mirror_the_config():
    conductor = models.create("micrograin", tau0=0.4, beta=1.0, material="conductor", **COPPER)
    assert (conductor.albedo, conductor.eta, conductor.k, conductor.base, conductor.base_albedo) == (
        0.0, 1.0152, 6.6273, "absorber", 0.0)
    mirror = models.create("micrograin", tau0=0.4, beta=1.0, material="mirror", base="lambert", base_albedo=0.5)
    assert (mirror.albedo, mirror.eta, mirror.k, mirror.bulk, mirror.bulk_albedo) == (0.0, None, None, "lambert", 0.5)
    old = models.create("micrograin", tau0=0.4, beta=1.0, albedo=0.7, eta=1.3)
    assert (old.material, old.albedo, old.eta, old.k) == ("interfaced_lambert", 0.7, 1.3, 0.0)
    # what `microsim compare --param KEY=VALUE` passes: strings
    cli = models.create("micrograin_smith", tau0="0.4", beta="1", material="mirror", base="lambert", base_albedo="0.5")
    assert cli.values == models.create("micrograin_smith", tau0=0.4, beta=1.0, material="mirror", bulk="lambert",
                                       bulk_albedo=0.5).values


@pytest.mark.parametrize("name", ["micrograin", "micrograin_smith"])
def test_mirror_grains_are_conductor_grains_with_f_one(name):
    """Absorbing base: both models are a sum of terms proportional to F(i.h) for conductor grains,
    so mirror grains give the conductor's values divided by its F (rounding only); and a conductor
    of huge k, whose 1 - F is below 1 - F_min at every angle, lies within that of the mirror."""
    rng = np.random.default_rng(8)
    wi, wo = random_directions(rng, 300, mu_min=0.02), random_directions(rng, 300, mu_min=0.02)
    hv = (wi + wo) / np.linalg.norm(wi + wo, axis=-1, keepdims=True)
    cos_d = np.sum(wi * hv, axis=-1)
    shape = dict(tau0=0.5, beta_x=0.6, beta_y=1.4)
    mirror = models.create(name, **shape, material="mirror")(wi, wo)
    conductor = models.create(name, **shape, material="conductor", **COPPER)(wi, wo)
    assert np.all(mirror > 0.0)
    np.testing.assert_allclose(conductor / fresnel_conductor_array(cos_d, *COPPER.values()), mirror, rtol=1e-13)

    base = dict(base="lambert", base_albedo=0.7)
    mirror = models.create(name, **shape, material="mirror", **base)(wi, wo)
    near = models.create(name, **shape, material="conductor", eta=1.0, k=1e4, **base)(wi, wo)
    f_min = float(np.min(fresnel_conductor_array(np.linspace(0.0, 1.0, 1001), 1.0, 1e4)))
    assert 0.0 < 1.0 - f_min < 1e-3
    assert np.all(near <= mirror)
    assert np.all(mirror - near <= (1.0 - f_min) * mirror)


@pytest.mark.parametrize("name", ["micrograin", "micrograin_smith"])
@pytest.mark.parametrize("bad, keys", [
    (dict(material="conductor", albedo=0.5, **COPPER), ["albedo"]),
    (dict(material="conductor", albedo=0.0, **COPPER), ["albedo"]),
    (dict(material="conductor", eta=1.5), ["k"]),
    (dict(material="conductor", k=2.0), ["eta"]),
    (dict(material="mirror", eta=1.5), ["eta"]),
    (dict(material="mirror", albedo=0.5), ["albedo"]),
    (dict(material="lambert", albedo=0.5, eta=1.5), ["eta"]),
    (dict(material="lambert", albedo=0.5, k=0.0), ["k"]),
    (dict(material="lambert"), ["albedo"]),
    (dict(material="interfaced_lambert", albedo=0.5), ["eta"]),
    (dict(material="interfaced_lambert", eta=1.5), ["albedo"]),
    (dict(material="interfaced_lambert", albedo=0.5, eta=1.5, k=1.0), ["k"]),
    (dict(material="plastic", albedo=0.5), ["material"]),
    (dict(albedo=0.5, base="absorber", base_albedo=0.3), ["base_albedo"]),
    (dict(albedo=0.5, base_albedo=0.0), ["base_albedo"]),
    (dict(albedo=0.5, base="lambert"), ["base_albedo"]),
    (dict(albedo=0.5, base="mirror"), ["base"]),
    (dict(albedo=0.5, base_albedo=1.5), ["base_albedo"]),
    (dict(albedo=0.5, bulk="lambert", base="lambert", base_albedo=0.5), ["bulk", "base"]),
    (dict(albedo=0.5, base="lambert", bulk_albedo=0.5, base_albedo=0.5), ["bulk_albedo", "base_albedo"]),
])
def test_bad_config_names_raise_one_line(name, bad, keys):
    assert_rejected(name, dict(tau0=0.5, beta=1.0, **bad), keys)
    with pytest.raises(ValueError) as err:
        models.create(name, tau0=0.5, beta=1.0, **bad)
    assert "\n" not in str(err.value)


def test_compare_takes_the_config_names(tmp_path, capsys):
    """`microsim compare --param` passes the names through: a bad combination is one line naming
    the key (exit 2); a good one gets as far as the table."""
    params = ["--param", "tau0=0.4", "--param", "beta=1", "--param", "material=conductor"]
    missing = str(tmp_path / "missing.h5")
    assert main(["compare", missing, "--model", "micrograin", *params, "--param", "albedo=0.5"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "albedo" in lines[0] and "conductor" in lines[0]
    good = params + ["--param", "eta=1.0152", "--param", "k=6.6273", "--param", "base=lambert",
                     "--param", "base_albedo=0.5"]
    assert main(["compare", missing, "--model", "micrograin", *good]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "TABLE.h5" in lines[0] and "not found" in lines[0]


def test_models_listing_shows_optional_keys_and_aliases(capsys):
    assert main(["models"]) == 0
    out = capsys.readouterr().out.splitlines()
    start = next(j for j, line in enumerate(out) if line.startswith("micrograin:"))
    end = next(j for j in range(start + 1, len(out)) if not out[j].startswith("    "))
    rows = {line.split()[0]: line for line in out[start + 1:end]}
    for key in ("material", "albedo", "eta", "k", "base_albedo", "bulk", "bulk_albedo"):
        assert "optional" in rows[key], rows[key]
    assert "default absorber" in rows["base"]
    assert "old name of base" in rows["bulk"] and "old name of base_albedo" in rows["bulk_albedo"]
