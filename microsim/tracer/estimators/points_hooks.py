"""Next-event estimation's kernel hooks (:mod:`microsim.tracer.estimators.points`): a shadow ray
from every scattering event towards every point, and the rays a backend answers later."""

from __future__ import annotations

from microsim.core.orders import ORDERS
from microsim.tracer.estimators.exit_bins_hooks import add_exit
from microsim.tracer.estimators.hooks import ON_INTERACTION, ON_SEEN
from microsim.tracer.estimators.points import PointsTally
from microsim.tracer.integrators import walk


@ON_INTERACTION.register(PointsTally)
def on_interaction(record, setup, tally, work, i, world, site):
    """The event of path i sends a shadow ray towards every point (``setup``: their unit vectors
    about the incidence): w e V into the row of the order its interaction makes (module doc)."""
    points, (d, state) = setup, site
    paths = work.paths
    w, order = paths.weight[i], paths.order[i] + 1
    row = min(order, ORDERS) - 1
    wi = (-d[0], -d[1], -d[2])
    weight = record.weight[tally.row]
    for k in range(len(points)):
        wo = (points[k, 0], points[k, 1], points[k, 2])
        value = walk.evaluate(world, state, wi, wo)
        if value > 0.0:
            seen = walk.see(world, work, i, state, wo, (w * value, k, order))
            if seen > 0.0:
                add_exit(weight, tally.albedo_scale, (row, k), w * value * seen, order)


@ON_SEEN.register(PointsTally)
def on_seen(record, tally, payload):
    """A queued shadow ray towards point k reached the sky: its w e into the row of its order."""
    amount, k, order = payload
    add_exit(record.weight[tally.row], tally.albedo_scale, (min(order, ORDERS) - 1, k), amount, order)
