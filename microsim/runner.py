"""A run: realizations x incidences of paths, on one or more worker processes.

Each realization is one batch: an independent geometry sample, traced with an independent
random stream for every incidence, with the same number of paths. Standard errors are the
spread of the per-realization estimates divided by sqrt(realizations) (CONVENTIONS 2), so they
include the variance of the geometry, which is far from negligible on a finite tile.

Work is cut into units (realization r, incidence i). The random stream of a unit is keyed by
(seed, r, i) and the geometry of realization r by (seed, r), so a unit's tally does not
depend on which process traced it. Units are split into contiguous blocks, one per worker (a
worker builds each realization of its block once), and tallies are summed in unit order
whatever order they arrive in: the table is bit-identical for any number of workers.
"""

from __future__ import annotations

import math
import multiprocessing
import queue
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field

import numpy as np

import geometry

from .frames import direction
from . import embree, integrators
from .integrators.records import COUNT_NAMES, ENERGY_NAMES, ORDERS
from .rng import geometry_rng, stream_key
from .sensor import Sensor


@dataclass
class Plan:
    """Everything a worker needs to trace any unit of a run (picklable)."""

    config: object
    scene: dict  # resolved scene parameters
    theta_i: np.ndarray
    phi_i: np.ndarray
    sensor_cells: int
    realizations: int
    paths_per_realization: int
    backend: str  # resolved run.backend: "direct" or "embreex"
    backend_note: str  # why "auto" fell back to embreex ("" otherwise)
    threads: int = 1

    @classmethod
    def from_config(cls, config, threads: int = 1, workers: int = 1) -> "Plan":
        """The plan of a validated config on ``workers`` processes of ``threads`` threads; raises
        PlanError (one line) if it cannot be traced here. The backend, and the scene as that
        backend can trace it, are resolved here, and every substitution is said in backend_note."""
        run = config.run
        theta = np.radians(np.asarray(config.illumination.theta_i_deg, dtype=np.float64))
        phi = np.full_like(theta, math.radians(config.illumination.phi_i_deg))
        backend, notes = resolve_backend(run.backend, check=workers == 1)
        if backend == "embreex" and threads > 1:
            if run.backend == "embreex":
                raise PlanError(f"--threads {threads}: the embreex backend traces on one thread; use --workers")
            threads, notes = 1, notes + ["one thread (the embreex backend has no threads)"]
        generator = geometry.SCENES[config.scene.kind]
        config, substitution = generator.for_backend(config, backend)
        notes += [substitution] if substitution else []
        return cls(config, generator.resolve(config), theta, phi, config.sensor.cells, run.realizations,
                   math.ceil(run.paths / run.realizations), backend, "; ".join(notes), threads)

    @property
    def n_incidences(self) -> int:
        return len(self.theta_i)

    @property
    def paths(self) -> int:
        """Paths traced per incidence."""
        return self.realizations * self.paths_per_realization

    @property
    def units(self) -> list[tuple[int, int]]:
        """(realization, incidence) in the order tallies are summed."""
        return [(r, i) for r in range(self.realizations) for i in range(self.n_incidences)]

    def incidence_direction(self, i: int) -> np.ndarray:
        return direction(self.theta_i[i], self.phi_i[i])

    @property
    def generator(self):
        """The scene generator module of the config's scene kind."""
        return geometry.SCENES[self.config.scene.kind]

    @property
    def tracer_class(self):
        """The integrator class that traces the scenes of this run (named by the generator)."""
        return integrators.get(self.generator.INTEGRATOR)

    @property
    def tracer_options(self) -> dict:
        return {"backend": self.backend, "threads": self.threads}


class PlanError(ValueError):
    """A config that cannot be traced on this machine: the message is one line."""


def resolve_backend(requested: str, check: bool = True) -> tuple[str, list[str]]:
    """(backend, [why "auto" fell back]): "direct" where the Embree binding loads, else "embreex".

    ``check`` = False (a process about to fork workers) only loads the library: its layout
    check commits a scene, which starts Embree's threads; each worker then checks for itself.
    """
    if requested == "embreex":
        return "embreex", []
    try:
        embree.load() if check else embree.available()
    except embree.EmbreeUnavailable as err:
        if requested == "direct":
            raise PlanError(f"run.backend = 'direct': {err}") from None
        return "embreex", [f"the direct backend is unavailable ({err})"]
    return "direct", []


@dataclass
class Estimate:
    """Running sums over batches of per-batch estimates: mean and standard error of the mean."""

    total: np.ndarray
    squares: np.ndarray
    count: int = 0

    @classmethod
    def zeros(cls, shape) -> "Estimate":
        return cls(np.zeros(shape), np.zeros(shape))

    def add(self, value) -> None:
        self.total += value
        self.squares += np.square(value)
        self.count += 1

    @property
    def mean(self) -> np.ndarray:
        return self.total / self.count

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
    brdf: list  # per incidence: Estimate of f_C over (ORDERS + 1, n_cells), last row = all orders
    albedo: list  # per incidence: Estimate over (ORDERS + 1,)
    energy: list  # per incidence: Estimate over (*ENERGY_NAMES, balance)
    counts: np.ndarray  # (n_incidences, len(COUNT_NAMES)) tracer event counts
    scene_info: dict = field(default_factory=dict)  # realization -> info of the generated scene
    wall_time: float = 0.0

    @property
    def paths(self) -> np.ndarray:
        return np.full(self.plan.n_incidences, self.plan.paths, dtype=np.int64)


class _Reducer:
    """Sums unit tallies in unit order, buffering those that arrive early."""

    def __init__(self, plan: Plan, sensor: Sensor):
        n_i, n_c = plan.n_incidences, sensor.n_cells
        self.plan = plan
        self.result = Result(
            plan, sensor,
            [Estimate.zeros((ORDERS + 1, n_c)) for _ in range(n_i)],
            [Estimate.zeros(ORDERS + 1) for _ in range(n_i)],
            [Estimate.zeros(len(ENERGY_NAMES) + 1) for _ in range(n_i)],
            np.zeros((n_i, len(COUNT_NAMES)), np.int64),
        )
        self.order = {unit: k for k, unit in enumerate(plan.units)}
        self.pending = {}
        self.next = 0
        self.units = plan.units

    def add(self, unit, tally, info) -> None:
        self.result.scene_info.setdefault(unit[0], info)
        self.pending[self.order[unit]] = (unit, tally)
        while self.next in self.pending:
            self._reduce(*self.pending.pop(self.next))
            self.next += 1

    def _reduce(self, unit, tally) -> None:
        i = unit[1]
        res = self.result
        per_path = tally.exit_weight / tally.paths
        cells = np.vstack([per_path, per_path.sum(axis=0)])
        res.brdf[i].add(cells / res.sensor.projected_solid_angle())
        albedo = cells.sum(axis=1)
        res.albedo[i].add(albedo)
        lost = tally.energy / tally.paths
        res.energy[i].add(np.append(lost, albedo[-1] + lost.sum()))
        res.counts[i] += tally.counts

    @property
    def done(self) -> bool:
        return self.next == len(self.units)


def trace_units(plan: Plan, units, emit) -> None:
    """Trace ``units`` in order, calling ``emit(unit, tally, scene_info)`` after each."""
    sensor = Sensor.build(plan.sensor_cells)
    generator = plan.generator
    seed, max_order = plan.config.run.seed, plan.config.run.max_order
    current, tracer = None, None
    for r, i in units:
        if r != current:
            scene = tracer = None  # the previous realization's scene and acceleration structure go first
            scene = generator.generate(plan.scene, plan.config, geometry_rng(seed, r))
            tracer = plan.tracer_class(scene, sensor, **plan.tracer_options)
            current = r
        tally = tracer.trace(plan.incidence_direction(i), plan.paths_per_realization, stream_key(seed, r, i),
                             max_order)
        emit((r, i), tally, scene.info)


_queue = None


def _init_worker(q) -> None:
    global _queue
    _queue = q


def _worker(plan: Plan, units) -> None:
    trace_units(plan, units, lambda unit, tally, info: _queue.put((unit, tally, info)))


def split(units: list, parts: int) -> list[list]:
    """Contiguous blocks of nearly equal size."""
    edges = np.linspace(0, len(units), parts + 1).round().astype(int)
    return [units[a:b] for a, b in zip(edges[:-1], edges[1:]) if b > a]


def run(config, workers: int = 1, threads: int = 1, progress=None) -> Result:
    """Trace a validated config on ``workers`` processes of ``threads`` threads each;
    ``progress(paths_done)`` is called as units complete. Raises PlanError (one line)."""
    plan = Plan.from_config(config, threads, workers)
    sensor = Sensor.build(plan.sensor_cells)
    reducer = _Reducer(plan, sensor)
    start = time.perf_counter()

    def collect(unit, tally, info):
        reducer.add(unit, tally, info)
        if progress is not None:
            progress(tally.paths)

    blocks = split(plan.units, max(1, workers))
    if len(blocks) <= 1:
        trace_units(plan, plan.units, collect)
    else:
        plan.tracer_class.compile(sensor, **plan.tracer_options)
        context = multiprocessing.get_context("fork")
        q = context.Queue()
        with ProcessPoolExecutor(len(blocks), mp_context=context, initializer=_init_worker, initargs=(q,)) as pool:
            futures = [pool.submit(_worker, plan, block) for block in blocks]
            while not reducer.done:
                try:
                    collect(*q.get(timeout=0.2))
                except queue.Empty:
                    for f in futures:
                        if f.done() and f.exception() is not None:
                            raise f.exception()
    reducer.result.wall_time = time.perf_counter() - start
    return reducer.result
