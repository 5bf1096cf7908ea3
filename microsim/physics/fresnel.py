"""Unpolarised Fresnel reflectance, shared by the tracer's materials and the analytic models.

Scalar kernels are numba functions (callable from other kernels); the ``*_array`` forms are
ufuncs over numpy arrays. :func:`fresnel` is the one dispatch on the complex index
``eta + i k`` that the models use: a dielectric when k = 0, a conductor otherwise.
"""

import math

import numba
import numpy as np


@numba.njit(cache=True, error_model="numpy")
def fresnel_dielectric(cos_i, eta):
    """Reflectance of a smooth dielectric interface, exact unpolarised form.

    ``cos_i`` is the cosine between the incident direction and the normal on the incident
    side (>= 0); ``eta`` = n_transmitted / n_incident. Total internal reflection gives 1.
    Form of Walter et al. 2007, Eq. 22 (also Meneveaux et al. 2015, Eq. 4).
    """
    c = min(abs(cos_i), 1.0)
    g2 = eta * eta - 1.0 + c * c
    if g2 <= 0.0:
        return 1.0
    g = math.sqrt(g2)
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return 0.5 * a * a * (1.0 + b * b)


@numba.njit(cache=True, error_model="numpy")
def fresnel_conductor(cos_i, eta, k):
    """Reflectance of a smooth conductor with complex relative index ``eta + i k``.

    Exact unpolarised form (average of s and p reflectances), as in pbrt-v3 FrConductor;
    reduces to :func:`fresnel_dielectric` for k = 0 and eta >= 1.
    """
    c = min(abs(cos_i), 1.0)
    c2 = c * c
    s2 = 1.0 - c2
    t0 = eta * eta - k * k - s2
    a2b2 = math.sqrt(t0 * t0 + 4.0 * eta * eta * k * k)
    a = math.sqrt(max(0.5 * (a2b2 + t0), 0.0))
    t1 = a2b2 + c2
    t2 = 2.0 * c * a
    t3 = c2 * a2b2 + s2 * s2
    t4 = t2 * s2
    # (rs + rp) / 2 with rs = (t1 - t2) / (t1 + t2) and rp = rs (t3 - t4) / (t3 + t4), in one
    # division; t3 > 0 (c = 0 gives s2 = 1), so rp needs no guard
    return (t1 - t2) * t3 / ((t1 + t2) * (t3 + t4))


@numba.njit(cache=True, error_model="numpy")
def fresnel(cos_i, eta, k):
    """Reflectance of a smooth interface of complex relative index ``eta + i k`` (k >= 0).

    :func:`fresnel_dielectric` when k = 0 (it covers eta < 1 and total internal reflection;
    the conductor form equals it only for eta >= 1), :func:`fresnel_conductor` otherwise.
    """
    if k == 0.0:
        return fresnel_dielectric(cos_i, eta)
    return fresnel_conductor(cos_i, eta, k)


@numba.vectorize(cache=True)
def fresnel_dielectric_array(cos_i, eta):
    """Array form of :func:`fresnel_dielectric`."""
    return fresnel_dielectric(cos_i, eta)


@numba.vectorize(cache=True)
def fresnel_conductor_array(cos_i, eta, k):
    """Array form of :func:`fresnel_conductor`."""
    return fresnel_conductor(cos_i, eta, k)


@numba.vectorize(cache=True)
def fresnel_array(cos_i, eta, k):
    """Array form of :func:`fresnel`."""
    return fresnel(cos_i, eta, k)


#: Below this eta, Eq. 10 loses its digits to cancellation (error 1e-8 at eta = 1.001,
#: 0.75 at 1 + 1e-9); the defining integral is used there instead.
MOLENAAR_MIN_ETA = 1.01


def _external_diffuse_reflectance_quadrature(eta: float) -> float:
    """r_e = integral_0^1 F(c) 2c dc, composite Gauss-Legendre on geometric segments of c.

    The segments (48 from 1e-12 to 1, 24 nodes each) resolve the grazing layer
    c < sqrt(eta^2 - 1) where F rises to 1; exact to rounding for 1 <= eta <= 10.
    """
    edges = np.concatenate([[0.0], np.geomspace(1e-12, 1.0, 48)])
    x, w = np.polynomial.legendre.leggauss(24)
    a, b = edges[:-1, None], edges[1:, None]
    c = a + 0.5 * (b - a) * (x + 1.0)
    return float(np.sum(0.5 * (b - a) * w * fresnel_dielectric_array(c, eta) * 2.0 * c))


def external_diffuse_reflectance(eta: float) -> float:
    """r_e: reflectance of the flat interface under Lambertian light from outside (Meneveaux et al. 2015, Eq. 10)."""
    n = eta
    if n < MOLENAAR_MIN_ETA:
        return _external_diffuse_reflectance_quadrature(n)
    n2, n4 = n * n, n**4
    return (
        0.5
        - 2.0 * n**3 * (n2 + 2.0 * n - 1.0) / ((n2 + 1.0) * (n4 - 1.0))
        + (n - 1.0) * (3.0 * n + 1.0) / (6.0 * (n + 1.0) ** 2)
        + 8.0 * n4 * (n4 + 1.0) / ((n2 + 1.0) * (n4 - 1.0) ** 2) * math.log(n)
        + n2 * (n2 - 1.0) ** 2 / (n2 + 1.0) ** 3 * math.log((n - 1.0) / (n + 1.0))
    )


def internal_diffuse_reflectance(eta: float) -> float:
    """r_i from n_i^2 (1 - r_i) = 1 - r_e (Meneveaux et al. 2015, Eq. 9-10)."""
    return 1.0 - (1.0 - external_diffuse_reflectance(eta)) / eta**2
