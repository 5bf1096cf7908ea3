"""Radiative transfer in a half space of independent point scatterers (docs/conventions.md §5.5).

The medium z < 0 has unit mean free path, single-scattering albedo c and phase function p(mu),
mu the cosine between the propagation directions before and after scattering (so the light
arriving along -wi and leaving along wo is turned by mu = -wi.wo). Its single scattering is

    f1(wi, wo) = c p(-wi.wo) / (mu_i + mu_o)        (d'Eon 2021, Eq. 10),

exact for any phase function: the Lambert-sphere model, the Boolean-sphere single-scattering
model, their tests and the dilute-limit benchmark all take it from here.

With isotropic scatterers the whole BRDF, every order, is closed (Chandrasekhar 1960,
Radiative Transfer, Ch. IV-V, the diffuse reflection of a semi-infinite isotropic atmosphere):

    f(wi, wo) = c H(mu_i) H(mu_o) / (4 pi (mu_i + mu_o)),

H the solution of H(mu) = 1 + mu H(mu) int_0^1 (c / 2) H(mu') / (mu + mu') dmu'
(:class:`~microsim.models.hfunctions.HFunction` with ``ISOTROPIC_MODE``); its directional albedo is
1 - H(mu_i) sqrt(1 - c), the model ``rte_isotropic``. The medium tables of
``geometry/halfspace_medium.py`` are checked against it.
"""

from __future__ import annotations

import math

import numpy as np

from microsim.models.base import BRDFModel, Param, register
from microsim.models.hfunctions import ISOTROPIC_MODE, HFunction


def single_scattering(wi, wo, albedo, phase=None) -> np.ndarray:
    """f1 = c p(-wi.wo) / (mu_i + mu_o), Eq. 10, in 1/sr, for directions (..., 3) that broadcast.

    ``phase`` is p(mu) in 1/sr, integrating to 1 over the sphere; the default (None) is the exact
    Lambert-sphere phase function (Eq. 1), imported here as it is first needed: its numba ufuncs
    take a tenth of a second to load, which listing the models need not pay.
    """
    if phase is None:
        from microsim.physics.phase import phase_lambert_sphere as phase
    return albedo * phase(-np.sum(wi * wo, axis=-1)) / (wi[..., 2] + wo[..., 2])


@register
class RteIsotropic(BRDFModel):
    name = "rte_isotropic"
    params = (Param("albedo", "single-scattering albedo c of the isotropic point scatterers", None, 0.0, 1.0),)
    reference = "Chandrasekhar 1960 (Radiative Transfer, Ch. IV-V): f = c H(mu_i) H(mu_o) / (4 pi (mu_i + mu_o)), exact"

    def setup(self):
        self.h = HFunction(ISOTROPIC_MODE, self.albedo)

    def _eval(self, wi, wo):
        mu_i, mu_o = wi[:, 2], wo[:, 2]
        return self.albedo * self.h(mu_i) * self.h(mu_o) / (4.0 * math.pi * (mu_i + mu_o))
