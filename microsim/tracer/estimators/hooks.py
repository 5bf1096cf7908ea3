"""The estimators' kernel hooks, called by the walk of every integrator for every estimator of a run.

Each estimator registers its implementations on its ``Record`` class (:class:`microsim.tracer.jit.dispatch.Generic`);
a hook it does not register does nothing and compiles to nothing. The walk calls
:func:`each_exit` and :func:`each_interaction` on the tuple of the run's records and the parallel
tuple of their setups (``Estimator.setup``: what each reads of the incidence), and a backend
that answers visibility later (:mod:`microsim.tracer.integrators.embreex`) :func:`each_seen`; they
call the hook of each record in turn (unrolled when the kernel compiles).
"""

from __future__ import annotations

from microsim.tracer.jit.dispatch import Generic, over_each


def on_exit(record, setup, tally, paths, i, d):
    """Path i of ``paths`` leaves the surface along d (unit, float64): add what it brings to
    ``record`` (row ``tally.row``; albedo scales ``tally.albedo_scale``); ``setup`` is the
    estimator's record for the incidence."""


def on_interaction(record, setup, tally, work, i, world, site):
    """The path of row i of ``work`` (its ``paths``, and its Embree query record where it has
    one) is about to interact, with its weight and order before the interaction: ``site`` =
    (d, state), the direction it arrived along and its integrator's state at the event;
    ``world`` is what its integrator traces, which the queries of next-event estimation take
    (:mod:`microsim.tracer.integrators.walk`); ``setup`` as the exit's."""


def on_seen(record, tally, payload):
    """A shadow ray that the estimator queued with ``payload`` (through
    :func:`microsim.tracer.integrators.walk.see`) reached above the surface unoccluded."""


def _nothing(record, setup, tally, paths, i, d):
    pass


def _nothing_on_interaction(record, setup, tally, work, i, world, site):
    pass


def _nothing_on_seen(record, tally, payload):
    pass


ON_EXIT = Generic(on_exit, default=_nothing)
ON_INTERACTION = Generic(on_interaction, default=_nothing_on_interaction)
ON_SEEN = Generic(on_seen, default=_nothing_on_seen)


def each_exit(records, setups, tally, paths, i, d):
    """:func:`on_exit` of every record of the tuple ``records``, with its setup of ``setups``."""


def each_interaction(records, setups, tally, work, i, world, site):
    """:func:`on_interaction` of every record of the tuple ``records``, with its setup of ``setups``."""


def each_seen(records, tally, payload):
    """:func:`on_seen` of every record of the tuple ``records``."""


over_each(each_exit, on_exit, parallel=2)
over_each(each_interaction, on_interaction, parallel=2)
over_each(each_seen, on_seen)
