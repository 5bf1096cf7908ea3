"""Surface materials of the tracer: a registry of kinds, each sampled exactly in numba.

A material is a kind code and up to ``N_PARAMS`` parameters (a row of the scene's material
table), built from its config dictionary by :func:`material_row`. :func:`scatter` samples the
outgoing direction of one interaction exactly (the sampled density equals BSDF * cos / weight)
and returns the factor by which the path weight is multiplied; 0 ends the path (absorbed).

Kinds:

- ``absorber``: absorbs everything.
- ``lambert``: ``albedo``; cosine sampling about the shading normal, weight x albedo.
- ``conductor``: smooth metal with complex index ``eta + i k``; mirror reflection, weight x
  Fresnel reflectance (exact unpolarised form, :mod:`microsim.fresnel`).
- ``interfaced_lambert``: a smooth dielectric interface (index ratio ``eta``) over a Lambertian
  body of albedo ``albedo`` (the flat interfaced Lambertian of
  interfaced_lambertian_microfacets.txt, Eq. 8-10): Fresnel reflection or refraction at the
  interface, then Lambertian bounces in the body with Fresnel (and total internal) reflection
  at the interface from inside until the light leaves. The whole excursion is one interaction.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .fresnel import fresnel_conductor, fresnel_dielectric
from .rng import uniform

ABSORBER = 0
LAMBERT = 1
CONDUCTOR = 2
INTERFACED_LAMBERT = 3
N_PARAMS = 2

#: kind name -> (code, parameter names in row order)
KINDS = {
    "absorber": (ABSORBER, ()),
    "lambert": (LAMBERT, ("albedo",)),
    "conductor": (CONDUCTOR, ("eta", "k")),
    "interfaced_lambert": (INTERFACED_LAMBERT, ("albedo", "eta")),
}

#: cap on the body bounces of one interfaced_lambert interaction; weight left is truncated
MAX_BODY_BOUNCES = 256


def material_row(spec: dict) -> tuple[int, np.ndarray]:
    """(kind code, parameter row) of a validated material dictionary such as {"kind": "lambert", "albedo": 0.8}."""
    code, names = KINDS[spec["kind"]]
    row = np.zeros(N_PARAMS)
    for j, name in enumerate(names):
        row[j] = spec[name]
    return code, row


@numba.njit(cache=True, error_model="numpy", inline="always")
def orthonormal_basis(nx, ny, nz):
    """Two tangents completing the unit normal n (Duff et al. 2017, branchless)."""
    sign = 1.0 if nz >= 0.0 else -1.0
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    return (1.0 + sign * nx * nx * a, sign * b, -sign * nx), (b, sign + ny * ny * a, -ny)


@numba.njit(cache=True, error_model="numpy", inline="always")
def sample_cosine(states, i, nx, ny, nz):
    """Direction about the normal n with density cos(theta) / pi (Malley: a uniform point of the
    unit disk, by rejection from its square, lifted onto the hemisphere; no trigonometry)."""
    while True:
        a = 2.0 * uniform(states, i) - 1.0
        b = 2.0 * uniform(states, i) - 1.0
        r2 = a * a + b * b
        if r2 < 1.0:
            break
    c = math.sqrt(1.0 - r2)
    t, s = orthonormal_basis(nx, ny, nz)
    return (
        a * t[0] + b * s[0] + c * nx,
        a * t[1] + b * s[1] + c * ny,
        a * t[2] + b * s[2] + c * nz,
    )


@numba.njit(cache=True, error_model="numpy", inline="always")
def reflect(dx, dy, dz, nx, ny, nz):
    """Mirror direction of the propagation direction d about n."""
    c = 2.0 * (dx * nx + dy * ny + dz * nz)
    return dx - c * nx, dy - c * ny, dz - c * nz


@numba.njit(cache=True, error_model="numpy")
def scatter(kind, prm, states, i, dx, dy, dz, nx, ny, nz):
    """One interaction: returns (new direction, weight factor, truncated weight fraction).

    ``d`` is the propagation direction of the arriving ray (pointing into the surface) and n
    the outward shading normal. A weight factor of 0 means the path ends.
    """
    if kind == LAMBERT:
        ox, oy, oz = sample_cosine(states, i, nx, ny, nz)
        return ox, oy, oz, prm[0], 0.0
    if kind == CONDUCTOR:
        cos_i = -(dx * nx + dy * ny + dz * nz)
        ox, oy, oz = reflect(dx, dy, dz, nx, ny, nz)
        return ox, oy, oz, fresnel_conductor(cos_i, prm[0], prm[1]), 0.0
    if kind == INTERFACED_LAMBERT:
        return _interfaced_lambert(prm[0], prm[1], states, i, dx, dy, dz, nx, ny, nz)
    return dx, dy, dz, 0.0, 0.0


@numba.njit(cache=True, error_model="numpy")
def _interfaced_lambert(albedo, eta, states, i, dx, dy, dz, nx, ny, nz):
    """Smooth dielectric over a Lambertian body, sampled bounce by bounce (see module doc)."""
    cos_i = -(dx * nx + dy * ny + dz * nz)
    if uniform(states, i) < fresnel_dielectric(cos_i, eta):
        ox, oy, oz = reflect(dx, dy, dz, nx, ny, nz)
        return ox, oy, oz, 1.0, 0.0
    weight = 1.0
    t, s = orthonormal_basis(nx, ny, nz)
    for _ in range(MAX_BODY_BOUNCES):
        weight *= albedo
        if weight == 0.0:
            return dx, dy, dz, 0.0, 0.0
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
            a = sin_o * math.cos(phi)
            b = sin_o * math.sin(phi)
            return (
                a * t[0] + b * s[0] + cos_o * nx,
                a * t[1] + b * s[1] + cos_o * ny,
                a * t[2] + b * s[2] + cos_o * nz,
                weight,
                0.0,
            )
    return dx, dy, dz, 0.0, weight
