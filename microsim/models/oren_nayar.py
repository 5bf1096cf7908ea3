"""The full Oren-Nayar model: direct term with C1, C2, C3 and the inter-reflection term.

Oren & Nayar 1994, "Generalization of Lambert's reflectance model", SIGGRAPH '94, 239-246,
functional approximation of the V-cavity model with Gaussian facet slopes (std sigma):

    f = rho/pi [C1 + cos(phi) C2 tan(beta) + (1 - |cos(phi)|) C3 tan((alpha + beta)/2)]
        + 0.17 rho^2/pi sigma^2/(sigma^2 + 0.13) [1 - cos(phi) (2 beta/pi)^2]

    C1 = 1 - 0.5 sigma^2 / (sigma^2 + 0.33)
    C2 = 0.45 sigma^2 / (sigma^2 + 0.09) sin(alpha)                     if cos(phi) >= 0
         0.45 sigma^2 / (sigma^2 + 0.09) (sin(alpha) - (2 beta/pi)^3)   otherwise
    C3 = 0.125 sigma^2 / (sigma^2 + 0.09) (4 alpha beta / pi^2)^2

with alpha = max(theta_i, theta_o), beta = min(theta_i, theta_o) and phi = phi_o - phi_i
(cos(phi) > 0: light and viewer on the same side, the backscatter half plane of
docs/conventions.md §1).
Cross-checked against the independent implementation in KimuraRyo/libbsdf
(include/libbsdf/ReflectanceModel/OrenNayar.h, the same L1 + L2), not the qualitative model of
pbrt. f is L_r / (E0 cos theta_i), so the 1/cos theta_i of the radiance form cancels.

``terms = "direct"`` keeps L1 alone: the model's single-bounce part, to judge against a table's
order 1 (the full model against orders 1 + 2, and against all orders, as in
``benchmarks/vcavities_fig7.py``).

Reciprocal: every term depends on (theta_i, theta_o) only through max/min and on phi only through
cos(phi), all symmetric under wi <-> wo (checked to 1e-10 relative in the tests).

Negative values: in the forward half plane near grazing (both theta > ~64 deg, sigma >~ 0.7) the
published C2 term makes the direct part negative (down to -0.27 rho/pi as theta_i, theta_o -> 90 deg),
and for rho <~ 0.85 the inter-reflection term does not make up for it. A BRDF is non-negative, so
f is clamped at 0 there (symmetric in wi, wo, so reciprocity is kept); elsewhere f is the
published form exactly.

Energy: the published approximation is not energy conserving for rho near 1: at grazing
incidence and small sigma its directional albedo reaches 1.05 for rho = 1 (sigma ~ 0.3,
theta_i = 89.9 deg); it stays <= 1 for rho <= 0.95 (``energy_conserving_albedo_max``).

Roughness domain: sigma in [0, pi/2). sigma is the standard deviation of the facet slope angle,
an angle in [0, pi/2), so a larger spread has no meaning for the V-cavity surface; every
coefficient saturates smoothly (sigma^2/(sigma^2 + k) -> 1), f stays finite and the directional
albedo decreases with sigma for sigma >= 0.2 up to the bound. sigma = 0 gives C1 = 1 and all other
terms 0: exactly ``lambert``.
"""

import math

import numpy as np

from microsim.models.base import BRDFModel, Param, register


@register
class OrenNayar(BRDFModel):
    name = "oren_nayar"
    params = (
        Param("albedo", "facet albedo rho", None, 0.0, 1.0),
        Param("roughness", "sigma, standard deviation of the facet slope angle (radians)", None, 0.0, math.pi / 2, hi_open=True),
        Param("terms", "full: L1 + L2; direct: L1 alone, the single-bounce part", "full", choices=("full", "direct")),
    )
    reference = "Oren & Nayar 1994 (SIGGRAPH), full model L1 + L2 (C1, C2, C3, inter-reflection)"
    #: Largest albedo for which the published form keeps the directional albedo <= 1 for every
    #: sigma and theta_i <= 89.9 deg (measured: 0.955).
    energy_conserving_albedo_max = 0.95

    def _eval(self, wi, wo):
        rho, s2 = self.albedo, self.roughness**2
        sin_i = np.hypot(wi[:, 0], wi[:, 1])
        sin_o = np.hypot(wo[:, 0], wo[:, 1])
        theta_i = np.arctan2(sin_i, wi[:, 2])
        theta_o = np.arctan2(sin_o, wo[:, 2])
        alpha, beta = np.maximum(theta_i, theta_o), np.minimum(theta_i, theta_o)
        sin_product = sin_i * sin_o
        cos_phi = np.divide(wi[:, 0] * wo[:, 0] + wi[:, 1] * wo[:, 1], sin_product, out=np.zeros_like(sin_product), where=sin_product > 0.0)
        cos_phi = np.clip(cos_phi, -1.0, 1.0)
        b = 2.0 * beta / math.pi
        c1 = 1.0 - 0.5 * s2 / (s2 + 0.33)
        c2 = 0.45 * s2 / (s2 + 0.09) * np.where(cos_phi >= 0.0, np.sin(alpha), np.sin(alpha) - b**3)
        c3 = 0.125 * s2 / (s2 + 0.09) * (4.0 * alpha * beta / math.pi**2) ** 2
        direct = c1 + cos_phi * c2 * np.tan(beta) + (1.0 - np.abs(cos_phi)) * c3 * np.tan(0.5 * (alpha + beta))
        inter = 0.17 * rho * s2 / (s2 + 0.13) * (1.0 - cos_phi * b**2) if self.terms == "full" else 0.0
        return np.maximum(rho / math.pi * (direct + inter), 0.0)
