"""Interfaced Lambertian microfacets: a Lambertian body (albedo K_d) under a dielectric interface.

Paper: Meneveaux et al. 2015 (interfaced Lambertian microfacets; docs/reference/papers.md), whose
equation numbers are cited below, with n_i = ``eta`` and K_d = ``albedo``:

- flat (``roughness`` = 0): body reflection, Eq. 8 taken at m = n,
  f_b = K_d T(mu_i) T(mu_o) / (pi n_i^2 (1 - K_d r_i)), T = 1 - F (Eq. 7), with the internal
  diffuse reflectance r_i from n_i^2 (1 - r_i) = 1 - r_e and Molenaar's r_e (Eq. 10). The
  interface's mirror reflection is a Dirac of weight F(mu_i) in the specular direction; a
  BRDF value cannot carry it, so :meth:`~InterfacedLambert.specular_delta_reflectance`
  returns its weight and ``model(wi, wo)`` the body term only.
- rough: f = f_s + f_b (Eq. 11), f_s the specular microfacet BRDF (Eq. 3, see
  :mod:`microsim.models.microfacet`) and f_b the body integral over facet normals (Eq. 12),
  K_d / (pi n_i^2 (1 - r_i K_d)) integral T(i, m) T(o, m) D(m) G(i, o, m) <i.m><o.m> /
  (mu_i mu_o) d(omega_m), by a fixed product rule: Gauss-Legendre in xi1 and the midpoint
  rule in xi2 of the map (xi1, xi2) -> m of :func:`distributions.sample`, whose density is
  D(m)(m.n), so that D(m) d(omega_m) = d(xi1) d(xi2) / (m.n) at every roughness.

Reciprocal: T(i, m) T(o, m), <i.m><o.m>, D and every GAF offered are symmetric in (i, o), and
the facet nodes do not depend on the directions, so the quadrature is symmetric too.
Energy: with K_d = 1 and a flat interface the body albedo is exactly 1 - F(mu_i); the rough
form stays below 1 because each GAF is bounded by a masking function satisfying the
projected-area identity (tests/test_models_interfaced_lambert.py).
"""

import math

import numba
import numpy as np

from microsim.models.base import BRDFModel, Param, register
from microsim.models.microfacet import roughness_params, specular_brdf
from microsim.physics import distributions as nd
from microsim.physics.fresnel import fresnel_dielectric, fresnel_dielectric_array, internal_diffuse_reflectance

#: Facet-normal rule of the body integral (Eq. 12): Gauss-Legendre nodes in xi1 (tilt) times
#: midpoint nodes in xi2 (azimuth). Relative error against a rule 4 x finer in each direction,
#: theta_i, theta_o <= 80 deg: <= 1e-4 up to roughness 0.3 for every NDF and GAF, <= 1.2e-3
#: at roughness 1 and 2.6e-3 at roughness 3 (Torrance-Sparrow kinks; Smith 6e-4); 7.6e-3 at
#: 85 deg and roughness 3. It grows only where both directions graze, where the body is small.
BODY_NODES_TILT = 48
BODY_NODES_AZIMUTH = 96

@numba.njit(cache=True)
def _body_integral(wi, wo, lambda_i, lambda_o, m, weight, eta, gaf_code):
    """sum_q weight_q T(i, m_q) T(o, m_q) G <i.m_q><o.m_q> / (mu_i mu_o), per direction pair."""
    out = np.empty(wi.shape[0])
    for p in range(wi.shape[0]):
        acc = 0.0
        for q in range(m.shape[0]):
            im = wi[p, 0] * m[q, 0] + wi[p, 1] * m[q, 1] + wi[p, 2] * m[q, 2]
            om = wo[p, 0] * m[q, 0] + wo[p, 1] * m[q, 1] + wo[p, 2] * m[q, 2]
            if im <= 0.0 or om <= 0.0:
                continue
            g = nd.gaf_value(gaf_code, lambda_i[p], lambda_o[p], wi[p, 2], wo[p, 2], m[q, 2], im, om)
            t = (1.0 - fresnel_dielectric(im, eta)) * (1.0 - fresnel_dielectric(om, eta))
            acc += weight[q] * t * g * (im * om)
        out[p] = acc / (wi[p, 2] * wo[p, 2])
    return out


def facet_rule(distribution, roughness_x, roughness_y, n_tilt=BODY_NODES_TILT, n_azimuth=BODY_NODES_AZIMUTH):
    """Facet normals m (K, 3) and weights (K,) with sum w g(m) ~ integral g(m) D(m) d(omega_m).

    xi1 = 1 - (1 - t)^2 with t on Gauss-Legendre nodes: D d(omega) = d(xi) / (m.n) and m.n
    vanishes like sqrt(1 - xi1) at the horizon for GGX, a singularity this change removes.
    """
    x, w = np.polynomial.legendre.leggauss(n_tilt)
    t, wt = 0.5 * (x + 1.0), 0.5 * w
    xi1, w1 = 1.0 - (1.0 - t) ** 2, wt * 2.0 * (1.0 - t)
    xi2 = (np.arange(n_azimuth) + 0.5) / n_azimuth
    m = nd.sample(distribution, roughness_x, roughness_y, xi1[:, None], xi2[None, :]).reshape(-1, 3)
    weight = np.repeat(w1, n_azimuth) / n_azimuth / m[:, 2]
    return np.ascontiguousarray(m), weight


@register
class InterfacedLambert(BRDFModel):
    name = "interfaced_lambert"
    params = (
        Param("albedo", "Lambertian albedo K_d of the body under the interface", None, 0.0, 1.0),
        Param("eta", "refractive index ratio n_i = n_body / n_outside", 1.5, 1.0, 10.0),
        *roughness_params(flat=True),
        Param("distribution", "microfacet normal distribution (rough interface)", "beckmann", choices=nd.DISTRIBUTIONS),
        Param("gaf", "masking-shadowing function (rough interface)", "smith", choices=nd.GAFS),
    )
    reference = ("Meneveaux et al. 2015 (interfaced Lambertian microfacets), Eq. 3, 7-12 "
                 "(flat: Eq. 8-10; rough: Eq. 11-12)")

    def resolve(self, values):
        if not any(k in values for k in ("roughness", "roughness_x", "roughness_y")):
            values = {**values, "roughness": 0.0}
        return nd.resolve_roughness(values, allow_zero=True)

    def setup(self):
        self.flat = self.roughness_x == 0.0
        self.r_i = internal_diffuse_reflectance(self.eta)
        self.body_scale = self.albedo / (math.pi * self.eta**2 * (1.0 - self.r_i * self.albedo))
        if not self.flat:
            nd.check_gaf(self.distribution, self.gaf, self.roughness_x, self.roughness_y)
            self.facets, self.facet_weights = facet_rule(self.distribution, self.roughness_x, self.roughness_y)

    def specular_delta_reflectance(self, wi) -> np.ndarray:
        """Weight of the Dirac mirror reflection: F(mu_i) for a flat interface, 0 when rough."""
        mu = np.asarray(wi, dtype=np.float64)[..., 2]
        if not self.flat:
            return np.zeros(mu.shape)
        return np.where(mu > 0.0, fresnel_dielectric_array(mu, self.eta), 0.0)

    def _eval(self, wi, wo):
        if self.flat:
            t_i = 1.0 - fresnel_dielectric_array(wi[:, 2], self.eta)
            t_o = 1.0 - fresnel_dielectric_array(wo[:, 2], self.eta)
            return self.body_scale * t_i * t_o
        args = (self.distribution, self.roughness_x, self.roughness_y)
        if self.gaf == "torrance_sparrow":
            lam_i = lam_o = np.zeros(wi.shape[0])
        else:
            lam_i = nd.smith_lambda(*args, wi)
            lam_o = nd.smith_lambda(*args, wo)
        code = nd.GAFS.index(self.gaf)
        body = _body_integral(wi, wo, lam_i, lam_o, self.facets, self.facet_weights, self.eta, code)
        return self.body_scale * body + specular_brdf(wi, wo, *args, self.gaf, self.eta)
