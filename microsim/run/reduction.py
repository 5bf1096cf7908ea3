"""The reduction of a run's units to its estimates: every estimator's estimates of each unit
summed in unit order, whatever order the units arrive in (so that a table is bit-identical for
any number of workers, any executor and any number of interruptions), into the mean and
standard error over the realizations (docs/conventions.md §2: the errors include the variance of
the geometry, which is far from negligible on a finite tile), with the energy balance and the
event counts.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from microsim.core.tally import COUNT_NAMES, ENERGY_NAMES, per_albedo
from microsim.run.plan import Plan
from microsim.tracer.sensor import Sensor


@dataclass
class Estimate:
    """Running sums over batches of per-batch estimates: mean and standard error of the mean;
    with ``products``, also the covariance of the mean over the last axis (estimates that share
    their paths, as the points of next-event estimation do). Those sums are of the deviations
    from the first batch (``shift``), so that batches of equal values (a Lambertian plane's
    points) have no spread at all, not the rounding of large sums that cancel."""

    total: np.ndarray
    squares: np.ndarray
    count: int = 0
    products: np.ndarray | None = None  # sums of value[..., :, None] * value[..., None, :]
    shift: np.ndarray | None = None  # with products: the first batch, which the sums are taken from

    @classmethod
    def zeros(cls, shape, covariance: bool = False) -> "Estimate":
        products = np.zeros((*shape, shape[-1])) if covariance else None
        return cls(np.zeros(shape), np.zeros(shape), products=products)

    def add(self, value) -> None:
        if self.products is not None:
            if self.shift is None:
                self.shift = np.array(value, np.float64)
            value = value - self.shift
            self.products += value[..., :, None] * value[..., None, :]
        self.total += value
        self.squares += np.square(value)
        self.count += 1

    @property
    def covariance(self) -> np.ndarray:
        """Covariance of the mean over the last axis (..., n, n), from the spread of the batches
        (its diagonal is stderr squared); needs ``products``."""
        n = self.count
        spread = (self.products - self.total[..., :, None] * self.total[..., None, :] / n) / (n - 1)
        return spread / n

    @property
    def mean(self) -> np.ndarray:
        return self.total / self.count if self.shift is None else self.shift + self.total / self.count

    @property
    def stderr(self) -> np.ndarray:
        n = self.count
        var = np.maximum(self.squares - self.total * self.total / n, 0.0) / (n - 1)
        return np.sqrt(var / n)


@dataclass
class Result:
    """Per-incidence estimates of a run, ready for :func:`microsim.tables.write`."""

    plan: Plan
    sensor: Sensor
    albedo_value: float | None  # the material albedo of these estimates, in a run of several (else None)
    estimators: tuple  # the run's estimators (microsim.tracer.estimators), which write their datasets
    #: every estimator's estimates by name (microsim.tracer.estimators.Estimator.reduce), per incidence
    estimates: dict
    energy: list  # per incidence: Estimate over (*ENERGY_NAMES, balance)
    counts: np.ndarray  # (n_incidences, len(COUNT_NAMES)) tracer event counts
    scene_info: dict = field(default_factory=dict)  # realization -> info of the generated scene
    wall_time: float = 0.0
    units_resumed: int = 0  # units taken from a unit store (microsim.run.unit_store)
    units_traced: int = 0  # units traced by this call

    @property
    def brdf(self) -> list:
        """Per incidence: Estimate of the cell-averaged BRDF over (RESULT_ROWS, cells) (microsim.core.orders)."""
        return self.estimates["brdf"]

    @property
    def albedo(self) -> list:
        """Per incidence: Estimate of the albedo over (RESULT_ROWS,), rows as brdf's."""
        return self.estimates["albedo"]

    @property
    def paths(self) -> np.ndarray:
        return np.full(self.plan.n_incidences, self.plan.paths, dtype=np.int64)


def unit_estimates(estimators, tally, incidence: int, albedo: int = 0):
    """(estimator, its estimates by name) of every estimator of a unit's ``tally`` traced at
    incidence number ``incidence``, for albedo number ``albedo`` of the run."""
    for estimator, record in zip(estimators, tally.estimates):
        fields = record._make(per_albedo(field[0], len(shape))[albedo] for field, shape in zip(record, estimator.shapes()))
        yield estimator, estimator.reduce(fields, tally.paths, incidence)


class Reducer:
    """Sums unit tallies in unit order, buffering those that arrive early; one Result per albedo.
    Each estimator reduces its own fields (by name); the reducer keeps the mean and standard
    error of every estimate over the realizations, and the energy balance."""

    def __init__(self, plan: Plan):
        n_i = plan.n_incidences
        self.plan, self.estimators = plan, plan.estimators
        self.results = [Result(plan, plan.sensor, value, self.estimators, {},
                               [Estimate.zeros(len(ENERGY_NAMES) + 1) for _ in range(n_i)],
                               np.zeros((n_i, len(COUNT_NAMES)), np.int64))
                        for value in (plan.albedos or (None,))]
        self.order = {unit: k for k, unit in enumerate(plan.units)}
        self.pending = {}
        self.next = 0
        self.units = plan.units

    def add(self, unit, tally, info) -> None:
        for result in self.results:
            result.scene_info.setdefault(unit[0], info)
        self.pending[self.order[unit]] = (unit, tally)
        while self.next in self.pending:
            self._reduce(*self.pending.pop(self.next))
            self.next += 1

    def _reduce(self, unit, tally) -> None:
        i = unit[1]
        energy = per_albedo(tally.energy, 1)
        for j, res in enumerate(self.results):
            exited = 0.0
            for estimator, estimates in unit_estimates(self.estimators, tally, i, j):
                for name, value in estimates.items():
                    if name not in res.estimates:
                        covariant = name in estimator.COVARIANT
                        res.estimates[name] = [Estimate.zeros(value.shape, covariant) for _ in self.plan.theta_i]
                    res.estimates[name][i].add(value)
                exited += estimator.exited(estimates)
            lost = energy[j] / tally.paths
            res.energy[i].add(np.append(lost, exited + lost.sum()))
            res.counts[i] += tally.counts

    @property
    def done(self) -> bool:
        return self.next == len(self.units)
