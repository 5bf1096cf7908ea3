"""Relations of the Boolean (Poisson germ-grain) models that microsim's scenes are built from.

One home for the formulas that a scene generator and the analytic model of the same scene must
share, so that the two can never drift apart (generators, models, benchmarks and tests import
them from here).

Boolean spheres (docs/conventions.md §5.2), radius r = 1, centres a Poisson process of n per unit
volume: a point is in the void when no centre lies within r of it, with probability
exp(-n 4/3 pi) = 1 - phi, so n = -ln(1 - phi) / (4/3 pi); a ray in the void travels an
exponential distance with mean l = 1 / (n pi r^2) = 4 / (-3 ln(1 - phi)) before it meets a
sphere, and r / l = n pi r^2 = -3/4 ln(1 - phi) measures the finite size of the spheres.

Micrograins (conventions §5.3; Lucas et al. 2024, Sec. 4): a Boolean model
of grains on a plane. Half-ellipsoids of vertical semi-axis r_s = 1 and lateral semi-axes
1/beta_x, 1/beta_y have their centres Poisson on the base plane z = 0 with density rho per unit
area; a base point is bare when no centre lies in the ellipse of area pi / (beta_x beta_y)
about it, so the covered fraction is tau0 = 1 - exp(-rho pi / (beta_x beta_y)) (Eq. 8), i.e.
rho = lambda beta_x beta_y / pi with lambda = -ln(1 - tau0) (Eq. 9). The affine map
E = diag(beta_x, beta_y, 1) (Sec. 4.2) turns the grains into unit half-spheres, whose centres
then have density lambda / pi: directions map to w' = E w / |E w|, normals to
m' = E^-1 m / |E^-1 m|, and the grain point of normal m lies at height h' = n . m' (heights
are unchanged by E). The scalar forms are numba kernels (callable from other kernels and from
Python); the ``*_array`` forms apply them to arrays of vectors (..., 3).
"""

from __future__ import annotations

import math

import numba
import numpy as np


def number_density(phi: float) -> float:
    """Sphere centres per unit volume (radius 1): n = -ln(1 - phi) / (4/3 pi)."""
    return -math.log1p(-phi) / (4.0 / 3.0 * math.pi)


def radius_over_free_path(phi: float) -> float:
    """r / l = n pi r^2 = -3/4 ln(1 - phi): the sphere radius in mean void free paths."""
    return -0.75 * math.log1p(-phi)


def free_path(phi: float) -> float:
    """Mean void free path l = 4 / (-3 ln(1 - phi)) in radii (conventions §5.2)."""
    return 1.0 / radius_over_free_path(phi)


@numba.njit(cache=True)
def grain_extinction(tau0):
    """lambda = -ln(1 - tau0) (Eq. 9 with r_s = 1): pi times the grain density in unit space."""
    return -math.log1p(-tau0)


@numba.njit(cache=True)
def grain_density(tau0, beta_x, beta_y):
    """rho = -ln(1 - tau0) beta_x beta_y / pi, grain centres per unit base area (Eq. 9, r_s = 1)."""
    return grain_extinction(tau0) * beta_x * beta_y / math.pi


@numba.njit(cache=True)
def unit_space_direction(wx, wy, wz, beta_x, beta_y):
    """w' = E w / |E w| (Sec. 4.2) of one direction, as a tuple (x, y, z)."""
    vx = beta_x * wx
    vy = beta_y * wy
    norm = math.sqrt(vx * vx + vy * vy + wz * wz)
    return vx / norm, vy / norm, wz / norm


@numba.njit(cache=True)
def unit_space_height(mx, my, mz, beta_x, beta_y):
    """h' = n . m', m' = E^-1 m / |E^-1 m| (Sec. 4.2): the height of the grain point of normal m."""
    vx = mx / beta_x
    vy = my / beta_y
    return mz / math.sqrt(vx * vx + vy * vy + mz * mz)


@numba.njit(cache=True)
def _unit_space_directions(w, beta_x, beta_y):
    out = np.empty_like(w)
    for n in range(w.shape[0]):
        out[n, 0], out[n, 1], out[n, 2] = unit_space_direction(w[n, 0], w[n, 1], w[n, 2], beta_x, beta_y)
    return out


@numba.njit(cache=True)
def _unit_space_heights(m, beta_x, beta_y):
    out = np.empty(m.shape[0])
    for n in range(m.shape[0]):
        out[n] = unit_space_height(m[n, 0], m[n, 1], m[n, 2], beta_x, beta_y)
    return out


def _rows(v) -> np.ndarray:
    """Vectors (..., 3) as a contiguous float64 array (N, 3)."""
    return np.ascontiguousarray(np.asarray(v, dtype=np.float64).reshape(-1, 3))


def unit_space_direction_array(w, beta_x: float, beta_y: float) -> np.ndarray:
    """:func:`unit_space_direction` of directions w (..., 3)."""
    return _unit_space_directions(_rows(w), beta_x, beta_y).reshape(np.shape(w))


def unit_space_height_array(m, beta_x: float, beta_y: float) -> np.ndarray:
    """:func:`unit_space_height` of unit normals m (..., 3)."""
    return _unit_space_heights(_rows(m), beta_x, beta_y).reshape(np.shape(m)[:-1])
