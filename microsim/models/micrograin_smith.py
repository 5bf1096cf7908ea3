"""The micrograin BSDF of Lucas et al. 2023 with the Smith GAF, ``micrograin_smith``.

As recalled in Lucas et al. 2024 (fully-correlated anisotropic micrograin BSDF), Sec. 3, Eq. 1-6
(the equation numbers below are that paper's; docs/reference/papers.md):

    f = w+ f^S + (1 - w+) f^B,                                          (Eq. 1)
    f^S = K_d / pi T_avg(i, o) + D(h) G(i, o) F(i.h) / (4 mu_i mu_o),   (Eq. 2)
    1 - w+ = (1 - tau_b+(i)) (1 - tau_b+(o)) / (1 - tau0)               (Eq. 4)
           = (1 - tau0) G1^dist(i, 0) G1^dist(o, 0)                     (Eq. 24-25, App. C)
           = (1 - tau0)^((1 / cos theta_i' + 1 / cos theta_o') / 2),

(Eq. 24 is printed as G1^dist(i, o); its right side (1 - tau_b+(i)) / (1 - tau0) and Eq. 25
make it G1^dist(i, 0), the term at pore level; test_smith_model_weights checks the result)

D the micrograin NDF (Eq. 5, the isotropic case of Eq. 10-12; Eq. 5 as printed lacks the 1/pi
of Eq. 11 and would integrate to pi: we use Eq. 10-12, test_ndf_is_normalised) and G Smith's
GAF of that NDF,
G = G1(i) G1(o) with G1 = 1 / (1 + Lambda) (``gaf = "separable"``, the default, as in the
public implementations of this model) or G = 1 / (1 + Lambda(i) + Lambda(o))
(``"height_correlated"``). Lambda has no known closed form; it is computed by quadrature in
:func:`microsim.models.micrograin_geometry.smith_lambda`.

The 2023 paper itself was not at hand (only its summary in Lucas et al. 2024): its average
transmission T_avg is taken as (1 - F(mu_i)) (1 - F(mu_o)), the interface transmittance at the
mean normal n (1 for ``lambert`` grains; the diffuse term is absent for ``conductor`` and
``mirror`` grains, and ``mirror`` grains have F = 1 at every angle).

Extension: Lucas et al. 2023 treat isotropic grains only; beta_x != beta_y is accepted here
through the same affine map as the 2024 model (shape-invariant NDF, Lambda(w) = Lambda_1(w'),
tau_b+ from the unit-space direction), which reduces to the published model when
beta_x = beta_y.

Parameters are those of ``micrograin`` and mirror a micrograin scene's run config
(docs/conventions.md §4): ``material`` (lambert | conductor | mirror | interfaced_lambert) with
``albedo``, ``eta``, ``k`` as its ``[material]`` table takes them, ``base`` (absorber | lambert)
with ``base_albedo``; the old names ``bulk``, ``bulk_albedo`` and the old grain description by
``eta`` and ``k`` alone remain as aliases (see :mod:`microsim.models.micrograin_params`). As there, T
omits the internal reflections of the scenes' interfaced_lambert material.
"""

from __future__ import annotations

import numpy as np

from microsim.models.base import Param, register
from microsim.models.micrograin_geometry import ndf, pore_visibility, smith_lambda
from microsim.models.micrograin_params import MicrograinParams
from microsim.physics.fresnel import fresnel_conductor_array, fresnel_dielectric_array

#: The two Smith forms of the GAF (Lucas et al. 2023 use the separable one).
GAF = Param("gaf", "Smith GAF: G1(i) G1(o), or height-correlated 1 / (1 + Lambda_i + Lambda_o)", "separable",
            choices=("separable", "height_correlated"))


@register
class MicrograinSmith(MicrograinParams, gaf=GAF):
    name = "micrograin_smith"
    reference = (
        "Lucas et al. 2023 (micrograin BSDF for porous layers), as recalled in Lucas et al. 2024 "
        "(fully-correlated anisotropic micrograin BSDF): Eq. 1-6, with Eq. 24-25 for tau_beta+"
    )

    def _eval(self, wi, wo):
        mu_i = wi[:, 2]
        mu_o = wo[:, 2]
        bulk_weight = pore_visibility(wi, wo, self.tau0, self.beta_x, self.beta_y, correlated=False)
        grains = np.full(wi.shape[0], self.albedo / np.pi)
        if self.has_interface:
            t_i = 1.0 - fresnel_dielectric_array(mu_i, self.eta)
            grains *= t_i * (1.0 - fresnel_dielectric_array(mu_o, self.eta))
        if self.has_specular:
            hv = wi + wo
            hv /= np.linalg.norm(hv, axis=-1, keepdims=True)
            lambda_i = smith_lambda(wi, self.tau0, self.beta_x, self.beta_y)
            lambda_o = smith_lambda(wo, self.tau0, self.beta_x, self.beta_y)
            if self.gaf == "separable":
                g = (1.0 / (1.0 + lambda_i)) * (1.0 / (1.0 + lambda_o))
            else:
                g = 1.0 / (1.0 + lambda_i + lambda_o)
            d = ndf(hv, self.tau0, self.beta_x, self.beta_y)
            grains += d * g * self._fresnel(np.sum(wi * hv, axis=-1)) / (4.0 * mu_i) / mu_o
        return (1.0 - bulk_weight) * grains + bulk_weight * self.base_brdf

    def _fresnel(self, cos_d):
        """F(i.h) of the specular term, as ``micrograin._grain_fresnel``."""
        if self.material == "mirror":
            return np.ones_like(cos_d)
        if self.material == "conductor":
            return fresnel_conductor_array(cos_d, self.eta, self.k)
        return fresnel_dielectric_array(cos_d, self.eta)
