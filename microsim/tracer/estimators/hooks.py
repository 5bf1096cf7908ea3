"""The estimators' kernel hooks, called by the walk of every integrator for every estimator of a run.

Each estimator registers its implementations on its ``Record`` class (:class:`microsim.tracer.jit.dispatch.Generic`);
a hook it does not register does nothing and compiles to nothing. The walk calls
:func:`each_exit` and :func:`each_interaction` on the tuple of the run's records, and a backend
that answers visibility later (:mod:`microsim.tracer.integrators.embreex`) :func:`each_seen`; they call
the hook of each record in turn (unrolled when the kernel compiles).
"""

from __future__ import annotations

from microsim.tracer.jit.dispatch import Generic, over_each


def on_exit(record, tally, paths, i, d, sensor):
    """Path i of ``paths`` leaves the surface along d (unit, float64): add what it brings to
    ``record`` (row ``tally.row``; albedo scales ``tally.albedo_scale``)."""


def on_interaction(record, tally, work, i, world, site, sensor):
    """The path of row i of ``work`` (its ``paths``, and its Embree query record where it has
    one) is about to interact, with its weight and order before the interaction: ``site`` =
    (d, state), the direction it arrived along and its integrator's state at the event;
    ``world`` is what its integrator traces, which the queries of next-event estimation take
    (:mod:`microsim.tracer.integrators.walk`); ``sensor`` as the exit's."""


def on_seen(record, tally, payload):
    """A shadow ray that the estimator queued with ``payload`` (through
    :func:`microsim.tracer.integrators.walk.see`) reached above the surface unoccluded."""


def _nothing(record, tally, paths, i, d, sensor):
    pass


def _nothing_on_interaction(record, tally, work, i, world, site, sensor):
    pass


def _nothing_on_seen(record, tally, payload):
    pass


ON_EXIT = Generic(on_exit, default=_nothing)
ON_INTERACTION = Generic(on_interaction, default=_nothing_on_interaction)
ON_SEEN = Generic(on_seen, default=_nothing_on_seen)


def each_exit(records, tally, paths, i, d, sensor):
    """:func:`on_exit` of every record of the tuple ``records``."""


def each_interaction(records, tally, work, i, world, site, sensor):
    """:func:`on_interaction` of every record of the tuple ``records``."""


def each_seen(records, tally, payload):
    """:func:`on_seen` of every record of the tuple ``records``."""


over_each(each_exit, on_exit)
over_each(each_interaction, on_interaction)
over_each(each_seen, on_seen)
