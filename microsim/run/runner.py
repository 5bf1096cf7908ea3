"""A run: its plan traced, on one or more worker processes, and reduced.

:class:`Run` plans a config once (:mod:`microsim.run.plan`), checks its memory
(:mod:`microsim.run.memory`), compiles its tracer once, takes the units a
:class:`~microsim.run.unit_store.UnitStore` kept from an interrupted run, has an executor
(:mod:`microsim.run.executors`: this process, forked workers, or Dask) trace the others, keeps
each new unit in the store as it ends, and reduces them in unit order
(:mod:`microsim.run.reduction`).
"""

from __future__ import annotations

import time

import numpy as np

from microsim.physics.rng import stream_key
from microsim.run import executors
from microsim.run.memory import check_memory
from microsim.run.plan import Plan, PlanError
from microsim.run.reduction import Reducer, Result, unit_estimates
from microsim.tracer.jit.compile_watch import CompileWatch


class Run:
    """One run, planned once: its :class:`Plan` (with the sensor, estimators and tracer class it
    builds once), the memory check, the tracer compiled once in this process, and its units
    traced and reduced. :func:`microsim.app.session.run` is the front door that makes one (the
    command line's and Python's); tests and benchmarks make one through :mod:`microsim.testing`."""

    def __init__(self, plan: Plan):
        self.plan = plan
        self.compiled = False

    @classmethod
    def of(cls, config, threads: int = 1, workers: int = 1) -> "Run":
        """The run of a validated config on ``workers`` processes of ``threads`` threads (PlanError,
        one line, if it cannot be traced here)."""
        return cls(Plan.from_config(config, threads, workers))

    def check_memory(self, workers: int, spawned: bool = False) -> None:
        """Refuse (PlanError, one line) a run that cannot fit in the free memory (:func:`memory_estimate`)."""
        check_memory(self.plan, workers, spawned)

    def compile(self) -> None:
        """Compile (or load from numba's cache) the kernels of the plan's tracer in this process,
        once: before worker processes fork (they inherit the machine code) or a local Dask cluster
        starts (its workers load it from the disk cache), and outside the time a run reports."""
        if self.compiled:
            return
        plan = self.plan
        plan.tracer_class.compile(plan.sensor, plan.estimators, len(plan.albedo_scale), plan.scene,
                                  **plan.tracer_options)
        stream_key(plan.config.run.seed, 0, 0)  # each unit's random stream
        self.compiled = True

    def trace(self, workers: int = 1, progress=None, executor: str = "local", scheduler: str | None = None,
              store=None) -> list[Result]:
        """Trace the run (its memory checked by the caller): one Result per albedo, in the order of
        ``material.albedo``, from one set of paths traced at the largest (conventions §4).

        ``executor`` ("local" or "dask") traces on ``workers`` processes of ``plan.threads``
        threads each (``scheduler``: the address of a Dask cluster's scheduler). ``store`` (a
        :class:`~microsim.run.unit_store.UnitStore`): its saved units are taken as they are, only
        the others are traced, and each new one is saved as it ends. ``progress(unit, paths,
        resumed)`` is called for every unit, saved ones first. Raises PlanError (one line), and
        executors.WorkerFailed if a worker raises or dies."""
        plan = self.plan
        reducer = Reducer(plan)
        saved = set(store.saved_units()) if store is not None else set()
        missing = [unit for unit in plan.units if unit not in saved]
        if missing and scheduler is None:
            self.compile()
        if progress is not None:
            for unit in sorted(saved):
                progress(unit, plan.paths_per_realization, True)

        def reduce_saved():  # saved units are read when the sum reaches them: memory holds none ahead
            while not reducer.done and reducer.units[reducer.next] in saved:
                unit = reducer.units[reducer.next]
                reducer.add(unit, *store.load(unit))

        def collect(unit, tally, info):
            if store is not None:
                store.save(unit, tally, info)
            reducer.add(unit, tally, info)
            reduce_saved()
            if progress is not None:
                progress(unit, tally.paths, False)

        with CompileWatch() as watch:  # what numba compiles here while the run traces is not the run's time
            start = time.perf_counter()
            reduce_saved()
            if missing:
                EXECUTORS[executor](plan, missing, collect, workers, scheduler)
        for result in reducer.results:
            result.wall_time = time.perf_counter() - start - watch.seconds  # the tracing, without compiling
            result.units_resumed, result.units_traced = len(plan.units) - len(missing), len(missing)
        return reducer.results

    def trace_realizations(self, workers: int = 1) -> dict[str, np.ndarray]:
        """Trace a run of one albedo on the local executor (``workers`` processes) and keep every
        realization's estimates instead of their mean: {estimate name: array (realizations,
        incidences, ...)}, the names of the estimators' ``reduce``. For statistics a table's mean
        and standard error do not give: the covariance of estimates that share paths, jackknife
        errors of a function of them."""
        plan = self.plan
        if plan.albedos:
            raise PlanError(f"material.albedo = {list(plan.albedos)}: trace_realizations takes a config of one albedo")
        self.compile()
        out = {}

        def keep(unit, tally, info):
            r, i = unit
            for _, estimates in unit_estimates(plan.estimators, tally, i):
                for name, value in estimates.items():
                    out.setdefault(name, np.zeros((plan.realizations, plan.n_incidences, *value.shape)))[r, i] = value

        EXECUTORS["local"](plan, plan.units, keep, workers)
        return out


#: the executors of ``--executor`` (microsim.run.executors), as microsim.core.choices.EXECUTORS names them
EXECUTORS = {"local": executors.local, "dask": executors.dask}
