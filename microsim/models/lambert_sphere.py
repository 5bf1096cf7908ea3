"""BRDF of a half space of Lambertian spheres (d'Eon 2021): accurate form and fast variant.

Paper: d'Eon 2021 (Lambert-sphere BRDF; docs/reference/papers.md), whose equation numbers are
cited below. Accurate form, Eqs. 9-12 and 21:
``f = f1 + f_m^(0) + f_m^(1) cos(phi)`` where f1 is the exact single scattering with the exact
phase function (Eq. 10, p(-wi.wo), Eq. 1; :mod:`microsim.models.radiative_transfer`) and
``f_m^(k) = f^(k) - f_1,3^(k)``: the Horak-Chandrasekhar Fourier modes of the three-term half
space (f^(0) Eq. 30, f^(1) Eq. 22) minus the single scattering of the three-term phase function
(Eqs. 38, 28); f_m^(2) = 0 (Eq. 21).

Azimuth: phi = phi_o - phi_i with phi = 0 the backscatter half plane (docs/conventions.md §1). The
paper uses the same: its f^(1) (> 0) multiplies cos(phi), and the first mode of the single scattering of
this backward phase function is positive on the backscatter side. In code ``S cos(phi)`` is
``wi_x wo_x + wi_y wo_y``, with S = sqrt((1 - mu_i^2)(1 - mu_o^2)) (Eq. 28 prints it as
sqrt((mu_i^2 - 1)(mu_o^2 - 1)), the same positive number).

Corrections to the printed formulas (each checked in tests/test_models_lambert_sphere.py):

* Eq. 22 prints the prefactor c / (6 pi), Eq. 28 the denominator 384 pi; both are too small by 2.
  c / (3 pi) and 192 pi are used: the cos(phi) Fourier coefficient of the three-term single
  scattering c p3(-wi.wo) / (mu_i + mu_o), projected numerically, is
  c (64 + 45 mu_i mu_o) S / (192 pi (mu_i + mu_o)), and a discrete-ordinate solution of the
  transfer equation agrees with the 3 pi form of f^(1) for all c.
* Eqs. 23-24 print ``H1(mu) ~ H1(1) H1_{c=1}(mu)`` with
  ``H1_{c=1}(mu) = exp(-0.0894878 mu^e(mu))``, which is 0.914 (not 1) at mu = 1 and is 8-11 %
  off the numerical H^(1). Read as a separable fit of ln H instead,
  ``H1(mu) ~ H1(1)^(mu^e(mu))`` (= H1(1)^(ln H1_{c=1}(mu) / ln H1_{c=1}(1))), it is within
  0.36 % of the numerical H^(1) for mu, c in [0, 1] (paper: 0.5 %): that form is used.

``method="exact"`` replaces every fit (H0 Eqs. 31-32, H1 Eqs. 23-25, l and m Eqs. 26-27, B-F
Eqs. 34-37) by its numerical counterpart (``hfunctions``); the structure (Eqs. 11, 12, 21) is
unchanged, so "fit" minus "exact" is the error of the fits alone.
"""

from __future__ import annotations

import math

import numpy as np

from microsim.models import hfunctions
from microsim.models.base import BRDFModel, Param, register
from microsim.models.radiative_transfer import single_scattering


def albedo_from_kd(kd):
    """Particle albedo c from the diffuse colour k_d, Eq. 39 (clipped to [0, 1]: Eq. 39 gives -0.005 at k_d = 0)."""
    t = 1.0 - np.asarray(kd, dtype=np.float64)
    return np.clip((1.0 - 1.00425 * t**2.67103) / (1.0 - 0.219924 * t**2.44559), 0.0, 1.0)


def kd_from_albedo(c):
    """Diffuse colour k_d (spherical albedo of the material) from the particle albedo c, Eq. 40."""
    s = np.sqrt(1.0 - np.asarray(c, dtype=np.float64))
    return (-0.453029 * s * s - 0.544162 * s + 1.0) / (1.42931 * s + 1.0)


def _log_h0_fit(mu, c):
    s = math.sqrt(1.0 - c)
    a = (1.50112 * s**6.05435 + 8.21644) / (4.17593 - 1.21222 * s)
    d = (7.7731 - 0.565811 * s**0.961546) / (8.65912 - 0.159974 * s**7)
    x = a * np.asarray(mu, dtype=np.float64) ** d
    return np.log1p(x) - np.log1p(x * math.sqrt(hfunctions.k_at_zero(0, c)))


def h0_fit(mu, c):
    """H^(0)(mu) ~ (1 + a mu^d) / (1 + a mu^d / H0(inf)), Eqs. 31-32."""
    return np.exp(_log_h0_fit(mu, c))


def _log_h1_fit(mu, c):
    mu = np.asarray(mu, dtype=np.float64)
    shape = -1.12831 * mu**3 + 1.85728 * mu**2 - 1.07879 * mu + 0.459442
    return (0.0242851 * c * c - 0.144839 * c) * mu**shape


def h1_fit(mu, c):
    """H^(1)(mu) ~ H1(1)^(mu^e(mu)), Eqs. 23-25 in the corrected (log-separable) reading, see module notes."""
    return np.exp(_log_h1_fit(mu, c))


def first_mode_constants_fit(c):
    """(l, m) of Eq. 22 by the fits Eqs. 26-27."""
    return -0.00473696 * c * c - 0.0589037 * c, 0.44038 * c + 1.0


def zeroth_mode_constants_fit(c) -> dict:
    """A-F of Eq. 30: A, E exact (Eq. 33), B, C, D, F by the fits Eqs. 34-37."""
    s = math.sqrt(1.0 - c)
    return dict(
        A=69.0 * c / 128.0,
        B=(0.346689 * s**3 - 0.777574 * s**2 + 0.515357 * s - 0.084463) / (0.182602 * s**2 - 0.665502 * s + 0.964893),
        C=(-5602.45 * s**3 + 7487.99 * s**2 - 2567.74 * s + 682.848) / (1480.25 * s**2 - 4008.33 * s + 5850.6),
        D=(166.883 * s**3 - 327.428 * s**2 + 160.397 * s + 0.285529) / (596.423 * s**2 - 412.984 * s + 674.191),
        E=15.0 / 128.0 * (1.0 - c) * c * (4.0 * c / 3.0 + 3.0),
        F=(266.063 * s**3 - 21.9141 * s**2 - 242.16 * s - 1.9209) / (215.773 * s**2 + 457.42 * s + 1499.9),
    )


def zeroth_mode_multiple(mu_i, mu_o, c, log_h_i, log_h_o, k: dict):
    """f_m^(0) = f^(0) (Eq. 30) - f_1,3^(0) (Eq. 38), written without the cancelling constant term A.

    ``log_h_*`` are ln H^(0) at mu_i, mu_o; ``k`` holds A-F.
    """
    hh = np.exp(log_h_i + log_h_o)
    sigma, prod = mu_i + mu_o, mu_i * mu_o
    rest = k["B"] * sigma + k["C"] * prod + k["D"] * prod * sigma + k["E"] * prod**2 + k["F"] * (mu_i**2 + mu_o**2)
    single = c * (256.0 * prod + 135.0 * prod**2 - 45.0 * (mu_i**2 + mu_o**2)) / 384.0
    return (k["A"] * np.expm1(log_h_i + log_h_o) + hh * rest - single) / (2.0 * math.pi * sigma)


def first_mode_multiple(mu_i, mu_o, c, log_h_i, log_h_o, l, m):
    """f_m^(1) / S = [f^(1) (Eq. 22, prefactor c/(3 pi)) - f_1,3^(1) (Eq. 28, 192 pi)] / S."""
    sigma, prod = mu_i + mu_o, mu_i * mu_o
    k = l * l + 45.0 * m / 64.0
    bracket = np.expm1(log_h_i + log_h_o) * (1.0 + k * prod + l * sigma) + l * sigma + (k - 45.0 / 64.0) * prod
    return c * bracket / (3.0 * math.pi * sigma)


def three_term_modes(mu_i, mu_o, c):
    """Exact f^(0), f^(1), f^(2) of the three-term half space (all orders; numerical H, exact constants).

    f = f^(0) + f^(1) cos(phi) + f^(2) cos(2 phi) (Eq. 9); f^(2) = 15 c S^2 H2 H2 / (256 pi (mu_i + mu_o)).
    """
    mu_i = np.asarray(mu_i, dtype=np.float64)
    mu_o = np.asarray(mu_o, dtype=np.float64)
    sigma = mu_i + mu_o
    h0, h1, h2 = (hfunctions.HFunction(mode, c) for mode in range(3))
    k = hfunctions.zeroth_mode_constants(c)
    pi0 = k["A"] + k["B"] * sigma + k["C"] * mu_i * mu_o + k["D"] * mu_i * mu_o * sigma + k["E"] * (mu_i * mu_o) ** 2 + k["F"] * (mu_i**2 + mu_o**2)
    f0 = h0(mu_i) * h0(mu_o) * pi0 / (2.0 * math.pi * sigma)
    l, m = hfunctions.first_mode_constants(c)
    s = np.sqrt((1.0 - mu_i**2) * (1.0 - mu_o**2))
    f1 = c * s * h1(mu_i) * h1(mu_o) * (1.0 + (l * l + 45.0 * m / 64.0) * mu_i * mu_o + l * sigma) / (3.0 * math.pi * sigma)
    f2 = 15.0 * c * s * s * h2(mu_i) * h2(mu_o) / (256.0 * math.pi * sigma)
    return f0, f1, f2


class _AlbedoOrKd(BRDFModel):
    """Parameters shared by the two Lambert-sphere models: particle albedo c or diffuse colour k_d."""

    def resolve(self, values):
        has_c, has_kd = "albedo" in values, "kd" in values
        if has_c == has_kd:
            raise ValueError(f"model {self.name!r} needs exactly one of albedo, kd (each in [0, 1])")
        if has_kd:
            values["albedo"] = float(albedo_from_kd(values["kd"]))
        else:
            values["kd"] = float(kd_from_albedo(values["albedo"]))
        return values


_ALBEDO = Param("albedo", "particle (sphere) albedo c, Eq. 8", None, 0.0, 1.0)
_KD = Param("kd", "diffuse colour k_d (spherical albedo), mapped to c by Eq. 39", None, 0.0, 1.0)


@register
class LambertSphere(_AlbedoOrKd):
    name = "lambert_sphere"
    params = (
        _ALBEDO,
        _KD,
        Param("method", "fit: the paper's approximations; exact: numerical H and exact constants", "fit", choices=("fit", "exact")),
    )
    reference = ("d'Eon 2021 (Lambert-sphere BRDF), Eqs. 1, 8-12, 21-28, 30-38 "
                 "(f1 + f_m^(0) + f_m^(1) cos phi; corrections in module notes)")

    def setup(self):
        c = self.albedo
        if self.method == "exact":
            self._h0, self._h1 = hfunctions.HFunction(0, c).log, hfunctions.HFunction(1, c).log
            self._zeroth = hfunctions.zeroth_mode_constants(c)
            self._first = hfunctions.first_mode_constants(c)
        else:
            self._h0, self._h1 = (lambda mu: _log_h0_fit(mu, c)), (lambda mu: _log_h1_fit(mu, c))
            self._zeroth = zeroth_mode_constants_fit(c)
            self._first = first_mode_constants_fit(c)

    def _eval(self, wi, wo):
        c = self.albedo
        mu_i, mu_o = wi[:, 2], wo[:, 2]
        s_cos_phi = wi[:, 0] * wo[:, 0] + wi[:, 1] * wo[:, 1]
        f = single_scattering(wi, wo, c)
        f += zeroth_mode_multiple(mu_i, mu_o, c, self._h0(mu_i), self._h0(mu_o), self._zeroth)
        f += s_cos_phi * first_mode_multiple(mu_i, mu_o, c, self._h1(mu_i), self._h1(mu_o), *self._first)
        return f


@register
class LambertSphereFast(_AlbedoOrKd):
    name = "lambert_sphere_fast"
    params = (_ALBEDO, _KD)
    reference = "d'Eon 2021 (Lambert-sphere BRDF), Eq. 41 (with Eq. 10 for f1, Eq. 40 for k_d)"
    #: Largest albedo c for which Eq. 41 keeps the directional albedo <= 1 (theta_i <= 89.9 deg;
    #: measured: 0.98 gives 0.988, 0.985 gives 1.02, c = 1 gives 1.29 at grazing incidence).
    energy_conserving_albedo_max = 0.98

    def _eval(self, wi, wo):
        c = self.albedo
        mu_i, mu_o = wi[:, 2], wo[:, 2]
        s = np.sqrt(np.clip((1.0 - mu_i**2) * (1.0 - mu_o**2), 0.0, 1.0))
        abs_phi = np.arctan2(np.abs(wi[:, 0] * wo[:, 1] - wi[:, 1] * wo[:, 0]), wi[:, 0] * wo[:, 0] + wi[:, 1] * wo[:, 1])
        # 1 / (acos(S)/S + 0.113706) written as S / (acos(S) + 0.113706 S): finite at S = 0.
        lobe = 0.0151829 * (c - 0.249978) * (abs_phi + np.sqrt(mu_i * mu_o)) * s / (np.arccos(s) + 0.113706 * s)
        return np.maximum(0.0, single_scattering(wi, wo, c) + lobe + 0.234459 * self.kd**1.85432)
