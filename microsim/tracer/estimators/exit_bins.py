"""The exit binning: every path that leaves adds its weight to the sensor cell it leaves through.

The estimator of docs/conventions.md §2: a beam of unit irradiance, N paths; a path leaving along d
with weight w adds w / (N x the projected solid angle of d's cell) to the cell average of the
BRDF, by scattering order (1, 2, 3, 4+), all orders, order 1 scattered by the base plane
(conventions §6, ``brdf_order1_base``) and orders 1 and 2 together (``brdf_orders12``); and, if the
sensor has retro rings, the same in the ring about the retro direction that d falls in (a
path may count in a cell and a ring). The albedos are the sums over the cells.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np

from microsim.core.orders import ORDERS, RESULT_ALL_ORDERS, RESULT_ORDER1_BASE, RESULT_ORDERS12, RESULT_ROWS
from microsim.core.table_layout import Dataset
from microsim.tracer.estimators import Estimator

#: the row of the tally after the orders: order-1 exits scattered by the base plane
BASE_ROW = ORDERS
TALLY_ROWS = ORDERS + 1


class ExitBinsTally(NamedTuple):
    """Exit weights (rows: the orders, then order 1 from the base; columns: the sensor's cells,
    then its retro rings, ``Sensor.tally_width``)."""

    weight: np.ndarray


class ExitBins(Estimator):
    """The exit binning (module doc): datasets brdf*, albedo*, brdf_retro* (conventions §6)."""

    name = "exit_bins"
    Record = ExitBinsTally
    HOOKS = "microsim.tracer.estimators.exit_bins_hooks"
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
            ("brdf_retro", ("incidences", "retro_rings"), "1/sr", "f averaged (cos-weighted) over each ring about "
             "the retro direction, all orders", "sensor.retro_rings > 0", False),
            ("brdf_retro_order", ("incidences", "orders", "retro_rings"), "1/sr", "brdf_retro by order",
             "sensor.retro_rings > 0", False),
        )
        for dataset in (
            Dataset(name, axes, unit, doc, when=when, required=required),
            Dataset(f"{name}_stderr", axes, unit, f"standard error of {name}, from the spread of the realizations",
                    when=when, required=required),
        )
    ) + (
        Dataset("sensor/retro_gamma_lo", ("retro_rings",), "rad", "lower phase-angle bound of each retro ring "
                "(widths nearly equal, uniform in the chord 2 sin(gamma / 2))", when="sensor.retro_rings > 0"),
        Dataset("sensor/retro_gamma_hi", ("retro_rings",), "rad", "upper phase-angle bound of each retro ring",
                when="sensor.retro_rings > 0"),
        Dataset("sensor/retro_projected_solid_angle", ("incidences", "retro_rings"), "sr",
                "projected solid angle of each retro ring about each incidence (rings the horizon cuts included)",
                when="sensor.retro_rings > 0"),
    )

    def shapes(self):
        return ((TALLY_ROWS, self.sensor.tally_width),)

    def reduce(self, fields, paths, incidence):
        per_path = fields.weight / paths
        bins = np.vstack([per_path[:ORDERS], per_path[:ORDERS].sum(axis=0), per_path[BASE_ROW],
                          per_path[0] + per_path[1]])
        cells, rings = bins[:, :self.sensor.n_cells], bins[:, self.sensor.n_cells:]
        estimates = {"brdf": cells / self.sensor.projected_solid_angle(), "albedo": cells.sum(axis=1)}
        if self.sensor.retro_rings:
            projected = self.retro_projected_solid_angle[incidence]
            estimates["brdf_retro"] = np.divide(rings, projected, out=np.zeros_like(rings), where=projected > 0)
        return estimates

    def estimate_values(self):
        return RESULT_ROWS * (self.sensor.tally_width + 1)  # brdf and brdf_retro rows, and albedo

    def exited(self, estimates):
        return estimates["albedo"][RESULT_ALL_ORDERS]

    @functools.cached_property
    def retro_projected_solid_angle(self) -> list[np.ndarray]:
        """Per incidence of the run, the projected solid angles of the retro rings about it."""
        return [self.sensor.retro_projected_solid_angle(self.plan.incidence_direction(i))
                for i in range(self.plan.n_incidences)]

    def write(self, put, estimates):
        if self.sensor.retro_rings:
            for name, bounds in zip(("retro_gamma_lo", "retro_gamma_hi"), self.sensor.retro_phase_bounds()):
                put(f"sensor/{name}", bounds)
            put("sensor/retro_projected_solid_angle", np.stack(self.retro_projected_solid_angle))
            for suffix, row in (("", RESULT_ALL_ORDERS), ("_order", slice(0, ORDERS))):
                put(f"brdf_retro{suffix}", np.stack([e.mean[row] for e in estimates["brdf_retro"]]))
                put(f"brdf_retro{suffix}_stderr", np.stack([e.stderr[row] for e in estimates["brdf_retro"]]))
        rows = {"": RESULT_ALL_ORDERS, "_order": slice(0, ORDERS), "_orders12": RESULT_ORDERS12}
        if self.plan.scene.get("base", "none") != "none":
            rows["_order1_base"] = RESULT_ORDER1_BASE
        for name in ("brdf", "albedo"):
            for suffix, row in rows.items():
                put(name + suffix, np.stack([e.mean[row] for e in estimates[name]]))
                put(f"{name}{suffix}_stderr", np.stack([e.stderr[row] for e in estimates[name]]))
