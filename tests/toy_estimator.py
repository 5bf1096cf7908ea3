"""A toy estimator, the example of ``microsim.tracer.estimators``: the fraction of paths that leave after
each number of interactions (1, 2, 3, 4+), whatever their weight. tests/test_estimators.py
registers it; it shows what a new estimator costs (this module and one registration)."""

from typing import NamedTuple

import numba
import numpy as np

from microsim.core.orders import ORDERS
from microsim.tracer.estimators import Estimator
from microsim.tracer.estimators.hooks import ON_EXIT


class ExitCountsTally(NamedTuple):
    count: np.ndarray  # paths that left, by order


class ExitCounts(Estimator):
    name = "exit_counts"
    Record = ExitCountsTally

    def shapes(self):
        return ((ORDERS,),)

    def estimate_values(self):
        return ORDERS

    def reduce(self, fields, paths, incidence):
        return {"exit_fraction_order": fields.count / paths}

    def write(self, put, estimates):
        put("exit_fraction_order", np.stack([e.mean for e in estimates["exit_fraction_order"]]))
        put("exit_fraction_order_stderr", np.stack([e.stderr for e in estimates["exit_fraction_order"]]))


@ON_EXIT.register(ExitCountsTally)
def on_exit(record, tally, paths, i, d, sensor):
    add_one(record.count[tally.row], min(paths.order[i], ORDERS) - 1)


@numba.njit(cache=True, error_model="numpy", _nrt=False)
def add_one(count, order):
    """count[order] += 1, for each albedo of a run of several (the branch on ndim is resolved
    when numba compiles, for an argument)."""
    if count.ndim == 1:
        count[order] += 1.0
    else:
        for j in range(count.shape[0]):
            count[j, order] += 1.0
