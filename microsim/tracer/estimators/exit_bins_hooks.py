"""The exit binning's kernel hooks (:mod:`microsim.tracer.estimators.exit_bins`): every path that
leaves adds its weight to its sensor cell and retro ring, by order."""

from __future__ import annotations

import numba

from microsim.core.orders import ORDERS
from microsim.tracer.estimators.exit_bins import BASE_ROW, ExitBinsTally
from microsim.tracer.estimators.hooks import ON_EXIT
from microsim.tracer.sensor_kernels import cell_index, retro_ring


@ON_EXIT.register(ExitBinsTally)
def on_exit(record, tally, paths, i, d, sensor):
    """Path i leaves along d: its weight goes to d's sensor cell, in the row of its order (and in
    BASE_ROW too if its one interaction was with the base plane); and likewise to d's retro ring,
    if the sensor has retro rings and d falls in one (bins after the cells)."""
    order = paths.order[i]
    row, from_base = min(order, ORDERS) - 1, order == 1 and paths.from_base[i]
    weight = record.weight[tally.row]
    cell = cell_index(d, sensor)
    add_exit(weight, tally.albedo_scale, (row, cell), paths.weight[i], order)
    if from_base:
        add_exit(weight, tally.albedo_scale, (BASE_ROW, cell), paths.weight[i], order)
    if sensor.retro[4] > 0.0:
        ring = retro_ring(d, sensor)
        if ring >= 0:
            slot = sensor.ring_start[-1] + ring
            add_exit(weight, tally.albedo_scale, (row, slot), paths.weight[i], order)
            if from_base:
                add_exit(weight, tally.albedo_scale, (BASE_ROW, slot), paths.weight[i], order)


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
