"""Phase functions: the registry of those a medium can scatter with, and the Lambert sphere's.

``mu`` is the cosine of the scattering angle between the propagation directions before and after
scattering, so mu = -1 is backscatter. ``PHASES`` names each phase function once: its code (what
the medium's kernel branches on, :func:`sample_cosine`), p(mu) in 1/sr, and how it is sampled
(recorded in a table's ``scene/phase_sampling``). The config's ``[scene] phase``, the medium
tracer and the models read it from here.

The Lambert sphere's (d'Eon 2021, Eqs. 1-6) peaks at backscatter (mean cosine
g = -4/9). Its samplers are numba ufuncs: they take arrays from Python and scalars inside
``@numba.njit`` kernels (the volumetric reference tracer calls them there).
"""

import math
from typing import Callable, NamedTuple

import numba
import numpy as np

from microsim.physics.rng import uniform


@numba.vectorize(["float64(float64)"], cache=True)
def phase_lambert_sphere(mu):
    """p(mu) = 2 (sqrt(1 - mu^2) - mu acos(mu)) / (3 pi^2), Eq. 1, in 1/sr (integrates to 1 over the sphere)."""
    m = min(max(mu, -1.0), 1.0)
    return 2.0 * (math.sqrt(1.0 - m * m) - m * math.acos(m)) / (3.0 * math.pi * math.pi)


@numba.vectorize(cache=True)
def phase_lambert_sphere_cdf(mu):
    """P(cosine <= mu) = 2 pi int_-1^mu p, from the antiderivative of Eq. 1."""
    m = min(max(mu, -1.0), 1.0)
    s = math.sqrt(1.0 - m * m)
    g = 0.75 * m * s + 0.25 * math.asin(m) - 0.5 * m * m * math.acos(m)
    return 4.0 / (3.0 * math.pi) * (g + 0.625 * math.pi)


def legendre_coefficients(n: int) -> np.ndarray:
    """A_0..A_n of Eq. 2 by numerical projection, Eq. 3: A_k = 2 pi (2k+1) int p P_k dmu.

    Integrated in theta (mu = cos theta), where p(cos theta) = 2 (sin t - t cos t) / (3 pi^2) is
    analytic, so Gauss-Legendre converges geometrically (the integrand in mu has sqrt singularities).
    """
    x, w = np.polynomial.legendre.leggauss(64 + n)
    theta = 0.5 * math.pi * (x + 1.0)
    mu = np.cos(theta)
    weight = 0.5 * math.pi * w * np.sin(theta) * phase_lambert_sphere(mu)
    return np.array([2.0 * math.pi * (2 * k + 1) * np.sum(weight * np.polynomial.legendre.Legendre.basis(k)(mu)) for k in range(n + 1)])


@numba.vectorize(["float64(float64, float64, float64)"], cache=True)
def sample_phase_exact(xi1, xi2, xi3):
    """Scattering cosine distributed exactly as Eq. 1, from three uniforms in [0, 1), Eq. 5."""
    return math.sqrt((1.0 - xi1) * (1.0 - xi2)) * math.sin(2.0 * math.pi * xi3) - math.sqrt(xi1 * xi2)


@numba.vectorize(cache=True)
def sample_phase_approx(xi):
    """Scattering cosine from one uniform in [0, 1) by the approximate inverse CDF, Eq. 6 (|error| < 5e-4)."""
    return 1.0 - 2.0 * (1.0 - xi ** (0.0401885 * xi + 1.01938)) ** 0.397225


def phase_isotropic(mu):
    """p(mu) = 1 / (4 pi)."""
    return np.full(np.shape(mu), 0.25 / math.pi)


class Phase(NamedTuple):
    """A phase function: its name, its kernel code, p(mu) in 1/sr, and how kernels sample mu."""

    name: str
    code: int
    p: Callable
    sampling: str


#: kernel codes (numba reads module globals)
ISOTROPIC, LAMBERT_SPHERE = 0, 1
PHASES = {phase.name: phase for phase in (
    Phase("isotropic", ISOTROPIC, phase_isotropic, "exact: mu = 1 - 2 xi"),
    Phase("lambert_sphere", LAMBERT_SPHERE, phase_lambert_sphere, "exact: d'Eon 2021, Eq. 5 (three uniforms)"),
)}


@numba.njit(cache=True, error_model="numpy", inline="always")
def sample_cosine(code, states, i):
    """mu drawn exactly from the phase function of kernel code ``code`` (:data:`PHASES`), from
    the random stream of path i."""
    if code == LAMBERT_SPHERE:
        return sample_phase_exact(uniform(states, i), uniform(states, i), uniform(states, i))
    return 1.0 - 2.0 * uniform(states, i)


@numba.njit(cache=True, error_model="numpy", inline="always")
def phase_value(code, mu):
    """p(mu) in 1/sr of the phase function of kernel code ``code`` (:data:`PHASES`)."""
    if code == LAMBERT_SPHERE:
        return phase_lambert_sphere(mu)
    return 0.25 / math.pi
