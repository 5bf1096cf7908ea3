"""The material ``interfaced_lambert``: a smooth dielectric interface over a Lambertian body
(Meneveaux et al. 2015, Eq. 8-10), sampled bounce by bounce.
"""

from __future__ import annotations

import math
from typing import ClassVar, Literal

import numba
from pydantic import Field

from microsim.physics.fresnel import fresnel_dielectric, internal_diffuse_reflectance
from microsim.physics.rng import uniform
from microsim.physics.sampling import from_local, reflect
from microsim.tracer.materials.base import Material

#: cap on the body bounces of one interfaced_lambert interaction; weight left is truncated
MAX_BODY_BOUNCES = 256

class InterfacedLambert(Material):
    """A smooth dielectric interface (index ratio ``eta``) over a Lambertian body of albedo
    ``albedo``: the flat interfaced Lambertian of Meneveaux et al. 2015, Eq. 8-10.
    Fresnel reflection or refraction at the interface, then Lambertian bounces in the body with
    Fresnel (and total internal) reflection at the interface from inside until the light leaves.
    The whole excursion is one interaction."""

    kind: Literal["interfaced_lambert"]
    albedo: float = Field(ge=0.0, le=1.0, description="albedo K_d of the Lambertian body")
    eta: float = Field(ge=1.0, le=4.0, description="refractive index ratio n_i of the interface")
    example: ClassVar[dict] = {"albedo": 0.7, "eta": 1.5}
    delta_lobes: ClassVar[str] = "the mirror reflection of its smooth interface"

    def albedo_bound(self) -> float:
        f0 = fresnel_dielectric(1.0, self.eta)
        return min(1.0, f0 + (1.0 - f0) * self.albedo)

    def row(self) -> tuple[float, ...]:
        """albedo, eta, and the body's internal diffuse reflectance r_i (Eq. 9-10): the chance that
        light inside is sent back by the interface, which :func:`evaluate` and :func:`pdf` read."""
        return self.albedo, self.eta, internal_diffuse_reflectance(self.eta)

    @classmethod
    def row_size(cls) -> int:
        return 3

    @staticmethod
    def sample(prm, states, i, d, n):
        return _interfaced_lambert(prm[0], prm[1], states, i, d, n)

    @staticmethod
    def lobes(prm, white, wi, wo, n):
        cos_i = wi[0] * n[0] + wi[1] * n[1] + wi[2] * n[2]
        cos_o = wo[0] * n[0] + wo[1] * n[1] + wo[2] * n[2]
        return _interfaced_lambert_body(1.0 if white else prm[0], prm[1], prm[2], cos_i, cos_o) * cos_o


INTERFACED_LAMBERT = InterfacedLambert.code


@numba.njit(cache=True, error_model="numpy", _nrt=False)
def _interfaced_lambert_body(albedo, eta, r_i, cos_i, cos_o):
    """The body term of the flat interfaced Lambertian, Meneveaux et al. 2015, Eq. 8 at
    m = n: K_d T(mu_i) T(mu_o) / (pi eta^2 (1 - K_d r_i)), T = 1 - F. It is what the
    bounce-by-bounce sampler of :func:`_interfaced_lambert` gives on average: light enters with
    chance T(mu_i), each bounce multiplies the weight by K_d and leaves with chance 1 - r_i, in a
    direction of density T cos_t / pi inside, cos_t d(omega_t) = cos_o d(omega_o) / eta^2 out."""
    transmitted = (1.0 - fresnel_dielectric(cos_i, eta)) * (1.0 - fresnel_dielectric(cos_o, eta))
    return albedo * transmitted / (math.pi * eta * eta * (1.0 - albedo * r_i))


@numba.njit(cache=True, error_model="numpy", _nrt=False)
def _interfaced_lambert(albedo, eta, states, i, d, n):
    """Smooth dielectric over a Lambertian body, sampled bounce by bounce (see InterfacedLambert)."""
    cos_i = -(d[0] * n[0] + d[1] * n[1] + d[2] * n[2])
    if uniform(states, i) < fresnel_dielectric(cos_i, eta):
        return reflect(d, n), 1.0, 0.0
    weight = 1.0
    for _ in range(MAX_BODY_BOUNCES):
        weight *= albedo
        if weight == 0.0:
            return d, 0.0, 0.0
        # Lambertian body: cosine-distributed direction towards the interface (inside).
        u1 = uniform(states, i)
        u2 = uniform(states, i)
        sin_t = math.sqrt(u1)
        cos_t = math.sqrt(max(0.0, 1.0 - u1))
        if uniform(states, i) >= fresnel_dielectric(cos_t, 1.0 / eta):
            # Refraction out: Snell, sin_o = eta sin_t (no TIR here since F < 1).
            sin_o = min(eta * sin_t, 1.0)
            cos_o = math.sqrt(max(0.0, 1.0 - sin_o * sin_o))
            phi = 2.0 * math.pi * u2
            return from_local(sin_o * math.cos(phi), sin_o * math.sin(phi), cos_o, n), weight, 0.0
    return d, 0.0, weight
