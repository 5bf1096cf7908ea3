"""The sensor's lookups in numba: a direction's cell in O(1) (:mod:`microsim.tracer.sensor` says
how the cells are laid out) and its retro ring (:mod:`microsim.tracer.estimators.retro_rings`),
which the exit binning's and the rings' hooks call for every exit. Apart from the sensor's record, so that reading a table
(which rebuilds its sensor) compiles and imports no kernel."""

from __future__ import annotations

import math

import numba
import numpy as np

_INV_TWO_PI = 0.5 / math.pi
#: the largest error of :func:`azimuth`, 2.04e-4 rad (at 45 deg), doubled, as a fraction of a turn
_GUESS_MARGIN = 2.0 * 2.04e-4 * _INV_TWO_PI


@numba.njit(cache=True, error_model="numpy", inline="always")
def cell_index(d, sensor):
    """Cell of the direction d = (x, y, z), z > 0: O(1) (see module docstring)."""
    x, y, z = d
    n = sensor.ring_start[-1]
    slot = int((1.0 - z) * n)
    if slot >= n:
        slot = n - 1
    if slot < 0:
        slot = 0
    k = sensor.ring_of[slot]
    count = sensor.ring_counts[k]
    first = sensor.ring_start[k]
    if count == 1:
        return first
    guess = azimuth(x, y) * (count * _INV_TWO_PI) + 0.5
    j = int(math.floor(guess))
    inside = guess - j  # where d lies in the guessed cell, 0 .. 1 from edge to edge
    if j >= count:
        j -= count
    if j < 0:
        j += count
    c = first + j
    margin = count * _GUESS_MARGIN
    if margin < inside < 1.0 - margin:
        return c  # farther from both edges than the azimuth can be off: no edge test needed
    if sensor.edge_x[c] * y - sensor.edge_y[c] * x < 0.0:
        return c - 1 if j > 0 else first + count - 1
    upper = c + 1 if j + 1 < count else first
    if sensor.edge_x[upper] * y - sensor.edge_y[upper] * x >= 0.0:
        return upper
    return c


@numba.njit(cache=True, error_model="numpy", inline="always")
def retro_ring(d, r):
    """Retro ring of the exit direction d, or -1 outside the rings ``r`` = (wi_x, wi_y, wi_z, chord
    step, ring count) (:mod:`microsim.tracer.estimators.retro_rings`)."""
    # the chord from its components: 2 (1 - d.wi) would turn the ~1e-7 length error of a float32
    # direction into a chord error of sqrt(2e-7) (0.03 deg) near retro
    q = (d[0] - r[0]) ** 2 + (d[1] - r[1]) ** 2 + (d[2] - r[2]) ** 2
    ring = int(math.sqrt(q) / r[3])
    return ring if ring < r[4] else -1


@numba.njit(cache=True, error_model="numpy", inline="always")
def azimuth(x, y):
    """atan2(y, x) within 2.04e-4 rad (a cubic fit of atan on [0, 1], octant folded; the error
    peaks at 45 deg)."""
    ax, ay = abs(x), abs(y)
    big, small = max(ax, ay), min(ax, ay)
    if big == 0.0:
        return 0.0
    a = small / big
    s = a * a
    r = ((-0.0464964749 * s + 0.15931422) * s - 0.327622764) * s * a + a
    if ay > ax:
        r = 0.5 * math.pi - r
    if x < 0.0:
        r = math.pi - r
    return -r if y < 0.0 else r


@numba.njit(cache=True, error_model="numpy")
def cell_indices(w, sensor):
    """The cell of each direction of ``w`` (M, 3), w.z > 0."""
    out = np.empty(w.shape[0], dtype=np.int64)
    for i in range(w.shape[0]):
        out[i] = cell_index((w[i, 0], w[i, 1], w[i, 2]), sensor)
    return out
