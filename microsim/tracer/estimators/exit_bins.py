"""The exit binning: every path that leaves adds its weight to the sensor cell it leaves through.

The estimator of docs/conventions.md §2: a beam of unit irradiance, N paths; a path leaving along d
with weight w adds w / (N x the projected solid angle of d's cell) to the cell average of the
BRDF, by scattering order (1, 2, 3, 4+), all orders, order 1 scattered by the base plane
(conventions §6, ``brdf_order1_base``) and orders 1 and 2 together (``brdf_orders12``). The
albedos are the sums over the cells. ``compare`` and ``fit`` judge the cells by default
(:mod:`microsim.analysis.compare`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from microsim.core.orders import ORDERS, RESULT_ALL_ORDERS, RESULT_ORDER1_BASE, RESULT_ORDERS12, RESULT_ROWS
from microsim.core.table_layout import Dataset
from microsim.tracer.estimators import Estimator

#: datasets that tables of format 1.0 may lack (they came while 1.0 was written): their ``since``
SINCE = {name: "1.1" for name in ("brdf_orders12", "brdf_order1_base", "albedo_orders12", "albedo_order1_base")}
#: the row of the tally after the orders: order-1 exits scattered by the base plane
BASE_ROW = ORDERS
TALLY_ROWS = ORDERS + 1


class ExitBinsTally(NamedTuple):
    """Exit weights (rows: the orders, then order 1 from the base; columns: the sensor's cells)."""

    weight: np.ndarray


class ExitBins(Estimator):
    """The exit binning (module doc): datasets brdf*, albedo* (conventions §6)."""

    name = "exit_bins"
    Record = ExitBinsTally
    HOOKS = "microsim.tracer.estimators.exit_bins_hooks"
    JUDGE = "microsim.analysis.compare:CELLS"
    DATASETS = tuple(
        dataset
        for name, axes, unit, doc, when, required in (
            ("brdf", ("incidences", "cells"), "1/sr", "f_C = E_C / P_C: the BRDF averaged over each cell, "
             "cos-weighted, all orders", "always", True),
            ("brdf_order", ("incidences", "orders", "cells"), "1/sr", "f_C by scattering order 1, 2, 3, 4+ (they "
             "sum to brdf)", "always", True),
            ("brdf_orders12", ("incidences", "cells"), "1/sr", "orders 1 and 2 together (the f2 of two-bounce "
             "models)", "always", False),
            ("brdf_order1_base", ("incidences", "cells"), "1/sr", "the part of order 1 that the base plane scattered",
             "scenes with a base", False),
            ("albedo", ("incidences",), "", "directional albedo: the energy that left through the top", "always",
             True),
            ("albedo_order", ("incidences", "orders"), "", "albedo by scattering order", "always", True),
            ("albedo_orders12", ("incidences",), "", "albedo of orders 1 and 2 together", "always", False),
            ("albedo_order1_base", ("incidences",), "", "albedo of the base's part of order 1", "scenes with a base",
             False),
        )
        for dataset in (
            Dataset(name, axes, unit, doc, when=when, required=required, since=SINCE.get(name, "1.0")),
            Dataset(f"{name}_stderr", axes, unit, f"standard error of {name}, from the spread of the realizations",
                    when=when, required=required, since=SINCE.get(name, "1.0")),
        )
    )

    def setup(self, wi, phi_i):
        return self.sensor

    def shapes(self):
        return ((TALLY_ROWS, self.sensor.n_cells),)

    def reduce(self, fields, paths, incidence):
        per_path = fields.weight / paths
        bins = np.vstack([per_path[:ORDERS], per_path[:ORDERS].sum(axis=0), per_path[BASE_ROW],
                          per_path[0] + per_path[1]])
        return {"brdf": bins / self.sensor.projected_solid_angle(), "albedo": bins.sum(axis=1)}

    def estimate_values(self):
        return RESULT_ROWS * (self.sensor.n_cells + 1)  # brdf rows, and albedo

    def exited(self, estimates):
        return estimates["albedo"][RESULT_ALL_ORDERS]

    def write(self, put, estimates):
        rows = {"": RESULT_ALL_ORDERS, "_order": slice(0, ORDERS), "_orders12": RESULT_ORDERS12}
        if self.plan.scene.get("base", "none") != "none":
            rows["_order1_base"] = RESULT_ORDER1_BASE
        for name in ("brdf", "albedo"):
            for suffix, row in rows.items():
                put(name + suffix, np.stack([e.mean[row] for e in estimates[name]]))
                put(f"{name}{suffix}_stderr", np.stack([e.stderr[row] for e in estimates[name]]))
