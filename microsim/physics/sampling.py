"""Sampling helpers shared by every integrator and material (numba, on 3-tuples).

Directions and normals are tuples ``(x, y, z)`` of float64; random numbers come from the
counter-keyed stream ``states[i]`` of path ``i`` (:mod:`microsim.physics.rng`).
"""

from __future__ import annotations

import math

import numba

from microsim.physics.rng import uniform


@numba.njit(cache=True, error_model="numpy", inline="always")
def orthonormal_basis(n):
    """Two tangents completing the unit normal n (Duff et al. 2017, branchless)."""
    nx, ny, nz = n
    sign = 1.0 if nz >= 0.0 else -1.0
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    return (1.0 + sign * nx * nx * a, sign * b, -sign * nx), (b, sign + ny * ny * a, -ny)


@numba.njit(cache=True, error_model="numpy", inline="always")
def from_local(a, b, c, n):
    """The direction a t + b s + c n, with (t, s) the :func:`orthonormal_basis` of n."""
    t, s = orthonormal_basis(n)
    return (
        a * t[0] + b * s[0] + c * n[0],
        a * t[1] + b * s[1] + c * n[1],
        a * t[2] + b * s[2] + c * n[2],
    )


@numba.njit(cache=True, error_model="numpy", inline="always")
def sample_cosine(states, i, n):
    """Direction about the unit normal n with density cos(theta) / pi (Malley: a uniform point
    of the unit disk, by rejection from its square, lifted onto the hemisphere; no trigonometry)."""
    while True:
        a = 2.0 * uniform(states, i) - 1.0
        b = 2.0 * uniform(states, i) - 1.0
        r2 = a * a + b * b
        if r2 < 1.0:
            break
    return from_local(a, b, math.sqrt(1.0 - r2), n)


@numba.njit(cache=True, error_model="numpy", inline="always")
def reflect(d, n):
    """Mirror direction of the propagation direction d about the unit normal n."""
    c = 2.0 * (d[0] * n[0] + d[1] * n[1] + d[2] * n[2])
    return d[0] - c * n[0], d[1] - c * n[1], d[2] - c * n[2]
