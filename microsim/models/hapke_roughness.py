"""Hapke's macroscopic roughness: the effective cosines and the shadowing function S.

Hapke 1984 (Icarus 59, 41), Eqs. 46-51, as Hapke 2012 (Theory of Reflectance and Emittance
Spectroscopy, 2nd ed.) restates them in Ch. 12: a surface of facets tilted by a mean slope
angle theta_bar (the mean of |tan| over the Gaussian-like slope distribution), lit at i and
seen at e with azimuth difference psi in [0, pi] (psi = 0: the viewer on the source's side).

    chi = 1 / sqrt(1 + pi tan^2 theta_bar)
    E1(x) = exp(-(2/pi) cot theta_bar cot x),   E2(x) = exp(-(1/pi) cot^2 theta_bar cot^2 x)
    eta(x) = chi [cos x + sin x tan theta_bar E2(x) / (2 - E1(x))]

for i <= e

    mu0e = chi [cos i + sin i tan theta_bar (cos psi E2(e) + sin^2(psi/2) E2(i)) / (2 - E1(e) - (psi/pi) E1(i))]
    mue  = chi [cos e + sin e tan theta_bar (E2(e) - sin^2(psi/2) E2(i)) / (2 - E1(e) - (psi/pi) E1(i))]
    S    = mue / eta(e) mu0 / eta(i) chi / (1 - f(psi) + f(psi) chi mu0 / eta(i)),   f(psi) = exp(-2 tan(psi/2))

and for e <= i the same with the roles of i and e (and of mu0e, mue) exchanged, the last factor's
mu0 / eta(i) becoming mu / eta(e). The BRDF takes r(mu0e, mue) S / mu0, which is reciprocal:
the exchange of i and e exchanges mu0e and mue, and S / mu0 is symmetric (tests hold it).
"""

from __future__ import annotations

import math

import numpy as np


def azimuth_difference(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """psi in [0, pi] between the azimuths of directions (n, 3) ``wi`` and ``wo`` (0: the same side)."""
    return np.abs(np.angle(np.exp(1j * (np.arctan2(wo[:, 1], wo[:, 0]) - np.arctan2(wi[:, 1], wi[:, 0])))))


def roughness_cosines(cos_i, cos_e, psi, theta_bar: float):
    """(mu0e, mue, S) of directions of cosines ``cos_i``, ``cos_e`` (> 0) and azimuth difference
    ``psi`` in [0, pi], for a mean slope angle ``theta_bar`` in (0, pi/2) radians."""
    tan_t = math.tan(theta_bar)
    cot_t = 1.0 / tan_t
    chi = 1.0 / math.sqrt(1.0 + math.pi * tan_t * tan_t)
    sin_i, sin_e = np.sqrt(1.0 - cos_i * cos_i), np.sqrt(1.0 - cos_e * cos_e)
    with np.errstate(divide="ignore"):  # cot 0 = inf: E1 = E2 = 0 at normal incidence or view
        cot_i, cot_e = cos_i / sin_i, cos_e / sin_e
    e1_i, e1_e = np.exp(-2.0 / math.pi * cot_t * cot_i), np.exp(-2.0 / math.pi * cot_t * cot_e)
    e2_i, e2_e = np.exp(-cot_t * cot_t * cot_i * cot_i / math.pi), np.exp(-cot_t * cot_t * cot_e * cot_e / math.pi)
    eta_i = chi * (cos_i + sin_i * tan_t * e2_i / (2.0 - e1_i))
    eta_e = chi * (cos_e + sin_e * tan_t * e2_e / (2.0 - e1_e))
    half = np.sin(psi / 2.0) ** 2
    with np.errstate(over="ignore"):  # tan(pi/2) ~ 1.6e16: f = 0 in the forward plane
        f = np.exp(-2.0 * np.tan(psi / 2.0))
    lit_first = cos_i >= cos_e  # i <= e
    # i <= e
    d1 = 2.0 - e1_e - psi / math.pi * e1_i
    mu0e_1 = chi * (cos_i + sin_i * tan_t * (np.cos(psi) * e2_e + half * e2_i) / d1)
    mue_1 = chi * (cos_e + sin_e * tan_t * (e2_e - half * e2_i) / d1)
    # e <= i
    d2 = 2.0 - e1_i - psi / math.pi * e1_e
    mu0e_2 = chi * (cos_i + sin_i * tan_t * (e2_i - half * e2_e) / d2)
    mue_2 = chi * (cos_e + sin_e * tan_t * (np.cos(psi) * e2_i + half * e2_e) / d2)
    mu0e = np.where(lit_first, mu0e_1, mu0e_2)
    mue = np.where(lit_first, mue_1, mue_2)
    lit = np.where(lit_first, cos_i / eta_i, cos_e / eta_e)
    s = mue / eta_e * cos_i / eta_i * chi / (1.0 - f + f * chi * lit)
    return mu0e, mue, s
