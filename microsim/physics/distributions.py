"""Microfacet normal distributions (NDFs), their masking-shadowing functions (GAFs) and sampling.

Shared by the specular ``microfacet`` model, ``interfaced_lambert`` and the V-cavity geometry
generator. Directions are float arrays (..., 3) in the macro-surface frame (n = +z); facet
normals m are unit vectors with m.z > 0. Every NDF is normalised in projected area,
integral of D(m) (m.n) d(omega_m) = 1 (Meneveaux et al. 2015, Sec. 2.1; the equation numbers
below are theirs).

Distributions (``roughness_x``, ``roughness_y`` act along the x and y axes of the surface):

- ``beckmann``: anisotropic Gaussian distribution of slopes, Eq. 15; roughness = alpha = the
  RMS slope along each axis times sqrt(2) (the paper's sigma_x, sigma_y).
- ``ggx``: anisotropic Trowbridge-Reitz, Eq. 20 (printed with sigma_x and sigma_y swapped,
  see :func:`ndf`); roughness = alpha.
- ``gaussian``: isotropic Gaussian in the facet tilt angle, Eq. 13,
  D(m) = C exp(-theta_m^2 / (2 sigma^2)) / (m.n) on theta_m < pi/2, roughness = sigma in
  radians, C from a deterministic quadrature. Small-angle equivalent Beckmann alpha =
  sqrt(2) sigma (Eq. 13 text).

Sampling: :func:`sample` maps uniform numbers (xi1, xi2) to facet normals of density
D(m)(m.n) by a smooth bijection (the models' deterministic quadratures);
:func:`sample_slope` draws the facet slope of that density in numba, one path at a time (the
V-cavity tracer, :mod:`microsim.tracer.integrators.vcavity`).

GAFs: ``smith`` (separable G1(i) G1(o), Eq. 16-18), ``smith_height_correlated``
(1 / (1 + Lambda(i) + Lambda(o)), the height-correlated Smith form of Heitz 2014) and
``torrance_sparrow`` (V-cavities, Eq. 14; the exact single scattering of explicit V-grooves,
:mod:`microsim.geometry.vcavities`). Smith's Lambda is exact for each distribution: closed forms for Beckmann (Eq. 19)
and GGX (Eq. 21), a 1D Gauss-Legendre integral for ``gaussian`` (:func:`smith_lambda`).

Accepted roughness: [ROUGHNESS_MIN, ROUGHNESS_MAX] = [1e-4, 10]. Below 1e-4 the lobe (width
~ roughness rad) is a mirror for any sensor or quadrature (peak D = 1/(pi alpha^2) > 3e7);
above 10 the Beckmann / GGX projected area sits at grazing facet angles (mean slope > 8),
and the gaussian is within 13 % of uniform in projected area from sigma = 3 on. The
normalisation and the Smith identity are tested from 0.01 to 10 (tests/test_models_microfacet.py).

The ``gaussian`` NDF of Eq. 13 keeps a non-zero projected-area density C exp(-pi^2/(8 sigma^2))
at the horizon, so its mean slope and its exact Smith Lambda diverge (logarithmically) for
every sigma > 0. While sigma <= GAUSSIAN_SMITH_MAX = 0.2 rad (exp(-pi^2/(8 sigma^2)) = 4e-14
there) the divergent tail changes Lambda by less than 3e-10 even with the logarithm cut at
the double-precision limit, so the computed Lambda is that of Eq. 13; above it no finite
Smith GAF exists and :func:`smith_lambda` and :func:`check_gaf` refuse the combination.
"""

from __future__ import annotations

import functools
import math

import numba
import numpy as np
from scipy.special import erfc

from microsim.physics.rng import uniform

DISTRIBUTIONS = ("beckmann", "ggx", "gaussian")
GAFS = ("smith", "smith_height_correlated", "torrance_sparrow")
ROUGHNESS_MIN = 1e-4
ROUGHNESS_MAX = 10.0
GAUSSIAN_SMITH_MAX = 0.2

#: Beyond GAUSSIAN_CUTOFF sigma the gaussian NDF is below exp(-72) of its peak and is dropped.
GAUSSIAN_CUTOFF = 12.0
_GL_NODES = 96
#: Nodes of the gaussian Lambda integral: G1 converged to 1e-14 against 800 nodes.
_LAMBDA_NODES = 48


def _gauss_legendre(n: int):
    """Gauss-Legendre nodes and weights on (0, 1)."""
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


def gaussian_theta_max(sigma: float) -> float:
    """Upper end of the tilt angles the gaussian NDF keeps: min(pi/2, GAUSSIAN_CUTOFF sigma)."""
    return min(0.5 * math.pi, GAUSSIAN_CUTOFF * sigma)


@functools.lru_cache(maxsize=256)
def gaussian_normalisation(sigma: float) -> float:
    """C of Eq. 13: 1/C = 2 pi integral_0^{pi/2} exp(-theta^2 / (2 sigma^2)) sin(theta) d(theta).

    Gauss-Legendre (96 nodes) on [0, theta_max], exact to rounding for this entire integrand.
    """
    t, w = _gauss_legendre(_GL_NODES)
    top = gaussian_theta_max(sigma)
    theta = top * t
    return 1.0 / (2.0 * math.pi * top * np.sum(w * np.exp(-0.5 * (theta / sigma) ** 2) * np.sin(theta)))


def ndf(distribution: str, roughness_x: float, roughness_y: float, m) -> np.ndarray:
    """D(m) in 1/sr for facet normals m (..., 3); 0 for m.z <= 0.

    Beckmann (Eq. 15): exp(-q / z^2) / (pi ax ay z^4), q = mx^2/ax^2 + my^2/ay^2.
    GGX (Eq. 20): 1 / (pi ax ay (z^2 + q)^2). Eq. 20 prints sigma_y under cos^2(phi) and
    sigma_x under sin^2(phi); that swap contradicts its own Lambda (Eq. 21, alpha_u with
    sigma_x under cos^2) and fails the Smith projected-area identity for anisotropic
    roughness (test_smith_g1_is_projected_area), so the unswapped form is used.
    Gaussian (Eq. 13): C exp(-theta^2 / (2 sigma^2)) / z.
    """
    m = np.asarray(m, dtype=np.float64)
    x, y, z = m[..., 0], m[..., 1], m[..., 2]
    up = z > 0.0
    zs = np.where(up, z, 1.0)
    if distribution == "gaussian":
        sigma = roughness_x
        theta = np.arctan2(np.hypot(x, y), zs)
        keep = up & (theta <= gaussian_theta_max(sigma))
        d = gaussian_normalisation(sigma) * np.exp(-0.5 * (theta / sigma) ** 2) / zs
        return np.where(keep, d, 0.0)
    q = (x / roughness_x) ** 2 + (y / roughness_y) ** 2
    norm = math.pi * roughness_x * roughness_y
    if distribution == "beckmann":
        d = np.exp(-q / zs**2 - 4.0 * np.log(zs)) / norm
    elif distribution == "ggx":
        d = 1.0 / (norm * (zs**2 + q) ** 2)
    else:
        raise ValueError(f"distribution = {distribution!r} is not allowed; accepted: {', '.join(DISTRIBUTIONS)}")
    return np.where(up, d, 0.0)


@numba.njit(cache=True)
def _lambda_gaussian_kernel(sin_u, cos_u, sigma, norm, top, s, ws):
    """Loop of :func:`_lambda_gaussian` over directions (nodes s, weights ws on (0, 1))."""
    out = np.zeros(sin_u.shape[0])
    for j in range(sin_u.shape[0]):
        lo = 0.5 * math.pi - math.atan2(sin_u[j], cos_u[j])
        span = top - lo
        if span <= 0.0:
            continue
        cot_u = cos_u[j] / sin_u[j]
        acc = 0.0
        for k in range(s.shape[0]):
            theta = lo + span * s[k] * s[k]
            x = min(1.0, cot_u / math.tan(theta))
            h = math.sqrt(1.0 - x * x) - x * math.acos(x)
            acc += ws[k] * 2.0 * s[k] * math.exp(-0.5 * (theta / sigma) ** 2) * math.sin(theta) * math.tan(theta) * h
        out[j] = 2.0 * norm * sin_u[j] / cos_u[j] * span * acc
    return out


def _lambda_gaussian(sigma: float, w: np.ndarray) -> np.ndarray:
    """Smith Lambda of the gaussian NDF, Lambda(u) = integral D(m) <-u.m> dm / (u.n).

    (Heitz 2014 Eq. 5 with integral D(m) (u.m) dm = u.n.) The azimuthal integral is closed:
    integral_0^2pi max(0, -a - b cos phi) dphi = 2 b h(a/b), h(x) = sqrt(1-x^2) - x arccos(x),
    a = cos(theta_u) cos(theta_m), b = sin(theta_u) sin(theta_m), which leaves
    Lambda = 2 tan(theta_u) integral_{pi/2-theta_u}^{pi/2} C e^{-theta^2/2sigma^2} sin(theta)
    tan(theta) h(cot(theta_u) cot(theta)) d(theta). Gauss-Legendre (48 nodes) after
    theta = lo + (hi - lo) s^2, which smooths the (theta - lo)^{3/2} start of h.
    """
    s, ws = _gauss_legendre(_LAMBDA_NODES)
    sin_u = np.ascontiguousarray(np.hypot(w[..., 0], w[..., 1]).reshape(-1))
    cos_u = np.ascontiguousarray(w[..., 2].reshape(-1))
    lam = _lambda_gaussian_kernel(sin_u, cos_u, sigma, gaussian_normalisation(sigma), gaussian_theta_max(sigma), s, ws)
    return lam.reshape(w.shape[:-1])


def smith_lambda(distribution: str, roughness_x: float, roughness_y: float, w) -> np.ndarray:
    """Smith's Lambda(w) for directions w (..., 3) with w.z > 0; G1 = 1 / (1 + Lambda).

    With a = 1 / (alpha_w tan(theta_w)), alpha_w^2 = ax^2 cos^2(phi_w) + ay^2 sin^2(phi_w):
    Beckmann, Eq. 19: (erf(a) - 1)/2 + exp(-a^2) / (2 a sqrt(pi)); GGX, Eq. 21:
    (-1 + sqrt(1 + 1/a^2)) / 2, evaluated as t / (2 (1 + sqrt(1 + t))), t = 1/a^2.
    """
    w = np.asarray(w, dtype=np.float64)
    if distribution == "gaussian":
        if roughness_x > GAUSSIAN_SMITH_MAX:
            raise ValueError(f"the Smith Lambda of the gaussian NDF diverges for sigma > {GAUSSIAN_SMITH_MAX:g} (got {roughness_x!r})")
        return _lambda_gaussian(roughness_x, w)
    z = w[..., 2]
    slope2 = (roughness_x * w[..., 0]) ** 2 + (roughness_y * w[..., 1]) ** 2
    if distribution == "ggx":
        t = slope2 / z**2
        return t / (2.0 * (1.0 + np.sqrt(1.0 + t)))
    if distribution == "beckmann":
        with np.errstate(divide="ignore"):
            a = z / np.sqrt(slope2)
        safe = np.where(np.isfinite(a), a, 1.0)
        lam = 0.5 * (np.exp(-safe * safe) / (safe * math.sqrt(math.pi)) - erfc(safe))
        return np.where(np.isfinite(a), np.maximum(lam, 0.0), 0.0)
    raise ValueError(f"distribution = {distribution!r} is not allowed; accepted: {', '.join(DISTRIBUTIONS)}")


def smith_g1(distribution: str, roughness_x: float, roughness_y: float, w) -> np.ndarray:
    """Smith masking G1(w) = 1 / (1 + Lambda(w)) (Eq. 18), without the facet indicator."""
    return 1.0 / (1.0 + smith_lambda(distribution, roughness_x, roughness_y, w))


@numba.njit(cache=True)
def gaf_value(gaf_code, lambda_i, lambda_o, wi_z, wo_z, m_z, wi_m, wo_m):
    """G(i, o, m) for one facet, from precomputed Smith Lambdas and cosines.

    ``gaf_code`` indexes GAFS. 0 when a direction sees the back of the facet (Eq. 17).
    Smith: G1(i) G1(o) (Eq. 16); height-correlated: 1 / (1 + Lambda_i + Lambda_o);
    Torrance-Sparrow (Eq. 14): min(1, 2 (n.m)(n.i) / (i.m), 2 (n.m)(n.o) / (o.m)).
    """
    if wi_m <= 0.0 or wo_m <= 0.0:
        return 0.0
    if gaf_code == 0:
        return 1.0 / ((1.0 + lambda_i) * (1.0 + lambda_o))
    if gaf_code == 1:
        return 1.0 / (1.0 + lambda_i + lambda_o)
    return min(1.0, 2.0 * m_z * wi_z / wi_m, 2.0 * m_z * wo_z / wo_m)


@numba.vectorize(cache=True)
def gaf_array(gaf_code, lambda_i, lambda_o, wi_z, wo_z, m_z, wi_m, wo_m):
    """Array form of :func:`gaf_value`."""
    return gaf_value(gaf_code, lambda_i, lambda_o, wi_z, wo_z, m_z, wi_m, wo_m)


def masking_shadowing(gaf: str, distribution: str, roughness_x: float, roughness_y: float, wi, wo, m) -> np.ndarray:
    """G(wi, wo, m) of ``gaf`` for facet normals m; all arguments (..., 3), broadcasting."""
    wi, wo, m = (np.asarray(a, dtype=np.float64) for a in (wi, wo, m))
    code = GAFS.index(gaf)
    if code == 2:
        lam_i = lam_o = 0.0
    else:  # each Lambda on its own directions; the ufunc broadcasts
        lam_i = smith_lambda(distribution, roughness_x, roughness_y, wi)
        lam_o = smith_lambda(distribution, roughness_x, roughness_y, wo)
    wi_m = np.sum(wi * m, axis=-1)
    wo_m = np.sum(wo * m, axis=-1)
    return gaf_array(code, lam_i, lam_o, wi[..., 2], wo[..., 2], m[..., 2], wi_m, wo_m)


@numba.njit(cache=True)
def _gaussian_theta_kernel(xi, sigma, norm, top, t, w):
    """Tilt angles with P(theta_m < theta) = xi under D(m)(m.n): Newton safeguarded by bisection.

    The CDF 2 pi C integral_0^theta exp(-t^2 / (2 sigma^2)) sin(t) dt by Gauss-Legendre on
    [0, theta]; stops at a step below 1e-13 sigma or a CDF residual below 4e-16.
    """
    out = np.empty(xi.shape[0])
    for j in range(xi.shape[0]):
        lo, hi = 0.0, top
        theta = min(top, sigma * math.sqrt(-2.0 * math.log1p(-min(xi[j], 1.0 - 1e-16))))
        for _ in range(200):
            acc = 0.0
            for k in range(t.shape[0]):
                node = theta * t[k]
                acc += w[k] * math.exp(-0.5 * (node / sigma) ** 2) * math.sin(node)
            g = norm * theta * acc - xi[j]
            if g < 0.0:
                lo = theta
            elif g > 0.0:
                hi = theta
            pdf = norm * math.exp(-0.5 * (theta / sigma) ** 2) * math.sin(theta)
            step = theta - g / pdf if pdf > 0.0 else -1.0
            new = step if lo <= step <= hi else 0.5 * (lo + hi)
            done = abs(new - theta) <= 1e-13 * sigma or abs(g) <= 4e-16
            theta = new
            if done:
                break
        out[j] = theta
    return out


def _gaussian_theta(sigma: float, xi: np.ndarray) -> np.ndarray:
    """Invert the gaussian tilt CDF (see :func:`_gaussian_theta_kernel`)."""
    t, w = _gauss_legendre(_GL_NODES)
    flat = np.ascontiguousarray(xi, dtype=np.float64).reshape(-1)
    theta = _gaussian_theta_kernel(flat, sigma, 2.0 * math.pi * gaussian_normalisation(sigma), gaussian_theta_max(sigma), t, w)
    return theta.reshape(np.shape(xi))


def sample(distribution: str, roughness_x: float, roughness_y: float, xi1, xi2) -> np.ndarray:
    """Facet normals m (..., 3) with density D(m)(m.n) from uniform numbers xi1, xi2 in [0, 1).

    Azimuth (Eq. 29, with the quadrant kept): phi = atan2(ay sin(2 pi xi2), ax cos(2 pi xi2)).
    Tilt: Beckmann (Eq. 30) tan^2 = -log(1 - xi1) / (cos^2 phi / ax^2 + sin^2 phi / ay^2);
    GGX (Eq. 31) tan^2 = xi1 / (1 - xi1) / (same); gaussian: numerical inverse of its CDF.
    A smooth bijection of the unit square, so fixed Gauss rules in (xi1, xi2) are
    deterministic quadratures of integral g(m) D(m)(m.n) dm.
    """
    xi1 = np.asarray(xi1, dtype=np.float64)
    xi2 = np.asarray(xi2, dtype=np.float64)
    if distribution == "gaussian":  # the tilt depends on xi1 alone: taken on its own values
        theta = _gaussian_theta(roughness_x, xi1)
    xi1, xi2 = np.broadcast_arrays(xi1, xi2)
    psi = 2.0 * math.pi * xi2
    phi = np.arctan2(roughness_y * np.sin(psi), roughness_x * np.cos(psi))
    if distribution == "gaussian":
        sin_t, cos_t = (np.broadcast_to(f(theta), xi1.shape) for f in (np.sin, np.cos))
    else:
        inv_a2 = (np.cos(phi) / roughness_x) ** 2 + (np.sin(phi) / roughness_y) ** 2
        if distribution == "beckmann":
            s2 = -np.log1p(-xi1)
        elif distribution == "ggx":
            s2 = xi1 / (1.0 - xi1)
        else:
            raise ValueError(f"distribution = {distribution!r} is not allowed; accepted: {', '.join(DISTRIBUTIONS)}")
        tan_t = np.sqrt(s2 / inv_a2)
        cos_t = 1.0 / np.sqrt(1.0 + tan_t**2)
        sin_t = tan_t * cos_t
    return np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=-1)


#: codes of DISTRIBUTIONS in numba kernels
BECKMANN, GGX, GAUSSIAN = range(3)


@numba.njit(cache=True, error_model="numpy", inline="always")
def sample_slope(code, roughness_x, roughness_y, states, i):
    """The slope (sx, sy) of a facet of normal m = (sx, sy, 1) / |(sx, sy, 1)| drawn with density
    D(m)(m.n), from path i's random stream. Exact for each distribution:

    - Beckmann, GGX: the map of :func:`sample` written on slopes. With psi = 2 pi xi2 the slope
      is s (ax cos psi, ay sin psi), s^2 = -log(1 - xi1) (Beckmann: Gaussian slopes of variance
      a^2 / 2 per axis) or xi1 / (1 - xi1) (GGX).
    - gaussian (Eq. 13; density C exp(-theta^2 / (2 sigma^2)) sin(theta) in theta on
      [0, top = ``gaussian_theta_max``], uniform in azimuth), by rejection from whichever of two
      proposals accepts more: the Rayleigh density theta / sigma^2 exp(-theta^2 / (2 sigma^2)),
      accepted with probability sin(theta) / theta, or sin(theta) / (1 - cos(top)) (uniform in
      cos theta), accepted with probability exp(-theta^2 / (2 sigma^2)). Both accept the
      integral I of exp(-theta^2 / (2 sigma^2)) sin(theta) over [0, top], divided by sigma^2 and
      by 1 - cos(top) respectively: Rayleigh while sigma^2 < 1 - cos(top), about sigma < 1
      (acceptance 0.997 at sigma = 0.1, 0.74 at 0.8, 0.60 at 1; then 0.69 at 1.2, 0.994 at 10).
    """
    if code == GAUSSIAN:
        sigma = roughness_x
        top = min(0.5 * math.pi, GAUSSIAN_CUTOFF * sigma)
        rayleigh = sigma * sigma < 1.0 - math.cos(top)
        while True:
            if rayleigh:
                theta = sigma * math.sqrt(-2.0 * math.log1p(-uniform(states, i)))
                if theta <= top and (theta == 0.0 or uniform(states, i) * theta <= math.sin(theta)):
                    break
            else:
                theta = math.acos(1.0 - uniform(states, i) * (1.0 - math.cos(top)))
                if uniform(states, i) <= math.exp(-0.5 * (theta / sigma) ** 2):
                    break
        psi = 2.0 * math.pi * uniform(states, i)
        slope = math.tan(theta)
        return slope * math.cos(psi), slope * math.sin(psi)
    xi1 = uniform(states, i)
    psi = 2.0 * math.pi * uniform(states, i)
    s = math.sqrt(-math.log1p(-xi1) if code == BECKMANN else xi1 / (1.0 - xi1))
    return s * roughness_x * math.cos(psi), s * roughness_y * math.sin(psi)


def resolve_roughness(values: dict, allow_zero: bool = False) -> dict:
    """Fill ``roughness_x``, ``roughness_y`` from the alias ``roughness`` (or check the pair).

    Giving ``roughness`` together with either axis, or only one axis, is a ValueError naming
    the keys. With ``allow_zero`` a roughness of 0 (flat) is accepted, on both axes at once.
    """
    out = dict(values)
    has_alias = "roughness" in out
    axes = [k for k in ("roughness_x", "roughness_y") if k in out]
    if has_alias and axes:
        raise ValueError(f"give either roughness or roughness_x + roughness_y, not both (got roughness and {', '.join(axes)})")
    if len(axes) == 1:
        raise ValueError(f"{axes[0]} needs its partner: give roughness_x and roughness_y together, or roughness")
    if has_alias:
        out["roughness_x"] = out["roughness_y"] = out["roughness"]
    elif axes:
        out["roughness"] = out["roughness_x"] if out["roughness_x"] == out["roughness_y"] else None
    else:
        return out
    ax, ay = out["roughness_x"], out["roughness_y"]
    if allow_zero and ax == 0.0 and ay == 0.0:
        return out
    for key, v in (("roughness_x", ax), ("roughness_y", ay)):
        if v < ROUGHNESS_MIN:
            zero = "0 (flat, on both axes) or " if allow_zero else ""
            raise ValueError(f"{key} = {v!r} is outside {zero}[{ROUGHNESS_MIN:g}, {ROUGHNESS_MAX:g}]")
    return out


def check_gaf(distribution: str, gaf: str, roughness_x: float, roughness_y: float) -> None:
    """ValueError for the combinations without a defined GAF (see the module docstring)."""
    if distribution != "gaussian":
        return
    if roughness_x != roughness_y:
        raise ValueError(
            "distribution = 'gaussian' is isotropic: give roughness (or roughness_x = roughness_y), "
            f"got roughness_x = {roughness_x!r}, roughness_y = {roughness_y!r}"
        )
    if gaf != "torrance_sparrow" and roughness_x > GAUSSIAN_SMITH_MAX:
        raise ValueError(
            f"distribution = 'gaussian' with gaf = {gaf!r} needs roughness <= {GAUSSIAN_SMITH_MAX:g} rad "
            f"(got {roughness_x!r}): the Smith Lambda of Eq. 13 diverges above it; use gaf = 'torrance_sparrow'"
        )
