"""Radiative transfer in a half space of independent point scatterers (CONVENTIONS 5.5).

The medium z < 0 has unit mean free path, single-scattering albedo c and phase function p(mu),
mu the cosine between the propagation directions before and after scattering (so the light
arriving along -wi and leaving along wo is turned by mu = -wi.wo). Its single scattering is

    f1(wi, wo) = c p(-wi.wo) / (mu_i + mu_o)        (lambert_sphere_brdf.txt, Eq. 10),

exact for any phase function: the Lambert-sphere model, the Boolean-sphere single-scattering
model, their tests and the dilute-limit benchmark all take it from here.
"""

from __future__ import annotations

import numpy as np

from .phase import phase_lambert_sphere


def single_scattering(wi, wo, albedo, phase=phase_lambert_sphere) -> np.ndarray:
    """f1 = c p(-wi.wo) / (mu_i + mu_o), Eq. 10, in 1/sr, for directions (..., 3) that broadcast.

    ``phase`` is p(mu) in 1/sr, integrating to 1 over the sphere; the default is the exact
    Lambert-sphere phase function (Eq. 1).
    """
    return albedo * phase(-np.sum(wi * wo, axis=-1)) / (wi[..., 2] + wo[..., 2])
