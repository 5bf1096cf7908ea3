"""The path walk every integrator shares: one handling of each event, and one path loop.

An integrator is a transport: what its kernels trace is a *world* (a record of its own: the
scene's arrays and Embree scene; the grooves' law; the medium), and it provides three numba
functions of it, with these signatures. A path is ``(d, state)``: its direction of travel
(float64, unit) and the integrator's own state (a point, a groove's frame, a depth, ...; any
tuple of one type).

- ``start(world, work, i, number, beam) -> (d, state)``: path ``number`` of the beam begins in
  row i (``events.begin_path``, then the integrator's own start: a point of the tile, a groove,
  the surface of the medium);
- ``next_event(world, work, i, path, tally) -> (kind, d, state)``: trace the path to its next
  event (an Embree query, the analytic groove, a free flight), counting its segments in
  ``tally.counts[SEGMENTS]``; kind is one of INTERACTION, EXIT, TRANSMISSION, STOP, IDLE;
- ``interact(world, paths, i, path) -> (d, factor, cut, state)``: the interaction there: the new
  direction, the weight factor kept and the fraction cut (as :func:`microsim.tracer.materials.scatter`
  returns them), and the state the path leaves with (off the surface, ...);

and, registered on its world's class, the two queries of next-event estimation
(:mod:`microsim.tracer.estimators.points`): :data:`EVALUATE`, ``evaluate(world, state, wi, wo)``, what
the interaction at ``state`` sends from wi into wo per steradian, f(wi, wo) |n . wo| without the
delta lobes (a surface's material, :func:`microsim.tracer.materials.evaluate`; c p for a point
scatterer of the medium); and :data:`VISIBILITY`, ``visibility(world, work, i, state, wo)``: the
transmittance from the point of an interaction along wo to above the surface (Embree's occluded
query through the periodic tile, the analytic groove, exp(-tau) in the medium), which
estimators ask through :data:`SEE`, ``see(world, work, i, state, wo, payload)``: the embreex
backend, which queries Embree a segment of every path at a time from Python, cannot answer at
once; it queues the shadow ray and hands ``payload`` back to the estimators when the ray is seen
(:mod:`.embreex`). An estimator's ``on_interaction`` hook gets the world and the workspace (row
i's query record is free during the event) and calls them; they are dispatched by the world's
type (:mod:`microsim.tracer.jit.dispatch`). The Embree intersector of the V-cavities logs its visibility
queries with its others when a ray log is kept.

:func:`take_event` then does, once for every integrator, what an event means: an exit goes to
every estimator (:func:`microsim.tracer.estimators.hooks.each_exit`); transmission and truncation are
tallied as lost; a segment without an interaction counts as idle; an interaction is cut at
``max_order``, shown to every estimator (``each_interaction``), made, and booked
(:func:`microsim.tracer.integrators.events.interacted`: weight, order, roulette, truncation).
:func:`walk` is the loop of a path traced alone, from start to end, and :func:`trace_chunks`
traces the chunks of a scheduler's share (:mod:`.scheduler`) with it: the V-cavity and medium
integrators. The surface integrator drives the same :func:`take_event` from its two Embree
backends, whose loops are not one path at a time: :mod:`.direct` interleaves two paths so that
the processor overlaps their work, :mod:`.embreex` advances every live path a segment per
embreex call (why each: their module docstrings).

The transport's functions are arguments, and every function here is inlined by numba: an
integrator's kernel names its own functions (module globals), so numba inlines them where
they are called, and the walk runs the machine code of a loop written for that integrator.
The walk does not dispatch by the world's type (:mod:`microsim.tracer.jit.dispatch`): that
compiles each function apart, and its calls are not inlined.

(measurements of this walk and of the designs tried: docs/developer/performance.md, section
'One walk, estimators and dispatch')
"""

from __future__ import annotations

import numba

from microsim.core.tally import TRANSMITTED
from microsim.tracer.estimators.hooks import each_exit, each_interaction
from microsim.tracer.integrators.events import add_lost, cut_at_max_order, idled, interacted, truncate
from microsim.tracer.integrators.scheduler import CHUNK_PATHS, ROW_STRIDE, chunk_tally
from microsim.tracer.jit.dispatch import Generic

#: kinds of event (a transport's ``next_event``): the path scatters; leaves through the top;
#: leaves through the bottom; is stopped where it can go nowhere (truncated); or went a segment
#: without an interaction (a tile side crossed, a face passed through)
INTERACTION, EXIT, TRANSMISSION, STOP, IDLE = 0, 1, 2, 3, 4


def visibility(world, work, i, state, wo):
    """The transmittance from the interaction at ``state`` (the state of row i's path there) along
    the unit direction wo out of the surface: 1 or 0 (unoccluded or not) on a surface, exp(-tau)
    in a medium; 0 for wo below the surface at the point. Row i of ``work`` holds the query."""


VISIBILITY = Generic(visibility)


def see(world, work, i, state, wo, payload):
    """:func:`visibility` now, for a world that answers it at once (the default); a world that
    cannot (the embreex backend, which calls Embree from Python) queues the shadow ray with
    ``payload`` and returns 0, and hands the payload to every estimator
    (:func:`microsim.tracer.estimators.hooks.each_seen`) once the ray has reached above the surface."""


def _see_now(world, work, i, state, wo, payload):
    return visibility(world, work, i, state, wo)


SEE = Generic(see, default=_see_now)


def evaluate(world, state, wi, wo):
    """f(wi, wo) |n . wo| of the interaction at ``state`` without its delta lobes, per steradian
    of wo (wi = -d, towards where the light came from; both unit); c p(-wi . wo) for a point
    scatterer of albedo c and phase function p."""


EVALUATE = Generic(evaluate)


@numba.njit(cache=True, error_model="numpy", inline="always")
def take_event(world, work, i, event, max_order, setups, tally, interact):
    """Row i of ``work`` met ``event`` = (kind, d, state): take it through it (module doc);
    ``interact`` is the transport's (any kind not named is an interaction). Returns (alive, d,
    state) of the path after it."""
    kind, d, state = event
    paths = work.paths
    if kind == EXIT:
        each_exit(tally.estimates, setups, tally, paths, i, d)
        return False, d, state
    if kind == TRANSMISSION:
        add_lost(tally, TRANSMITTED, paths.weight[i], paths.order[i])
        return False, d, state
    if kind == STOP:
        truncate(paths, i, tally)
        return False, d, state
    if kind == IDLE:
        return not idled(paths, i, tally), d, state
    if cut_at_max_order(paths, i, max_order, tally):
        return False, d, state
    each_interaction(tally.estimates, setups, tally, work, i, world, (d, state))
    wo, factor, cut, leaving = interact(world, paths, i, (d, state))
    return interacted(paths, i, factor, cut, tally), wo, leaving


@numba.njit(cache=True, error_model="numpy", inline="always")
def walk(row, beam, world, setups, tally, start, next_event, interact):
    """Path ``number`` of the beam, in row i of ``work`` (``row`` = (work, i, number)), from its
    start until it leaves, is absorbed or is truncated, by the transport (start, next_event,
    interact)."""
    work, i, number = row
    path = start(world, work, i, number, beam)
    while True:
        event = next_event(world, work, i, path, tally)
        alive, d, state = take_event(world, work, i, event, beam.max_order, setups, tally, interact)
        if not alive:
            return
        path = (d, state)


@numba.njit(cache=True, error_model="numpy", inline="always")
def trace_chunks(share, beam, world, setups, work, start, next_event, interact):
    """Chunks first+a .. first+b-1 of the beam (``share`` = (first, a, b)), chunk first+j into tally
    row j, its paths one after the other in path row ROW_STRIDE j (:func:`walk`)."""
    first, a, b = share
    for j in range(a, b):
        tally = chunk_tally(work, j, beam)
        chunk = first + j
        for number in range(chunk * CHUNK_PATHS, min((chunk + 1) * CHUNK_PATHS, beam.n_paths)):
            walk((work, ROW_STRIDE * j, number), beam, world, setups, tally, start, next_event, interact)
