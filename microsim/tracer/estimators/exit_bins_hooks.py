"""The exit binning's kernel hook (:mod:`microsim.tracer.estimators.exit_bins`): every path that
leaves adds its weight to its sensor cell, by order."""

from __future__ import annotations

import numba

from microsim.core.orders import ORDERS
from microsim.tracer.estimators.exit_bins import BASE_ROW, ExitBinsTally
from microsim.tracer.estimators.hooks import ON_EXIT
from microsim.tracer.sensor_kernels import cell_index


@ON_EXIT.register(ExitBinsTally)
def on_exit(record, setup, tally, paths, i, d):
    """Path i leaves along d: its weight goes to d's cell of the sensor (``setup``), in the row of
    its order (and in BASE_ROW too if its one interaction was with the base plane)."""
    sensor, order = setup, paths.order[i]
    weight = record.weight[tally.row]
    cell = cell_index(d, sensor)
    add_exit(weight, tally.albedo_scale, (min(order, ORDERS) - 1, cell), paths.weight[i], order)
    if order == 1 and paths.from_base[i]:
        add_exit(weight, tally.albedo_scale, (BASE_ROW, cell), paths.weight[i], order)


@numba.njit(cache=True, error_model="numpy", _nrt=False)
def add_exit(weight, scale, bin_, w, order):
    """weight[row, cell] += w for ``bin_`` = (row, cell); with an albedo axis,
    weight[j, row, cell] += w scale[j]^order for each albedo j (:class:`microsim.core.tally.Tally`).
    numba compiles each rank apart and resolves the branch on ndim at compile time, so one
    albedo runs the code it ran before albedo lists. Not inlined by numba; LLVM inlines it."""
    row, cell = bin_
    if weight.ndim == 2:
        weight[row, cell] += w
    else:
        for j in range(len(scale)):
            weight[j, row, cell] += w * scale[j] ** order
