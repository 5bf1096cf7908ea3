"""What a unit of work produces: the :class:`Tally` of its paths, read by the reducer and the unit store.

Numbers only (no numba, no tracer): the table writer, the unit store and the command line read
these names without importing a tracer.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

#: one albedo: every weight tallied as traced
SINGLE_ALBEDO = np.ones(1)

#: what a batch of paths produced, sums of weights not yet divided by ``paths``:
#: ``estimates``, the record of each of the run's estimators (:mod:`microsim.tracer.estimators`), every
#: array with a leading row axis (the chunks of a workspace; one row in a unit's tally) that
#: kernels index with ``row``; the lost energy (ENERGY_NAMES, after an albedo axis if the run
#: has several albedos) and the event counts (COUNT_NAMES) of the row.
#: Paths are traced at the largest albedo c_max; a weight w after k interactions counts
#: w (c_j / c_max)^k for albedo j (``albedo_scale``), which is exact where every interaction is
#: with one Lambertian material of albedo c_max or absorbs everything (conventions §4).
Tally = namedtuple("Tally", ["paths", "row", "estimates", "energy", "counts", "albedo_scale"])

#: indices of ``Tally.energy``
TRANSMITTED, TRUNCATED, ABSORBED = 0, 1, 2
ENERGY_NAMES = ("transmitted", "truncated", "absorbed")
#: indices of ``Tally.counts``
SEGMENTS, INSIDE_HITS, ROULETTE_KILLS = 0, 1, 2
COUNT_NAMES = ("segments", "inside_hits", "roulette_kills")


def albedo_axis(albedos: int) -> tuple:
    """The albedo axis of a tally's arrays: (albedos,) for a run of several, none for one (so
    that one albedo runs the kernels it ran before albedo lists)."""
    return (albedos,) if albedos > 1 else ()


def empty_tally(paths: int, estimators, albedo_scale=SINGLE_ALBEDO) -> Tally:
    """A zero tally of ``paths`` paths for ``estimators`` (one row each) and these albedos."""
    albedos = len(albedo_scale)
    return Tally(paths, 0, tuple(estimator.allocate(1, albedos) for estimator in estimators),
                 np.zeros((*albedo_axis(albedos), len(ENERGY_NAMES))), np.zeros(len(COUNT_NAMES), np.int64),
                 np.asarray(albedo_scale, np.float64))


def add_rows(total: Tally, estimates, energy, counts, rows: int) -> None:
    """Add rows 0 .. rows-1 of a workspace's ``estimates``, ``energy`` and ``counts`` to ``total``,
    in row order (so that the sum does not depend on which thread traced which row)."""
    for into, source in zip(total.estimates, estimates):
        for field, rows_of in zip(into, source):
            for j in range(rows):
                field[0] += rows_of[j]
    for j in range(rows):
        total.energy[...] += energy[j]
        total.counts[...] += counts[j]


def per_albedo(values: np.ndarray, albedo_rank: int) -> np.ndarray:
    """Tally ``values`` (of rank ``albedo_rank`` without the albedo axis) with the albedo axis
    first, also for a tally of one albedo."""
    return values if values.ndim > albedo_rank else values[None]
