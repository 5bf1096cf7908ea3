"""The specular microfacet BRDF f = D(h) G(i, o, h) F(i.h) / (4 mu_i mu_o).

Meneveaux et al. 2015 (interfaced Lambertian microfacets; docs/reference/papers.md), Eq. 3
(Cook-Torrance / Walter et al. 2007); equation numbers below are that paper's. With the NDFs and
GAFs of :mod:`microsim.physics.distributions` and the Fresnel reflectance of
:func:`microsim.physics.fresnel.fresnel`: a dielectric when ``k`` = 0 (exact unpolarised form,
Eq. 7, total internal reflection for ``eta`` < 1), a conductor with complex index ``eta`` + i
``k`` otherwise. Eq. 3 prints the denominator 4 |i.h| |o.h|; inserting the facet BRDF of Eq. 5,
F delta(h, m) / (4 |i.h|^2), into Eq. 2 gives F D G |i.h| |o.h| / (4 |i.h|^2 |i.n| |o.n|)
= F D G / (4 |i.n| |o.n|) (as in the paper's Eq. 26 and Walter et al. 2007 Eq. 20), which
is the form used.

Default ``eta`` = 1.5 (a typical glass / plastic dielectric, as in the configs' example).
"""

import numpy as np

from microsim.models.base import BRDFModel, Param, register
from microsim.physics import distributions as nd
from microsim.physics.fresnel import fresnel_array


def specular_brdf(wi, wo, distribution, roughness_x, roughness_y, gaf, eta, k=0.0) -> np.ndarray:
    """D(h) G(i, o, h) F(i.h) / (4 mu_i mu_o) for (N, 3) directions above the horizon."""
    h = wi + wo
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    d = nd.ndf(distribution, roughness_x, roughness_y, h)
    g = nd.masking_shadowing(gaf, distribution, roughness_x, roughness_y, wi, wo, h)
    f = fresnel_array(np.sum(wi * h, axis=-1), eta, k)
    return d * g * f / (4.0 * wi[:, 2] * wo[:, 2])


def roughness_params(flat: bool = False) -> tuple[Param, ...]:
    """The roughness alias and its two axes; with ``flat``, 0 (the default) is a flat surface."""
    rng = f"[{nd.ROUGHNESS_MIN:g}, {nd.ROUGHNESS_MAX:g}]"
    lo = 0.0 if flat else nd.ROUGHNESS_MIN
    return (
        Param(
            "roughness",
            "isotropic roughness (alpha; sigma in rad for gaussian), sets both axes; "
            + (f"0 = flat, else {rng}" if flat else rng),
            0.0 if flat else None,
            lo,
            nd.ROUGHNESS_MAX,
        ),
        Param("roughness_x", "roughness along the surface x axis (beckmann, ggx)", None, lo, nd.ROUGHNESS_MAX),
        Param("roughness_y", "roughness along the surface y axis (beckmann, ggx)", None, lo, nd.ROUGHNESS_MAX),
    )


@register
class Microfacet(BRDFModel):
    name = "microfacet"
    params = (
        Param("distribution", "microfacet normal distribution", "beckmann", choices=nd.DISTRIBUTIONS),
        *roughness_params(),
        Param("gaf", "masking-shadowing function", "smith", choices=nd.GAFS),
        Param("eta", "real part of the relative refractive index", 1.5, 0.0, 100.0, lo_open=True),
        Param("k", "imaginary part (extinction); 0 = dielectric", 0.0, 0.0, 100.0),
    )
    reference = ("Meneveaux et al. 2015 (interfaced Lambertian microfacets), Eq. 3 "
                 "(D: Eq. 13, 15, 20; G: Eq. 14, 16-21; F: Eq. 7)")

    def resolve(self, values):
        return nd.resolve_roughness(values)

    def setup(self):
        nd.check_gaf(self.distribution, self.gaf, self.roughness_x, self.roughness_y)

    def _eval(self, wi, wo):
        return specular_brdf(wi, wo, self.distribution, self.roughness_x, self.roughness_y, self.gaf, self.eta, self.k)
