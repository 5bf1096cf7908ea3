"""The retro rings' kernel hook (:mod:`microsim.tracer.estimators.retro_rings`): a path that leaves
near the retro direction adds its weight to its ring, by order."""

from __future__ import annotations

from microsim.core.orders import ORDERS
from microsim.tracer.estimators.exit_bins_hooks import add_exit
from microsim.tracer.estimators.hooks import ON_EXIT
from microsim.tracer.estimators.retro_rings import RetroRingsTally
from microsim.tracer.sensor_kernels import retro_ring


@ON_EXIT.register(RetroRingsTally)
def on_exit(record, setup, tally, paths, i, d):
    """Path i leaves along d: its weight goes to d's ring about the retro direction (``setup``:
    :meth:`RetroRings.about`), if d falls in one, in the row of its order."""
    rings = setup
    if rings[4] > 0.0:
        ring = retro_ring(d, rings)
        if ring >= 0:
            order = paths.order[i]
            add_exit(record.weight[tally.row], tally.albedo_scale, (min(order, ORDERS) - 1, ring), paths.weight[i],
                     order)
