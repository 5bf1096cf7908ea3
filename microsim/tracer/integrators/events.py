"""Per-path events that every integrator shares (numba kernels inlined into each tracer's loop).

A path ``i`` is a row of a :class:`~microsim.tracer.integrators.records.Paths` bundle; the kernels
update it and the batch's :class:`~microsim.core.tally.Tally` in place:

- :func:`begin_path`: a path's starting state;
- :func:`cut_at_max_order`: before an interaction, a path that has had ``max_order`` of them
  is truncated;
- :func:`interacted`: the bookkeeping of an interaction, the same whatever scattered the path (a
  surface's material, a medium's phase function): the weight the interaction did not keep is
  tallied as absorbed or truncated, the weight multiplied, the order counted; then
  :func:`survives_interaction`: the path ends if it has no weight left, is truncated at
  ``MAX_INTERACTIONS`` (its weight reported, never dropped), and plays Russian roulette below
  ``ROULETTE_WEIGHT`` (unbiased: survivors carry ROULETTE_WEIGHT);
- :func:`idled`: a segment without an interaction (a tile side crossed, a face passed through);
  a path idle for ``MAX_IDLE_SEGMENTS`` segments is truncated;
- :func:`truncate`: the weight of a path cut short is reported as truncated;
- :func:`move_path`: compaction of the live paths, every field of ``Paths`` at once.
"""

from __future__ import annotations

import numba
from numba import literal_unroll

from microsim.core.tally import ABSORBED, ROULETTE_KILLS, TRUNCATED
from microsim.physics.rng import path_state, uniform

#: Russian roulette: a path whose weight falls below this survives with probability weight / ROULETTE_WEIGHT
ROULETTE_WEIGHT = 0.05
#: a path scattered this many times is truncated (its weight is reported, never dropped)
MAX_INTERACTIONS = 100_000
#: a path that goes this many segments without an interaction (tile-side crossings, pass-throughs)
#: is truncated: only a ray parallel to the surface in empty space could get there
MAX_IDLE_SEGMENTS = 20_000


@numba.njit(cache=True, error_model="numpy", inline="always")
def begin_path(paths, i, number, key):
    """Row i holds path ``number`` of the stream ``key`` from now on: its random state, weight 1,
    no interaction yet (every field of records.PATH_FIELDS starts here)."""
    paths.rng[i] = path_state(key, number)
    paths.weight[i] = 1.0
    paths.order[i] = 0
    paths.idle[i] = 0
    paths.from_base[i] = 0


@numba.njit(cache=True, error_model="numpy", inline="always")
def add_lost(tally, kind, w, order):
    """Weight w of a path after ``order`` interactions into the lost energy ``kind`` (an index of
    ENERGY_NAMES), for every albedo of the tally."""
    _add_lost(tally.energy, tally.albedo_scale, kind, w, order)


@numba.njit(cache=True, error_model="numpy", inline="always")
def add_interaction(tally, w, order, factor, cut):
    """What a path of weight w after ``order`` interactions loses in one more: absorbed
    1 - factor - cut of it, truncated ``cut``; for albedo j the factor is factor c_j / c_max
    (an interaction keeps c_max or nothing, see :class:`~microsim.core.tally.Tally`)."""
    _add_interaction(tally.energy, tally.albedo_scale, w, order, factor, cut)


@numba.njit(cache=True, error_model="numpy", _nrt=False)
def _add_lost(energy, scale, kind, w, order):
    """:func:`add_lost` on the energy array: energy[kind] += w; with an albedo axis,
    energy[j, kind] += w scale[j]^order for each albedo j. numba compiles each rank apart and
    resolves the branch on ndim at compile time. Not inlined by numba; LLVM inlines it."""
    if energy.ndim == 1:
        energy[kind] += w
    else:
        for j in range(len(scale)):
            energy[j, kind] += w * scale[j] ** order


@numba.njit(cache=True, error_model="numpy", _nrt=False)
def _add_interaction(energy, scale, w, order, factor, cut):
    """:func:`add_interaction` on the energy array (the ranks as in :func:`_add_lost`)."""
    if energy.ndim == 1:
        energy[ABSORBED] += w * (1.0 - factor - cut)
        energy[TRUNCATED] += w * cut
    else:
        for j in range(len(scale)):
            weight = w * scale[j] ** order
            energy[j, ABSORBED] += weight * (1.0 - factor * scale[j] - cut)
            energy[j, TRUNCATED] += weight * cut


@numba.njit(cache=True, error_model="numpy", inline="always")
def truncate(paths, i, tally):
    add_lost(tally, TRUNCATED, paths.weight[i], paths.order[i])


@numba.njit(cache=True, error_model="numpy", inline="always")
def cut_at_max_order(paths, i, max_order, tally):
    """Whether path i, about to interact, has had its ``max_order`` interactions (0: no cap);
    its weight is then truncated."""
    if max_order > 0 and paths.order[i] >= max_order:
        truncate(paths, i, tally)
        return True
    return False


@numba.njit(cache=True, error_model="numpy", inline="always")
def interacted(paths, i, factor, cut, tally):
    """Path i interacted, keeping ``factor`` of its weight (a fraction ``cut`` of it cut short):
    the bookkeeping of every integrator's interactions (module doc). Returns whether it goes on."""
    w = paths.weight[i]
    add_interaction(tally, w, paths.order[i], factor, cut)
    paths.weight[i] = w * factor
    paths.order[i] += 1
    return survives_interaction(paths, i, tally)


@numba.njit(cache=True, error_model="numpy", inline="always")
def idled(paths, i, tally):
    """Path i went a segment without an interaction. Returns whether it has gone
    MAX_IDLE_SEGMENTS of them, and was truncated."""
    paths.idle[i] += 1
    if paths.idle[i] >= MAX_IDLE_SEGMENTS:
        truncate(paths, i, tally)
        return True
    return False


@numba.njit(cache=True, error_model="numpy", inline="always")
def survives_interaction(paths, i, tally):
    """Whether path i goes on after an interaction that set its weight and order (see module doc)."""
    w = paths.weight[i]
    if w <= 0.0:
        return False
    if paths.order[i] >= MAX_INTERACTIONS:
        truncate(paths, i, tally)
        return False
    if w < ROULETTE_WEIGHT:
        if uniform(paths.rng, i) * ROULETTE_WEIGHT < w:
            paths.weight[i] = ROULETTE_WEIGHT
        else:
            tally.counts[ROULETTE_KILLS] += 1
            return False
    return True


@numba.njit(cache=True, error_model="numpy", _nrt=False)
def move_path(paths, to, source):
    """Copy every field of path ``source`` to row ``to`` (compaction of the live paths).

    Not inlined by numba (literal_unroll does not survive its IR inlining); LLVM inlines it."""
    for field in literal_unroll(paths):
        field[to] = field[source]
