"""The equilibrium hard-sphere fluid in the Percus-Yevick approximation: the pair correlation g(r)
that the packings' measured structure is judged against.

Wertheim 1963 and Thiele 1963 solved the Ornstein-Zernike equation with the Percus-Yevick
closure for hard spheres of diameter sigma at packing fraction eta in closed form: the direct
correlation function is, for x = r / sigma < 1,

    c(x) = -(1 + 2 eta)^2 / (1 - eta)^4 + 6 eta (1 + eta / 2)^2 / (1 - eta)^4 x
           - eta (1 + 2 eta)^2 / (2 (1 - eta)^4) x^3,

and 0 beyond contact. With its Fourier transform C(k), number density rho = 6 eta / (pi sigma^3)
and the Ornstein-Zernike relation, the indirect correlation gamma = h - c has the transform
rho C^2 / (1 - rho C), which falls as k^-4 (gamma is continuous at contact, where h jumps), and
outside the core, where c = 0, g(r) = 1 + gamma(r):

    gamma(r) = 1 / (2 pi^2 r) int_0^inf k sin(k r) rho C(k)^2 / (1 - rho C(k)) dk.

:func:`percus_yevick_g` evaluates it by quadrature (C by Gauss-Legendre over the core, the k
integral by the trapezoidal rule to k sigma = ``K_MAX``); its contact value is the closed form
g(sigma+) = (1 + eta / 2) / (1 - eta)^2 to 1e-4 (tests).
"""

from __future__ import annotations

import math

import numpy as np

#: the k integral's step and end, in units of 1 / sigma
K_STEP, K_MAX = 0.02, 600.0
#: C(k) in closed form from this k sigma (below it by quadrature, exact for its smooth integrand)
CLOSED_FROM = 4.0


def direct_correlation(x, eta: float):
    """c(x) of the Percus-Yevick hard-sphere fluid at x = r / sigma (module doc)."""
    x = np.asarray(x, np.float64)
    d = (1.0 - eta) ** 4
    inside = (-(1.0 + 2.0 * eta) ** 2 / d + 6.0 * eta * (1.0 + 0.5 * eta) ** 2 / d * x
              - 0.5 * eta * (1.0 + 2.0 * eta) ** 2 / d * x**3)
    return np.where(x < 1.0, inside, 0.0)


def direct_correlation_transform(k, eta: float, nodes: int = 64):
    """C(k) = 4 pi int_0^1 c(x) x^2 sin(k x) / (k x) dx (sigma = 1): Gauss-Legendre below
    ``CLOSED_FROM`` (where the closed forms cancel), the integrals of x^n sin(k x) in closed form above."""
    k = np.asarray(k, np.float64)
    d = (1.0 - eta) ** 4
    c0, c1, c3 = -(1.0 + 2.0 * eta) ** 2 / d, 6.0 * eta * (1.0 + 0.5 * eta) ** 2 / d, -0.5 * eta * (1.0 + 2.0 * eta) ** 2 / d
    out = np.empty_like(k)
    small = k < CLOSED_FROM
    t, w = np.polynomial.legendre.leggauss(nodes)
    x, w = 0.5 * (t + 1.0), 0.5 * w
    out[small] = 4.0 * math.pi * np.sum(w * direct_correlation(x, eta) * x * x * np.sinc(np.outer(k[small], x) / math.pi),
                                        axis=1)
    q = k[~small]
    s, c = np.sin(q), np.cos(q)
    i1 = (s - q * c) / q**2
    i2 = (2.0 * q * s - (q * q - 2.0) * c - 2.0) / q**3
    i4 = ((4.0 * q**3 - 24.0 * q) * s - (q**4 - 12.0 * q * q + 24.0) * c + 24.0) / q**5
    out[~small] = 4.0 * math.pi / q * (c0 * i1 + c1 * i2 + c3 * i4)
    return out


def contact_value(eta: float) -> float:
    """g(sigma+) = (1 + eta / 2) / (1 - eta)^2, Percus-Yevick's contact value."""
    return (1.0 + 0.5 * eta) / (1.0 - eta) ** 2


def percus_yevick_g(r, eta: float, sigma: float = 1.0) -> np.ndarray:
    """g(r) of hard spheres of diameter ``sigma`` at packing fraction ``eta`` < 1: 0 inside the
    core, 1 + gamma(r) outside (module doc)."""
    r = np.asarray(r, np.float64) / sigma
    k = np.arange(K_STEP, K_MAX, K_STEP)
    c = direct_correlation_transform(k, eta)
    rho = 6.0 * eta / math.pi
    gamma_k = rho * c * c / (1.0 - rho * c)
    outside = r >= 1.0
    gamma = np.zeros_like(r)
    x = r[outside]
    weight = np.full(k.size, K_STEP)
    weight[-1] *= 0.5
    gamma[outside] = (np.sin(np.outer(x, k)) @ (weight * k * gamma_k)) / (2.0 * math.pi**2 * x)
    return np.where(outside, 1.0 + gamma, 0.0)
