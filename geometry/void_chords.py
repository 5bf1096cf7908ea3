"""Rays through a scene of spheres, in numba: where each first meets a sphere (the void's chords).

A :class:`SphereGrid` lays the spheres on a uniform grid over a box ``lo <= x < lo + sides``,
each axis periodic or not: a cell lists every sphere (or periodic image of one) that reaches into
it, with the image's centre. :func:`first_hits` walks each ray through the cells in order
(Amanatides and Woo's traversal, cell indices unwrapped along periodic axes) and returns the
distance to the first sphere it enters, in float64 with the exact ray-sphere root; ``inf`` if it
meets none before ``t_max`` or leaves the box along an axis that is not periodic. Only entries
from outside count (the smaller root, beyond ``T_MIN``), so a ray that starts on a sphere and
leaves it outward does not meet that sphere again. :func:`covered` says which points lie inside
a sphere other than their own.

Cells are at least a diameter of the largest sphere on a side (``CELL_DIAMETERS``; or the side
the caller gives), and as many as fit, up to ``MAX_CELLS``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

#: a cell's side, at least, in diameters of the largest sphere
CELL_DIAMETERS = 1.0
#: the most cells a grid has (the cells grow past a diameter to keep within it)
MAX_CELLS = 2_000_000
#: hits closer than this to a ray's origin are not hits (a ray that starts on a sphere's surface)
T_MIN = 1e-9


class SphereGrid(NamedTuple):
    """Spheres binned on a grid (module doc). ``entries`` (E, 4): x, y, z, r of each listed image,
    cell by cell (``starts`` (cells + 1,) into it, cells in x-major order) with ``owners`` (E,)
    the sphere each is of."""

    lo: np.ndarray
    sides: np.ndarray
    periodic: np.ndarray
    counts: np.ndarray
    starts: np.ndarray
    entries: np.ndarray
    owners: np.ndarray


def build(centres: np.ndarray, radii: np.ndarray, lo, sides, periodic, cell_side: float | None = None) -> SphereGrid:
    """The grid of the spheres (``centres`` (n, 3), ``radii`` (n,)) over the box ``lo``, ``sides``
    with the axes ``periodic`` (3 bools): every sphere listed in every cell it reaches into, its
    image by the period along a periodic axis (module doc). ``cell_side``: the cells' least side
    (default ``CELL_DIAMETERS`` diameters of the largest sphere)."""
    lo, sides = np.asarray(lo, np.float64), np.asarray(sides, np.float64)
    periodic = np.asarray(periodic, np.bool_)
    centres = np.ascontiguousarray(centres, np.float64)
    radii = np.ascontiguousarray(np.broadcast_to(radii, (len(centres),)), np.float64)
    least = CELL_DIAMETERS * 2.0 * float(radii.max(initial=0.0)) if cell_side is None else cell_side
    size = max(least, 1e-12)
    size = max(size, (float(np.prod(sides)) / MAX_CELLS) ** (1.0 / 3.0))
    counts = np.maximum(1, np.floor(sides / size)).astype(np.int64)
    listed = _count_entries(centres, radii, lo, sides, periodic, counts)
    starts = np.zeros(int(np.prod(counts)) + 1, np.int64)
    np.cumsum(listed, out=starts[1:])
    entries, owners = _fill_entries(centres, radii, lo, sides, periodic, counts, starts)
    return SphereGrid(lo, sides, periodic, counts, starts, entries, owners)


@numba.njit(cache=True)
def _cell_range(c, r, lo, side, periodic, count):
    """The unwrapped cell indices [first, last] along one axis that the interval c +- r reaches."""
    size = side / count
    first = int(math.floor((c - r - lo) / size))
    last = int(math.floor((c + r - lo) / size))
    if not periodic:
        first, last = max(first, 0), min(last, count - 1)
    return first, last


@numba.njit(cache=True)
def _images(centre, r, lo, sides, periodic, counts):
    """(m, 4): each cell the sphere at ``centre`` of radius ``r`` reaches into (its x-major index)
    and the image's centre there (shifted back by the periods the cell's index wrapped)."""
    x0, x1 = _cell_range(centre[0], r, lo[0], sides[0], periodic[0], counts[0])
    y0, y1 = _cell_range(centre[1], r, lo[1], sides[1], periodic[1], counts[1])
    z0, z1 = _cell_range(centre[2], r, lo[2], sides[2], periodic[2], counts[2])
    out = np.empty(((x1 - x0 + 1) * (y1 - y0 + 1) * (z1 - z0 + 1), 4))
    m = 0
    for a in range(x0, x1 + 1):
        for b in range(y0, y1 + 1):
            for k in range(z0, z1 + 1):
                out[m, 0] = ((a % counts[0]) * counts[1] + b % counts[1]) * counts[2] + k % counts[2]
                out[m, 1] = centre[0] - (a // counts[0]) * sides[0]
                out[m, 2] = centre[1] - (b // counts[1]) * sides[1]
                out[m, 3] = centre[2] - (k // counts[2]) * sides[2]
                m += 1
    return out


@numba.njit(cache=True, nogil=True)
def _count_entries(centres, radii, lo, sides, periodic, counts):
    listed = np.zeros(counts[0] * counts[1] * counts[2], np.int64)
    for i in range(len(centres)):
        for image in _images(centres[i], radii[i], lo, sides, periodic, counts):
            listed[int(image[0])] += 1
    return listed


@numba.njit(cache=True, nogil=True)
def _fill_entries(centres, radii, lo, sides, periodic, counts, starts):
    entries = np.empty((starts[-1], 4))
    owners = np.empty(starts[-1], np.int64)
    filled = starts[:-1].copy()
    for i in range(len(centres)):
        for image in _images(centres[i], radii[i], lo, sides, periodic, counts):
            slot = filled[int(image[0])]
            filled[int(image[0])] += 1
            entries[slot, :3] = image[1:]
            entries[slot, 3] = radii[i]
            owners[slot] = i
    return entries, owners


def first_hits(grid: SphereGrid, origins: np.ndarray, directions: np.ndarray, t_max: float) -> np.ndarray:
    """(n,) the distance along each unit ``directions`` row from ``origins`` (inside the box along
    the axes that are not periodic) to the first sphere entered; inf if none before ``t_max``."""
    return _first_hits(_box(grid), _shape(grid), grid.starts, grid.entries, np.ascontiguousarray(origins, np.float64),
                       np.ascontiguousarray(directions, np.float64), float(t_max))


def _box(grid: SphereGrid) -> np.ndarray:
    """(2, 3): the box's lower corner and sides, as the kernels take them."""
    return np.stack([grid.lo, grid.sides])


def _shape(grid: SphereGrid) -> np.ndarray:
    """(2, 3): each axis periodic (1) or not (0), and its cells, as the kernels take them."""
    return np.stack([grid.periodic.astype(np.int64), grid.counts])


@numba.njit(cache=True)
def _first_hits(box, shape, starts, entries, origins, directions, t_max):
    lo, sides, periodic, counts = box[0], box[1], shape[0], shape[1]
    out = np.empty(len(origins))
    size = sides / counts
    index = np.empty(3, np.int64)
    step = np.empty(3, np.int64)
    t_next = np.empty(3)
    t_delta = np.empty(3)
    for n in range(len(origins)):
        p = origins[n] - lo
        d = directions[n]
        for a in range(3):
            index[a] = int(math.floor(p[a] / size[a]))
            if not periodic[a]:
                index[a] = min(max(index[a], 0), counts[a] - 1)
            if d[a] > 0.0:
                step[a] = 1
                t_next[a] = ((index[a] + 1) * size[a] - p[a]) / d[a]
                t_delta[a] = size[a] / d[a]
            elif d[a] < 0.0:
                step[a] = -1
                t_next[a] = (index[a] * size[a] - p[a]) / d[a]
                t_delta[a] = -size[a] / d[a]
            else:
                step[a] = 0
                t_next[a] = np.inf
                t_delta[a] = np.inf
        best = np.inf
        while True:
            cell = 0
            shift = np.zeros(3)
            for a in range(3):
                wrapped = index[a] % counts[a]
                shift[a] = (index[a] // counts[a]) * sides[a]
                cell = cell * counts[a] + wrapped
            for e in range(starts[cell], starts[cell + 1]):
                ox = p[0] - (entries[e, 0] - lo[0] + shift[0])
                oy = p[1] - (entries[e, 1] - lo[1] + shift[1])
                oz = p[2] - (entries[e, 2] - lo[2] + shift[2])
                b = ox * d[0] + oy * d[1] + oz * d[2]
                c = ox * ox + oy * oy + oz * oz - entries[e, 3] * entries[e, 3]
                disc = b * b - c
                if disc > 0.0:
                    t = -b - math.sqrt(disc)
                    if T_MIN < t < best:
                        best = t
            a = 0
            if t_next[1] < t_next[a]:
                a = 1
            if t_next[2] < t_next[a]:
                a = 2
            t_exit = t_next[a]
            if best <= t_exit or t_exit > t_max:
                break
            index[a] += step[a]
            t_next[a] += t_delta[a]
            if not periodic[a] and (index[a] < 0 or index[a] >= counts[a]):
                best = np.inf  # left the box: a sphere met beyond its side is not in it
                break
        out[n] = best if best <= t_max else np.inf
    return out


def covered(grid: SphereGrid, points: np.ndarray, own: np.ndarray) -> np.ndarray:
    """(n,) bool: each of ``points`` lies strictly inside a sphere other than ``own`` (its index)."""
    return _covered(_box(grid), _shape(grid), grid.starts, grid.entries, grid.owners,
                    np.ascontiguousarray(points, np.float64), np.ascontiguousarray(own, np.int64))


@numba.njit(cache=True)
def _covered(box, shape, starts, entries, owners, points, own):
    lo, sides, periodic, counts = box[0], box[1], shape[0], shape[1]
    out = np.zeros(len(points), np.bool_)
    size = sides / counts
    for n in range(len(points)):
        cell = 0
        shift = np.zeros(3)
        inside_box = True
        for a in range(3):
            unwrapped = int(math.floor((points[n, a] - lo[a]) / size[a]))
            if not periodic[a] and (unwrapped < 0 or unwrapped >= counts[a]):
                inside_box = False
            shift[a] = (unwrapped // counts[a]) * sides[a]
            cell = cell * counts[a] + unwrapped % counts[a]
        if not inside_box:
            continue
        for e in range(starts[cell], starts[cell + 1]):
            if owners[e] == own[n]:
                continue
            dx = points[n, 0] - entries[e, 0] - shift[0]
            dy = points[n, 1] - entries[e, 1] - shift[1]
            dz = points[n, 2] - entries[e, 2] - shift[2]
            if dx * dx + dy * dy + dz * dz < entries[e, 3] * entries[e, 3]:
                out[n] = True
                break
    return out
