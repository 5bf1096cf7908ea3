"""Named records of the tracer's state: structure-of-arrays bundles that numba kernels take.

As pbrt-v4's wavefront work items and MCDC's records do, each bundle is a namedtuple of arrays
(numba compiles a field access to a struct member, and can cache the kernels that take them
because the classes live in this importable module). Kernels take a few bundles and a row
index instead of dozens of arrays. A new per-path field is one entry of ``PATH_FIELDS``: it is
allocated with the others and, on the embreex backend, carried along when live paths are
compacted (:func:`microsim.integrators.events.move_path`); no kernel signature changes. Its
starting value is set where a path starts (``events.begin_path``), its updates where it
changes.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

#: orders tallied separately: 1, 2, 3 and 4+ (CONVENTIONS 2)
ORDERS = 4
#: the row of ``Tally.exit_weight`` after the orders: order-1 exits scattered by the base plane
#: (CONVENTIONS 6, ``brdf_order1_base``); rows 0 .. ORDERS-1 are the orders, all surfaces
BASE_ROW = ORDERS
TALLY_ROWS = ORDERS + 1
#: rows of a run's per-incidence BRDF and albedo estimates (``runner.Result``) after the orders:
#: all orders, order 1 scattered by the base, and orders 1 and 2 together (the f2 of
#: interfaced_lambertian_microfacets.txt Sec. 3.3, with a standard error of its own: the two
#: orders of a realization are correlated)
RESULT_ALL_ORDERS, RESULT_ORDER1_BASE, RESULT_ORDERS12 = ORDERS, ORDERS + 1, ORDERS + 2
RESULT_ROWS = ORDERS + 3

#: what a path carries from segment to segment: name -> dtype (one row per path)
PATH_FIELDS = {
    "weight": np.float64,
    "order": np.int32,  # interactions so far
    "idle": np.int32,  # segments since the last interaction (side wraps, pass-throughs)
    "rng": np.uint64,  # state of the path's random stream (microsim.physics.rng)
    "from_base": np.int8,  # 1 if the first interaction was with the scene's base plane
}
Paths = namedtuple("Paths", PATH_FIELDS)

#: the segment each live path traces next, in float32 as Embree takes it: origin and direction
#: (n, 3), the distance ``tfar`` to the end of the segment, and which boundary ends it (``end``)
Rays = namedtuple("Rays", ["origin", "direction", "tfar", "end"])

#: one albedo: every weight tallied as traced
SINGLE_ALBEDO = np.ones(1)

#: the paths of one unit of work: incidence direction wi (float64 (3,)), random stream key
#: (uint64), number of paths, max_order (0: unlimited), and the albedo scales c_j / c_max of a
#: run of several albedos (float64 (A,); SINGLE_ALBEDO otherwise; see :class:`Tally`)
Beam = namedtuple("Beam", ["wi", "key", "n_paths", "max_order", "albedo_scale"], defaults=(SINGLE_ALBEDO,))

#: what a batch of paths produced, sums of weights not yet divided by ``paths``, for each of the
#: A albedos of the run: exits per order and sensor cell, then order 1 from the base alone
#: (A, TALLY_ROWS, bins), the bins being the sensor's cells and then its retro rings
#: (``Sensor.tally_width``); lost energy (A, ENERGY_NAMES); and event counts (COUNT_NAMES). A
#: tally of one albedo has no albedo axis ((TALLY_ROWS, bins) and (ENERGY_NAMES,)).
#: Paths are traced at the largest albedo c_max; a weight w after k interactions counts
#: w (c_j / c_max)^k for albedo j (``albedo_scale``), which is exact where every interaction is
#: with one Lambertian material of albedo c_max or absorbs everything (CONVENTIONS 4).
Tally = namedtuple("Tally", ["paths", "exit_weight", "energy", "counts", "albedo_scale"], defaults=(SINGLE_ALBEDO,))

#: indices of ``Tally.energy``
TRANSMITTED, TRUNCATED, ABSORBED = 0, 1, 2
ENERGY_NAMES = ("transmitted", "truncated", "absorbed")
#: indices of ``Tally.counts``
SEGMENTS, INSIDE_HITS, ROULETTE_KILLS = 0, 1, 2
COUNT_NAMES = ("segments", "inside_hits", "roulette_kills")


def allocate_paths(n: int) -> Paths:
    return Paths(*(np.empty(n, dtype) for dtype in PATH_FIELDS.values()))


def allocate_rays(n: int) -> Rays:
    return Rays(np.empty((n, 3), np.float32), np.empty((n, 3), np.float32), np.empty(n, np.float32),
                np.empty(n, np.int8))


def empty_tally(paths: int, width: int, albedo_scale=SINGLE_ALBEDO) -> Tally:
    axis = (len(albedo_scale),) if len(albedo_scale) > 1 else ()
    return Tally(paths, np.zeros((*axis, TALLY_ROWS, width)), np.zeros((*axis, len(ENERGY_NAMES))),
                 np.zeros(len(COUNT_NAMES), np.int64), np.asarray(albedo_scale, np.float64))


def per_albedo(values: np.ndarray, albedo_rank: int) -> np.ndarray:
    """Tally ``values`` (exit_weight: rank 2, energy: rank 1, without the albedo axis) with the
    albedo axis first, also for a tally of one albedo."""
    return values if values.ndim > albedo_rank else values[None]
