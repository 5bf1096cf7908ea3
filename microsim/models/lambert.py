"""The Lambertian BRDF, albedo / pi."""

import numpy as np

from microsim.models.base import BRDFModel, Param, register


@register
class Lambert(BRDFModel):
    name = "lambert"
    params = (Param("albedo", "reflectance (directional albedo, constant)", None, 0.0, 1.0),)
    reference = "Lambert 1760: f = albedo / pi"

    def _eval(self, wi, wo):
        return np.full(wi.shape[0], self.albedo / np.pi)
