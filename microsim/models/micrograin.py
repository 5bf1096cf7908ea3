"""The fully-correlated anisotropic micrograin BSDF (Lucas et al. 2024), ``micrograin``.

Paper: Lucas et al. 2024 (fully-correlated anisotropic micrograin BSDF; docs/reference/papers.md),
whose equation, section, figure and appendix numbers are cited below; grain geometry and
parametrisation in :mod:`microsim.models.micrograin_geometry`. The model (Eq. 20-23) is

    f(i, o) = tau0 [f^S,d(i, o) + D(h) G(i, o, h) F(i.h) / (4 mu_i mu_o)] + V_p(i, o) f^B(i, o)

with the micrograin NDF D (Eq. 10-12), the height- and direction-correlated GAF
G = chi+(i.m) chi+(o.m) G^dist(i, o, h'(m)) (Eq. 18-19; Eq. 17 with ``gaf = "uncorrelated"``),
pore visibility V_p = (1 - tau0) G^dist(i, o, 0) (Eq. 23) and the diffuse grain term (Eq. 21)

    f^S,d = K_d / pi * integral (i.m)+ (o.m)+ / (mu_i mu_o) D(m) G(i, o, m) T(i, o, m) dm,
    T = (1 - F(i.m)) (1 - F(o.m)).

For ``lambert``, ``conductor`` and ``mirror`` grains each term is the exact single-scattering
contribution of the grain layer of docs/conventions.md §5.3. ``interfaced_lambert`` grains are
not exact: the model's T = (1 - F(i.m)) (1 - F(o.m)) (Eq. 21-22) crosses the coat once each way
and omits the internal reflections (the paper says so in Sec. 7), whereas the scenes'
interfaced_lambert material follows every bounce under the interface (Fresnel and total internal
reflection from inside, :mod:`microsim.tracer.materials`). On a flat facet the two body terms differ by
the factor 1 / (eta^2 (1 - K_d r_i)) of the exact one (Meneveaux et al. 2015, Eq. 8-10;
:mod:`microsim.models.interfaced_lambert`): 1 at eta = 1, otherwise above 1 for white bodies
(1 / (1 - r_e) at K_d = 1) and below it for dark ones (-> 1 / eta^2), so a comparison of such
grains with a simulation measures this approximation as well. In every case the model is
reciprocal (G^dist depends on the union of the two shadows only, T and F(i.h) are symmetric)
and its albedo is <= 1.

Against explicit fields (geometry/micrograins.py, exact grains), G1^dist and V_p agree with
occlusion rays on the traced Embree scene (tests/test_micrograin_visibility.py), and order-1
tables of conductor and Lambertian grains and the base term V_p f_B agree with the model
(tests/test_micrograins.py). The uncorrelated form (``gaf = "uncorrelated"``, Eq. 17) fails
near retro at 86 deg, where it misses most of the simulated retro cell. Note for comparisons at
grazing incidence: the per-realization estimates there are skewed (light passes a few gaps
between grains), so a table's standard errors need many realizations (64 and more) before
chi^2 per cell means what it says (measurements: docs/developer/performance.md, section
'Micrograin model against explicit fields').

Eq. 21 is evaluated by fixed Gauss rules (the paper uses Monte Carlo). With the covered-area
measure D(m)(m.n) dm = p(h') dh' dphi' / (2 pi) in unit space (h' = m'.z, uniform phi'), where
p(h') = 2 lambda h' exp(-lambda (1 - h'^2)) / tau0 (the CDF of Eq. 13 written in h'), the
integrand carries p(h') / h' = 2 lambda exp(-lambda (1 - h'^2)) / tau0, which is smooth. The
height integral is cut at h' = sin(theta_i'), sin(theta_o'), where local masking and distant
shadowing start (both like (sin theta' - h')^(3/2)); each of the three panels takes
``end_graded_gauss_rule``. For each h' the azimuths where i.m > 0 and o.m > 0 (i.e. i'.m' > 0 and
o'.m' > 0) form at most two arcs, integrated in closed form for isotropic Lambertian grains and
by Gauss-Legendre otherwise (with a sinh map for elongated grains, ``_arc_integral``). The nodes
move continuously with the directions, so the model is a smooth function of them; against 4x
finer rules the relative error is 2e-4 or less (same section).

Its parameters mirror the run config of a micrograin scene: :mod:`microsim.models.micrograin_params`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from microsim.models.base import Param, register
from microsim.models.micrograin_geometry import end_graded_gauss_rule, ndf_value, shadowed_area
from microsim.models.micrograin_params import MicrograinParams
from microsim.physics.boolean_model import grain_extinction, unit_space_direction, unit_space_height
from microsim.physics.fresnel import fresnel, fresnel_conductor, fresnel_dielectric
from microsim.tracer.materials import CONDUCTOR, INTERFACED_LAMBERT, LAMBERT, MIRROR

#: Gauss-Legendre orders of Eq. 21: per height panel (three panels) and per azimuthal arc.
HEIGHT_NODES = 24
AZIMUTH_NODES = 16

#: The masking-shadowing choice of ``micrograin`` (Eq. 17-19), used in the grain terms and V_p alike.
GAF = Param("gaf", "distant GAF: direction-correlated (Eq. 18) or not (Eq. 17), also in V_p", "correlated",
            choices=("correlated", "uncorrelated"))


@numba.njit(cache=True)
def _grain_fresnel(material, cos_d, eta, k):
    """F(i.h) of the specular grain term: 1 for mirror grains, the conductor form for conductor
    grains (as the tracer's material, also for k = 0), the dielectric form for a coat."""
    if material == MIRROR:
        return 1.0
    if material == CONDUCTOR:
        return fresnel_conductor(cos_d, eta, k)
    return fresnel_dielectric(cos_d, eta)


@numba.njit(cache=True)
def _visible_half_width(dx, dy, dz, h, r):
    """Half-width of the azimuth arc where d' . m' > 0, m' the unit normal at height h (r = sqrt(1-h^2))."""
    s = math.sqrt(dx * dx + dy * dy)
    if s * r <= h * dz:
        return math.pi
    return math.acos(-h * dz / (s * r))


@numba.njit(cache=True)
def _azimuthal_terms(wi, wo, phi, ring, betas, optics):
    """(i.m)+ (o.m)+ T(i, o, m) |E m'| at unit-space normal m' = (r cos phi, r sin phi, h), with
    ``ring`` = (r, h), ``betas`` = (beta_x, beta_y) and ``optics`` = (eta, k, whether the grains
    have an interface, T = 1 - F)."""
    (r, h), (beta_x, beta_y), (eta, k, interface) = ring, betas, optics
    ex = beta_x * r * math.cos(phi)
    ey = beta_y * r * math.sin(phi)
    length = math.sqrt(ex * ex + ey * ey + h * h)
    ci = max((wi[0] * ex + wi[1] * ey + wi[2] * h) / length, 0.0)
    co = max((wo[0] * ex + wo[1] * ey + wo[2] * h) / length, 0.0)
    value = ci * co * length
    if interface:
        value *= (1.0 - fresnel(ci, eta, k)) * (1.0 - fresnel(co, eta, k))
    return value


@numba.njit(cache=True)
def _segment_integral(wi, wo, arc, sinh_map, ring, betas, optics, rule):
    """Integral over phi' in ``arc`` = [lo, hi] by the Gauss-Legendre ``rule`` (nodes, weights) in u,
    phi' = anchor + eps sinh(u), ``sinh_map`` = (anchor, eps).

    The sinh map (Johnston & Elliott 2005) resolves a near-singularity at anchor +- i eps.
    """
    (lo, hi), (anchor, eps), (px, pw) = arc, sinh_map, rule
    u_lo = math.asinh((lo - anchor) / eps)
    u_hi = math.asinh((hi - anchor) / eps)
    mid = 0.5 * (u_lo + u_hi)
    half = 0.5 * (u_hi - u_lo)
    total = 0.0
    for q in range(px.shape[0]):
        u = mid + half * px[q]
        phi = anchor + eps * math.sinh(u)
        total += pw[q] * eps * math.cosh(u) * _azimuthal_terms(wi, wo, phi, ring, betas, optics)
    return half * total


@numba.njit(cache=True)
def _arc_integral(wi, wo, arc, ring, betas, optics, rule):
    """Integral over the azimuth ``arc`` = [lo, hi] of ``_azimuthal_terms``, by the Gauss-Legendre
    ``rule`` (nodes, weights).

    For elongated grains |E m'| has complex zeros at phi_s +- i eps, phi_s the azimuths of the
    short axis (period pi) and eps^2 = (r^2 beta_min^2 + h^2) / (r^2 (beta_max^2 - beta_min^2)):
    plain Gauss-Legendre converges like exp(-2 n eps) there. The arc is then cut at the phi_s
    inside it (and half-way between two of them), and each piece uses the sinh map about its
    nearest phi_s; isotropic grains (and eps > 1) take plain Gauss-Legendre.
    """
    (lo, hi), (r, h), (beta_x, beta_y), (px, pw) = arc, ring, betas, rule
    lo_beta = min(beta_x, beta_y)
    spread = max(beta_x, beta_y) ** 2 - lo_beta**2
    eps = math.inf
    if spread > 0.0 and r > 0.0:
        eps = math.sqrt((r * r * lo_beta * lo_beta + h * h) / (r * r * spread))
    if eps > 1.0:
        mid = 0.5 * (lo + hi)
        half = 0.5 * (hi - lo)
        total = 0.0
        for q in range(px.shape[0]):
            total += pw[q] * _azimuthal_terms(wi, wo, mid + half * px[q], ring, betas, optics)
        return half * total
    phase = 0.0 if beta_x < beta_y else 0.5 * math.pi
    cuts = np.empty(12)
    singular = np.zeros(12, dtype=np.bool_)
    cuts[0] = lo
    n = 1
    s = phase + math.pi * (math.floor((lo - phase) / math.pi) + 1.0)
    while s < hi:
        if singular[n - 1]:
            cuts[n] = s - 0.5 * math.pi
            n += 1
        cuts[n] = s
        singular[n] = True
        n += 1
        s += math.pi
    cuts[n] = hi
    total = 0.0
    for j in range(n):
        c0 = cuts[j]
        c1 = cuts[j + 1]
        if singular[j]:
            anchor = c0
        elif singular[j + 1]:
            anchor = c1
        else:
            anchor = phase + math.pi * math.floor((0.5 * (c0 + c1) - phase) / math.pi + 0.5)
        total += _segment_integral(wi, wo, (c0, c1), (anchor, eps), ring, betas, optics, rule)
    return total


@numba.njit(cache=True)
def _arc_integral_isotropic(wi, wo, lo, hi, r, h, beta):
    """Closed form of ``_arc_integral`` for isotropic Lambertian grains (T = 1).

    |E m'| = sqrt(beta^2 r^2 + h^2) =: L is constant, and w . E m' = P cos(phi - alpha) + Q with
    P = beta r |w_xy|, Q = h w_z, so the integrand is a trigonometric polynomial of degree 2 / L.
    """
    alpha_i = math.atan2(wi[1], wi[0])
    alpha_o = math.atan2(wo[1], wo[0])
    pi_ = beta * r * math.sqrt(wi[0] * wi[0] + wi[1] * wi[1])
    po = beta * r * math.sqrt(wo[0] * wo[0] + wo[1] * wo[1])
    qi = h * wi[2]
    qo = h * wo[2]
    width = hi - lo
    both = 0.5 * (width * math.cos(alpha_i - alpha_o)
                  + 0.5 * (math.sin(2.0 * hi - alpha_i - alpha_o) - math.sin(2.0 * lo - alpha_i - alpha_o)))
    cos_i = math.sin(hi - alpha_i) - math.sin(lo - alpha_i)
    cos_o = math.sin(hi - alpha_o) - math.sin(lo - alpha_o)
    total = pi_ * po * both + pi_ * qo * cos_i + qi * po * cos_o + qi * qo * width
    return total / math.sqrt(beta * beta * r * r + h * h)


@numba.njit(cache=True)
def _azimuthal_integral(wi, wo, a, b, h, betas, optics, rule):
    """(1/2pi) integral over phi' of (i.m)+ (o.m)+ T(i, o, m) |E m'|, m' = (r cos, r sin, h).

    Only the azimuths where both i'.m' > 0 and o'.m' > 0 contribute: at most two arcs. Closed
    form for isotropic Lambertian grains, quadrature otherwise.
    """
    (beta_x, beta_y), interface = betas, optics[2]
    r = math.sqrt(max(1.0 - h * h, 0.0))
    half_a = _visible_half_width(a[0], a[1], a[2], h, r)
    half_b = _visible_half_width(b[0], b[1], b[2], h, r)
    centre = math.atan2(a[1], a[0])
    delta = math.atan2(b[1], b[0]) - centre
    total = 0.0
    for shift in (-2.0 * math.pi, 0.0, 2.0 * math.pi):
        lo = max(-half_a, delta + shift - half_b)
        hi = min(half_a, delta + shift + half_b)
        if hi <= lo:
            continue
        if beta_x == beta_y and not interface:
            total += _arc_integral_isotropic(wi, wo, centre + lo, centre + hi, r, h, beta_x)
        else:
            total += _arc_integral(wi, wo, (centre + lo, centre + hi), (r, h), betas, optics, rule)
    return total / (2.0 * math.pi)


@numba.njit(cache=True)
def _micrograin_kernel(wi, wo, field, surface, base_brdf, correlated, heights, azimuths):
    """f(i, o) of Eq. 20 for pairs of directions (N, 3), both above the horizon.

    ``field`` = (tau0, beta_x, beta_y); ``surface`` = (the grains' material kind code
    (:mod:`microsim.tracer.materials`), albedo, eta, k): the diffuse term for lambert and
    interfaced_lambert (with T), the specular term for all but lambert; ``heights`` and
    ``azimuths``: the Gauss rules (nodes, weights) of the diffuse term's two integrals.
    """
    (tau0, beta_x, beta_y), (material, albedo, eta, k), (hx, hw) = field, surface, heights
    betas = (beta_x, beta_y)
    diffuse_grains = (material == LAMBERT or material == INTERFACED_LAMBERT) and albedo > 0.0
    interface = material == INTERFACED_LAMBERT
    optics = (eta, k, interface)
    specular = material != LAMBERT
    lam = grain_extinction(tau0)
    rate = lam / math.pi
    out = np.empty(wi.shape[0])
    edges = np.empty(4)
    for n in range(wi.shape[0]):
        i = wi[n]
        o = wo[n]
        a = unit_space_direction(i[0], i[1], i[2], beta_x, beta_y)
        b = unit_space_direction(o[0], o[1], o[2], beta_x, beta_y)
        grains = 0.0
        if diffuse_grains:
            sa = math.sqrt(a[0] * a[0] + a[1] * a[1])
            sb = math.sqrt(b[0] * b[0] + b[1] * b[1])
            edges[0] = 0.0
            edges[1] = min(sa, sb)
            edges[2] = max(sa, sb)
            edges[3] = 1.0
            diffuse = 0.0
            for p in range(3):
                half = 0.5 * (edges[p + 1] - edges[p])
                if half <= 0.0:
                    continue
                mid = 0.5 * (edges[p + 1] + edges[p])
                for q in range(hx.shape[0]):
                    h = mid + half * hx[q]
                    density = 2.0 * lam * math.exp(-lam * (1.0 - h * h)) / tau0
                    visible = math.exp(-rate * shadowed_area(a[0], a[1], a[2], b[0], b[1], b[2], h, correlated))
                    azimuthal = _azimuthal_integral(i, o, a, b, h, betas, optics, azimuths)
                    diffuse += half * hw[q] * density * visible * azimuthal
            grains += albedo / math.pi * diffuse / i[2] / o[2]
        if specular:
            mx, my, mz = i[0] + o[0], i[1] + o[1], i[2] + o[2]
            norm = math.sqrt(mx * mx + my * my + mz * mz)
            mx, my, mz = mx / norm, my / norm, mz / norm
            hp = unit_space_height(mx, my, mz, beta_x, beta_y)
            visible = math.exp(-rate * shadowed_area(a[0], a[1], a[2], b[0], b[1], b[2], hp, correlated))
            cos_d = i[0] * mx + i[1] * my + i[2] * mz
            d = ndf_value(mx, my, mz, tau0, beta_x, beta_y)
            grains += d * visible * _grain_fresnel(material, cos_d, eta, k) / (4.0 * i[2]) / o[2]
        pores = 0.0
        if base_brdf > 0.0:
            pores = (1.0 - tau0) * math.exp(-rate * shadowed_area(a[0], a[1], a[2], b[0], b[1], b[2], 0.0, correlated))
        out[n] = tau0 * grains + pores * base_brdf
    return out


@register
class Micrograin(MicrograinParams, gaf=GAF):
    name = "micrograin"
    reference = (
        "Lucas et al. 2024 (fully-correlated anisotropic micrograin BSDF), Eq. 8-12 (NDF), "
        "16-19 and App. A-B (GAF), 20-23 and App. C (BSDF, pore visibility)"
    )

    def setup(self) -> None:
        super().setup()
        self._height_rule = end_graded_gauss_rule(HEIGHT_NODES)
        self._azimuth_rule = np.polynomial.legendre.leggauss(AZIMUTH_NODES)

    def _eval(self, wi, wo):
        eta, k = self.index
        return _micrograin_kernel(
            wi, wo, (self.tau0, self.beta_x, self.beta_y), (self.material_code, self.albedo, eta, k),
            self.base_brdf, self.gaf == "correlated", self._height_rule, self._azimuth_rule,
        )
