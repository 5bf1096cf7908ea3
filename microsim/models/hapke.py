"""Hapke's bidirectional reflectance of a particulate half space, in the form planetary science uses.

Hapke 2012 (Theory of Reflectance and Emittance Spectroscopy, 2nd ed., Cambridge University
Press), the form with the porosity factor of Hapke 2008 (Icarus 195, 918-926):

    r(i, e, g) = K w / (4 pi) mu0e / (mu0e + mue) [p(g) B_SH(g) + M(mu0e, mue)] S(i, e, psi)

and the BRDF f = r / mu0 (Hapke's r is the radiance factor per unit incident irradiance: r = f mu0).

* K(phi) = -ln(1 - 1.209 phi^(2/3)) / (1.209 phi^(2/3)) (Hapke 2008, Eq. 23), phi the volume
  fraction of the grains, below 0.752; K = 1 at phi = 0.
* w the single-scattering albedo of a grain. The grains of microsim's scenes are large
  Lambertian spheres traced without diffraction, so w is their surface albedo and p(g) the
  Lambertian sphere's (d'Eon 2021, Eq. 1) by default.
* p(g), g the phase angle (cos g = wi.wo; g = 0 at backscatter), normalised to a mean of 1 over
  the sphere: 4 pi times p(mu) of :mod:`microsim.physics.phase` at the scattering cosine
  mu = -cos g. Henyey-Greenstein (of mean scattering cosine ``asymmetry``) and Hapke's two-term
  Legendre form p = 1 + b1 cos g + b2 (3 cos^2 g - 1) / 2 are the alternatives.
* B_SH(g) = 1 + B_S0 / (1 + tan(g/2) / h_S), the shadow-hiding opposition effect (Hapke 2012,
  Ch. 9); h_S = -(3/8) ln(1 - phi) for equal spheres (Hapke 1986, Icarus 67, 264) where it is not
  given. The coherent-backscatter opposition effect is left out: geometric optics has none.
* M, the multiple scattering, evaluated with the H-function at mu / K (Hapke 2008):
  isotropic (IMSA), M = H(mu0e / K) H(mue / K) - 1; anisotropic (AMSA, Hapke 2002, Icarus 157,
  523, Eqs. 17-25), M = P(mu0e) [H(mue / K) - 1] + P(mue) [H(mu0e / K) - 1]
  + Pbar [H(mu0e / K) - 1] [H(mue / K) - 1], with P(mu) = 1 + sum_n A_n b_n P_n(mu) and
  Pbar = 1 + sum_n A_n^2 b_n over the odd n, A_n = (-1)^((n+1)/2) / n (1 3 5 ... n) / (2 4 6 ... (n+1)),
  b_n the Legendre coefficients of p(g) in cos g.
* H the exact H-function of isotropic scattering (Chandrasekhar 1960;
  :class:`~microsim.models.hfunctions.HFunction`), or Hapke's approximation (Hapke 2002, Eq. 13):
  H(x) = 1 / (1 - w x [r0 + (1 - 2 r0 x) / 2 ln((1 + x) / x)]), r0 = (1 - gamma) / (1 + gamma),
  gamma = sqrt(1 - w), within 1 % of the exact one (:data:`APPROXIMATE_H_ACCURACY`, a test holds it).
* mu0e, mue and S the macroscopic roughness of mean slope angle theta_bar
  (:mod:`microsim.models.hapke_roughness`); mu0e = mu0, mue = mu and S = 1 without it.

With K = 1, no opposition effect, isotropic scattering and the exact H, the model is
Chandrasekhar's result, ``rte_isotropic``; its single scattering with K = 1 and no opposition
effect is the exact Eq. 10 of d'Eon 2021 (:func:`microsim.models.radiative_transfer.single_scattering`).
"""

from __future__ import annotations

import math

import numpy as np

from microsim.models.base import BRDFModel, Param, register
from microsim.models.hapke_roughness import azimuth_difference, roughness_cosines
from microsim.models.hfunctions import ISOTROPIC_MODE, HFunction

#: the largest volume fraction of the porosity factor (1.209 phi^(2/3) < 1)
PHI_MAX = 1.209 ** -1.5
#: the stated accuracy of Hapke's approximate H-function (Hapke 2002: "better than 1 %")
APPROXIMATE_H_ACCURACY = 0.01
#: Legendre terms of p(g) that the anisotropic multiple scattering sums (odd n up to this)
LEGENDRE_TERMS = 199
PHASES = ("lambert_sphere", "isotropic", "henyey_greenstein", "legendre")


def porosity_factor(phi):
    """K(phi) = -ln(1 - 1.209 phi^(2/3)) / (1.209 phi^(2/3)), Hapke 2008 Eq. 23; 1 at phi = 0."""
    x = 1.209 * np.asarray(phi, np.float64) ** (2.0 / 3.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(x > 0.0, -np.log1p(-x) / np.where(x > 0.0, x, 1.0), 1.0)


def opposition_width(phi: float) -> float:
    """h_S = -(3/8) ln(1 - phi), the shadow-hiding width of equal spheres (Hapke 1986)."""
    return -0.375 * math.log1p(-phi)


def approximate_h(x, w: float):
    """Hapke's approximate H-function of isotropic scattering (Hapke 2002, Eq. 13), x >= 0."""
    x = np.asarray(x, np.float64)
    gamma = math.sqrt(1.0 - w)
    r0 = (1.0 - gamma) / (1.0 + gamma)
    with np.errstate(divide="ignore", invalid="ignore"):
        log_term = np.where(x > 0.0, x * np.log((1.0 + x) / np.where(x > 0.0, x, 1.0)), 0.0)
    return 1.0 / (1.0 - w * (x * r0 + 0.5 * (1.0 - 2.0 * r0 * x) * log_term))


def phase_of_angle(phase: str, cos_g, asymmetry: float = 0.0, b1: float = 0.0, b2: float = 0.0):
    """p(g) at cos g, normalised to a mean of 1 over the sphere (module doc)."""
    cos_g = np.asarray(cos_g, np.float64)
    if phase == "lambert_sphere":
        from microsim.physics.phase import phase_lambert_sphere  # numba ufuncs: loaded when first needed

        return 4.0 * math.pi * phase_lambert_sphere(-cos_g)
    if phase == "henyey_greenstein":
        a = asymmetry
        return (1.0 - a * a) / (1.0 + a * a + 2.0 * a * cos_g) ** 1.5
    if phase == "legendre":
        return 1.0 + b1 * cos_g + b2 * (1.5 * cos_g * cos_g - 0.5)
    return np.ones_like(cos_g)


def legendre_of_phase(phase: str, terms: int, **shape) -> np.ndarray:
    """b_0..b_terms of p(g) = sum_n b_n P_n(cos g) (b_0 = 1), by Gauss-Legendre projection in g,
    where the Lambertian sphere's p is analytic (in cos g it has square-root singularities)."""
    x, weight = np.polynomial.legendre.leggauss(2 * terms + 64)
    g = 0.5 * math.pi * (x + 1.0)
    weight = 0.5 * math.pi * weight * np.sin(g) * phase_of_angle(phase, np.cos(g), **shape)
    basis = np.polynomial.legendre.legvander(np.cos(g), terms)
    return (2.0 * np.arange(terms + 1) + 1.0) / 2.0 * (weight @ basis)


def amsa_weights(terms: int) -> np.ndarray:
    """A_0..A_terms of the anisotropic multiple scattering (Hapke 2002, Eq. 25): 0 at even n,
    (-1)^((n+1)/2) / n (1 3 ... n) / (2 4 ... (n+1)) at odd n."""
    a = np.zeros(terms + 1)
    ratio = 0.5  # (1 3 ... n) / (2 4 ... (n+1)) at n = 1
    for n in range(1, terms + 1, 2):
        a[n] = (-1.0) ** ((n + 1) // 2) * ratio / n
        ratio *= (n + 2.0) / (n + 3.0)
    return a


@register
class Hapke(BRDFModel):
    name = "hapke"
    params = (
        Param("albedo", "single-scattering albedo w of a grain", None, 0.0, 1.0),
        Param("volume_fraction", "volume fraction phi of the grains, for the porosity factor K(phi) "
              "(0: K = 1, the porosity of a sparse medium)", 0.0, 0.0, PHI_MAX, hi_open=True),
        Param("opposition_amplitude", "B_S0, the amplitude of the shadow-hiding opposition effect", 0.0, 0.0),
        Param("opposition_width", "h_S, its angular width (default: -(3/8) ln(1 - volume_fraction))", None,
              0.0, lo_open=True, optional=True),
        Param("roughness_deg", "mean slope angle theta_bar of the macroscopic roughness, degrees", 0.0, 0.0, 60.0),
        Param("phase", "single-particle phase function p(g)", "lambert_sphere", choices=PHASES),
        Param("asymmetry", "mean scattering cosine of the henyey_greenstein phase function", 0.0, -0.95, 0.95),
        Param("legendre_b1", "b1 of the legendre phase function p = 1 + b1 cos g + b2 P2(cos g)", 0.0, -1.0, 1.0),
        Param("legendre_b2", "b2 of the legendre phase function", 0.0, -0.5, 1.0),
        Param("multiple_scattering", "isotropic (IMSA) or anisotropic (AMSA, Hapke 2002)", "isotropic",
              choices=("isotropic", "anisotropic")),
        Param("h_function", "exact (Chandrasekhar) or approximate (Hapke 2002, within 1 %)", "exact",
              choices=("exact", "approximate")),
    )
    reference = ("Hapke 2012 (Theory of Reflectance and Emittance Spectroscopy, 2nd ed.) with K(phi) of Hapke 2008 "
                 "and the AMSA of Hapke 2002: r = K w/(4 pi) mu0e/(mu0e + mue) [p(g) B_SH(g) + M] S, f = r/mu0")

    def resolve(self, values: dict) -> dict:
        if values.get("opposition_width") is None:
            phi = values.get("volume_fraction", 0.0)
            if values.get("opposition_amplitude", 0.0) > 0.0 and phi == 0.0:
                raise ValueError("opposition_width: needed in (0, inf) when opposition_amplitude > 0 and "
                                 "volume_fraction = 0 (-(3/8) ln(1 - phi) is 0 there)")
            values["opposition_width"] = opposition_width(phi) if phi > 0.0 else None
        legendre = values.get("phase") == "legendre"
        p_back = 1.0 + values.get("legendre_b1", 0.0) + values.get("legendre_b2", 0.0)
        p_forward = 1.0 - values.get("legendre_b1", 0.0) + values.get("legendre_b2", 0.0)
        p_side = 1.0 - 0.5 * values.get("legendre_b2", 0.0)
        if legendre and min(p_back, p_forward, p_side) < 0.0:
            raise ValueError("legendre_b1, legendre_b2: the phase function 1 + b1 cos g + b2 P2(cos g) is negative "
                             "somewhere; accepted: |b1| <= 1 + b2 and b2 <= 2")
        return values

    def setup(self):
        self.k = float(porosity_factor(self.volume_fraction))
        self.shape = {"asymmetry": self.asymmetry, "b1": self.legendre_b1, "b2": self.legendre_b2}
        self.h = (HFunction(ISOTROPIC_MODE, self.albedo) if self.h_function == "exact"
                  else (lambda x: approximate_h(x, self.albedo)))
        if self.multiple_scattering == "anisotropic":
            b = legendre_of_phase(self.phase, LEGENDRE_TERMS, **self.shape)
            a = amsa_weights(LEGENDRE_TERMS)
            self.p_coefficients = a * b
            self.p_coefficients[0] = 1.0
            self.p_bar = 1.0 + float(np.sum(a[1:] ** 2 * b[1:]))

    def hemispherical_phase(self, mu):
        """P(mu) = 1 + sum_n A_n b_n P_n(mu) of the anisotropic multiple scattering (Hapke 2002)."""
        return np.polynomial.legendre.legval(mu, self.p_coefficients)

    def multiple(self, mu0e, mue):
        """M(mu0e, mue) of the isotropic or anisotropic approximation (module doc)."""
        h0, h = self.h(mu0e / self.k), self.h(mue / self.k)
        if self.multiple_scattering == "isotropic":
            return h0 * h - 1.0
        return (self.hemispherical_phase(mu0e) * (h - 1.0) + self.hemispherical_phase(mue) * (h0 - 1.0)
                + self.p_bar * (h0 - 1.0) * (h - 1.0))

    def _eval(self, wi, wo):
        mu0, mu = wi[:, 2], wo[:, 2]
        cos_g = np.clip(np.sum(wi * wo, axis=1), -1.0, 1.0)
        single = phase_of_angle(self.phase, cos_g, **self.shape)
        if self.opposition_amplitude > 0.0:
            tan_half = np.linalg.norm(wi - wo, axis=1) / np.linalg.norm(wi + wo, axis=1)  # tan(g/2), accurate at g = 0
            single = single * (1.0 + self.opposition_amplitude / (1.0 + tan_half / self.opposition_width))
        if self.roughness_deg > 0.0:
            mu0e, mue, shadowing = roughness_cosines(mu0, mu, azimuth_difference(wi, wo), math.radians(self.roughness_deg))
        else:
            mu0e, mue, shadowing = mu0, mu, 1.0
        r = self.k * self.albedo / (4.0 * math.pi) * mu0e / (mu0e + mue) * (single + self.multiple(mu0e, mue))
        return r * shadowing / mu0
