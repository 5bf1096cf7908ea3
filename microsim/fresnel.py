"""Unpolarised Fresnel reflectance, shared by the tracer's materials and the analytic models.

Scalar kernels are numba functions (callable from other kernels); the ``*_array`` forms are
ufuncs over numpy arrays. :func:`fresnel` is the one dispatch on the complex index
``eta + i k`` that the models use: a dielectric when k = 0, a conductor otherwise.
"""

import math

import numba


@numba.njit(cache=True, error_model="numpy")
def fresnel_dielectric(cos_i, eta):
    """Reflectance of a smooth dielectric interface, exact unpolarised form.

    ``cos_i`` is the cosine between the incident direction and the normal on the incident
    side (>= 0); ``eta`` = n_transmitted / n_incident. Total internal reflection gives 1.
    Form of Walter et al. 2007, Eq. 22 (also interfaced_lambertian_microfacets.txt, Eq. 4).
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


@numba.vectorize(["float64(float64, float64)"], cache=True)
def fresnel_dielectric_array(cos_i, eta):
    """Array form of :func:`fresnel_dielectric`."""
    return fresnel_dielectric(cos_i, eta)


@numba.vectorize(["float64(float64, float64, float64)"], cache=True)
def fresnel_conductor_array(cos_i, eta, k):
    """Array form of :func:`fresnel_conductor`."""
    return fresnel_conductor(cos_i, eta, k)


@numba.vectorize(["float64(float64, float64, float64)"], cache=True)
def fresnel_array(cos_i, eta, k):
    """Array form of :func:`fresnel`."""
    return fresnel(cos_i, eta, k)
