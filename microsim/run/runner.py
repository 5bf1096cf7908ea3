"""A run: realizations x incidences of paths, on one or more worker processes.

Each realization is one batch: an independent geometry sample, traced with an independent
random stream for every incidence, with the same number of paths. Standard errors are the
spread of the per-realization estimates divided by sqrt(realizations) (docs/conventions.md §2), so they
include the variance of the geometry, which is far from negligible on a finite tile.

Work is cut into units (realization r, incidence i). The random stream of a unit is keyed by
(seed, r, i) and the geometry of realization r by (seed, r), so a unit's tally does not
depend on which process traced it. :func:`run_albedos` plans the run, takes the units a
:class:`~microsim.run.unit_store.UnitStore` kept from an interrupted run, has an executor
(:mod:`microsim.run.executors`: this process, forked workers, or Dask) trace the others, keeps
each new unit in the store as it ends, and sums tallies in unit order whatever order they
arrive in: the table is bit-identical for any number of workers, any executor, and any number
of interruptions. Memory is estimated before anything is traced (:func:`memory_estimate`) and
a run that cannot fit is refused.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from microsim import geometry
from microsim.core.frames import direction
from microsim.core.tally import COUNT_NAMES, ENERGY_NAMES, SINGLE_ALBEDO, per_albedo
from microsim.physics.rng import stream_key
from microsim.run import executors
from microsim.tracer import embree, estimators, integrators
from microsim.tracer.integrators import embreex, scheduler
from microsim.tracer.jit.compile_watch import CompileWatch
from microsim.tracer.sensor import Sensor


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
    albedos: tuple = ()  # the material's albedos traced together (conventions §4); () for one
    estimator_names: tuple = estimators.DEFAULT  # the run's estimators (microsim.tracer.estimators)

    @property
    def albedo_scale(self) -> np.ndarray:
        """c_j / c_max of every albedo traced together (microsim.core.tally.Tally); [1] for a run of one."""
        if not self.albedos:
            return SINGLE_ALBEDO
        return np.asarray(self.albedos, np.float64) / max(self.albedos)

    @classmethod
    def from_config(cls, config, threads: int = 1, workers: int = 1) -> "Plan":
        """The plan of a validated config on ``workers`` processes of ``threads`` threads; raises
        PlanError (one line) if it cannot be traced here. The backend, and the scene as that
        backend can trace it, are resolved here, and every substitution is said in backend_note."""
        run = config.run
        theta = np.radians(np.asarray(config.illumination.theta_i_deg, dtype=np.float64))
        phi = np.radians(np.asarray(config.illumination.azimuths_deg(), dtype=np.float64))
        backend, notes = resolve_backend(run.backend, check=workers == 1)
        if backend == "embreex" and threads > 1:
            if run.backend == "embreex":
                raise PlanError(f"--threads {threads}: the embreex backend traces on one thread; use --workers")
            threads, notes = 1, notes + ["one thread (the embreex backend has no threads)"]
        generator = geometry.SCENES[config.scene.kind]
        config, substitution = generator.for_backend(config, backend)
        notes += [substitution] if substitution else []
        return cls(config, generator.resolve(config), theta, phi, config.sensor.cells, run.realizations,
                   math.ceil(run.paths / run.realizations), backend, "; ".join(notes), threads, albedos_of(config),
                   estimators.names_for(config))

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

    def build_sensor(self) -> Sensor:
        """The run's sensor: its cells, and its retro rings and points if the config asks for them."""
        section = self.config.sensor
        return (Sensor.build(self.sensor_cells).with_retro_rings(section.retro_rings, section.retro_max_deg)
                .with_points(section.directions_deg, section.retro_points_deg))

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

    def build_estimators(self, sensor: Sensor) -> tuple:
        """The run's estimators on its sensor (microsim.tracer.estimators)."""
        return estimators.build(self.estimator_names, sensor, self)


class PlanError(ValueError):
    """A config that cannot be traced on this machine: the message is one line."""


def albedos_of(config) -> tuple:
    """The albedos of a run of several (conventions §4), () for a run of one; PlanError where a
    list cannot be traced as one run: every interaction must be with the Lambertian material or
    absorb everything (microsim.core.tally.Tally)."""
    base = config.base
    if base is not None and len(getattr(base, "albedos", ())) > 1:
        raise PlanError("base.albedo: a list of albedos is taken by [material] only")
    albedos = getattr(config.material, "albedos", ())
    if len(albedos) <= 1:
        return ()
    if base is not None and base.kind != "absorber":
        raise PlanError(f"material.albedo = {list(albedos)}: several albedos from one run need every interaction "
                        f"to be with the material or absorb everything; here [base] is {base.kind!r} "
                        "(give it kind = \"absorber\", or run one albedo at a time)")
    return albedos


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
    def retro(self) -> list:
        """Per incidence, if the sensor has retro rings: Estimate of f over (RESULT_ROWS, rings)."""
        return self.estimates.get("brdf_retro", [])

    @property
    def paths(self) -> np.ndarray:
        return np.full(self.plan.n_incidences, self.plan.paths, dtype=np.int64)


def unit_estimates(estimators, tally, incidence: int, albedo: int = 0):
    """(estimator, its estimates by name) of every estimator of a unit's ``tally`` traced at
    incidence number ``incidence``, for albedo number ``albedo`` of the run."""
    for estimator, record in zip(estimators, tally.estimates):
        fields = record._make(per_albedo(field[0], len(shape))[albedo] for field, shape in zip(record, estimator.shapes()))
        yield estimator, estimator.reduce(fields, tally.paths, incidence)


class _Reducer:
    """Sums unit tallies in unit order, buffering those that arrive early; one Result per albedo.
    Each estimator reduces its own fields (by name); the reducer keeps the mean and standard
    error of every estimate over the realizations, and the energy balance."""

    def __init__(self, plan: Plan, sensor: Sensor):
        n_i = plan.n_incidences
        self.plan, self.estimators = plan, plan.build_estimators(sensor)
        self.results = [Result(plan, sensor, value, self.estimators, {},
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


#: what the main process holds before any scene (interpreter, numpy, numba, Embree, kernels):
#: 225 MiB resident measured on phi = 0.3
PROCESS_BYTES = 250 * 2**20
#: what a forked worker adds before its scene: 50 MiB proportional set size measured (the rest
#: is shared with the main process, copy on write)
WORKER_BYTES = 100 * 2**20
#: bytes a path row of the embreex backend takes while its batch is traced (row, ray, outputs)
PATH_ROW_BYTES = 80


def memory_estimate(plan: Plan, sensor: Sensor, workers: int, spawned: bool = False) -> int:
    """Peak bytes of a run, all processes: each tracing process (the main one, or one worker per
    block of units, forked or, with ``spawned``, started afresh as Dask's are) holds one
    realization's scene (the generator's ``scene_bytes``), a batch of path rows or the chunk
    tallies of a wave, and its unit's tally; the main process sums into per-incidence estimates
    and buffers the tallies of units that arrive early (up to all but one worker's share)."""
    estimators, albedos = plan.build_estimators(sensor), max(1, len(plan.albedos))
    tally = 8 * albedos * sum(estimator.tally_values() for estimator in estimators)
    if plan.backend == "embreex":
        points = sensor.n_points
        rows = min(plan.paths_per_realization, embreex.BATCH_PATHS // max(points, 1))
        paths = rows * (PATH_ROW_BYTES + points * embreex.SHADOW_BYTES)
    else:
        paths = scheduler.WAVE_CHUNKS_PER_THREAD * plan.threads * (tally + 1024)
    tracing = plan.generator.scene_bytes(plan.scene) + paths + 2 * tally
    units = len(plan.units)
    processes = len(executors.split(plan.units, max(1, workers)))
    estimates = 8 * albedos * sum(estimator.estimate_values() for estimator in estimators)
    reducing = 3 * plan.n_incidences * estimates + units * tally * (processes - 1) // processes
    workers_bytes = (PROCESS_BYTES if spawned else WORKER_BYTES) * processes if processes > 1 or spawned else 0
    return PROCESS_BYTES + workers_bytes + tracing * processes + reducing


def available_memory() -> int | None:
    """Bytes free for this run: MemAvailable of /proc/meminfo, or less where a cgroup (v2) limits
    this process (a container); None where neither can be read."""
    free = None
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    free = int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        limit = open("/sys/fs/cgroup/memory.max").read().strip()
        if limit != "max":
            used = int(open("/sys/fs/cgroup/memory.current").read())
            free = min(free if free is not None else math.inf, int(limit) - used)
    except (OSError, ValueError):
        pass
    return free


def check_memory(plan: Plan, sensor: Sensor, workers: int, spawned: bool = False) -> None:
    """Refuse (PlanError, one line) a run whose :func:`memory_estimate` exceeds the free memory."""
    need, free = memory_estimate(plan, sensor, workers, spawned), available_memory()
    size = getattr(plan.generator, "SIZE", "lower the scene's tile or depth")
    if free is not None and need > free:
        raise PlanError(f"this run needs about {need / 2**30:.3g} GiB of memory (scene "
                        f"{plan.generator.scene_bytes(plan.scene) / 2**30:.3g} GiB a tracing process, sensor.cells "
                        f"{sensor.n_cells}) and {free / 2**30:.3g} GiB are free: {size}; or lower sensor.cells "
                        "or --workers")


def compile_tracer(plan: Plan, sensor: Sensor | None = None) -> None:
    """Compile (or load from numba's cache) the kernels of the plan's tracer in this process:
    before worker processes fork (they inherit the machine code) or a local Dask cluster
    starts (its workers load it from the disk cache), and outside the time a run reports."""
    sensor = sensor if sensor is not None else plan.build_sensor()
    plan.tracer_class.compile(sensor, plan.build_estimators(sensor), len(plan.albedo_scale), plan.scene,
                              **plan.tracer_options)
    stream_key(plan.config.run.seed, 0, 0)  # each unit's random stream


def trace_realizations(config, workers: int = 1) -> tuple[Plan, dict[str, np.ndarray]]:
    """Trace a validated config of one albedo on the local executor (``workers`` processes) and
    keep every realization's estimates instead of their mean: (plan, {estimate name: array
    (realizations, incidences, ...)}), the names of the estimators' ``reduce``. For statistics a
    table's mean and standard error do not give: the covariance of estimates that share paths,
    jackknife errors of a function of them."""
    plan = Plan.from_config(config, workers=workers)
    if plan.albedos:
        raise PlanError(f"material.albedo = {list(plan.albedos)}: trace_realizations takes a config of one albedo")
    sensor = plan.build_sensor()
    run_estimators = plan.build_estimators(sensor)
    compile_tracer(plan, sensor)
    out = {}

    def keep(unit, tally, info):
        r, i = unit
        for _, estimates in unit_estimates(run_estimators, tally, i):
            for name, value in estimates.items():
                out.setdefault(name, np.zeros((plan.realizations, plan.n_incidences, *value.shape)))[r, i] = value

    EXECUTORS["local"](plan, plan.units, keep, workers)
    return plan, out


#: the executors of ``--executor`` (microsim.run.executors), as microsim.core.choices.EXECUTORS names them
EXECUTORS = {"local": executors.local, "dask": executors.dask}


def run(config, workers: int = 1, threads: int = 1, progress=None, **options) -> Result:
    """Trace a validated config of one albedo (see :func:`run_albedos`). A config of several
    albedos: :func:`run_albedos`."""
    albedos = albedos_of(config)
    if albedos:
        raise PlanError(f"material.albedo = {list(albedos)}: several albedos make several tables (runner.run_albedos)")
    return run_albedos(config, workers, threads, progress, **options)[0]


def run_albedos(config, workers: int = 1, threads: int = 1, progress=None, executor: str = "local",
                scheduler: str | None = None, store=None) -> list[Result]:
    """Trace a validated config of one albedo or several (conventions §4): one Result per albedo,
    in the order of ``material.albedo``, from one set of paths traced at the largest. The plan is
    made here and the memory checked (where the run traces on this machine), then :func:`trace`.
    :func:`microsim.app.session.run` is the whole run of the command line (resume, sweeps, signals,
    the table written). Raises PlanError (one line), and executors.WorkerFailed if a worker
    raises or dies."""
    plan = Plan.from_config(config, threads, workers)
    if scheduler is None:  # on this machine (a cluster's workers are elsewhere)
        check_memory(plan, plan.build_sensor(), workers, spawned=executor == "dask")
    return trace(plan, workers, progress, executor, scheduler, store)


def trace(plan: Plan, workers: int = 1, progress=None, executor: str = "local", scheduler: str | None = None,
          store=None) -> list[Result]:
    """Trace a planned run (its memory checked by the caller): one Result per albedo.

    ``executor`` ("local" or "dask") traces on ``workers`` processes of ``plan.threads`` threads
    each (``scheduler``: the address of a Dask cluster's scheduler). ``store`` (a
    :class:`~microsim.run.unit_store.UnitStore`): its saved units are taken as they are, only the
    others are traced, and each new one is saved as it ends. ``progress(unit, paths, resumed)``
    is called for every unit, saved ones first."""
    sensor = plan.build_sensor()
    reducer = _Reducer(plan, sensor)
    saved = set(store.saved_units()) if store is not None else set()
    missing = [unit for unit in plan.units if unit not in saved]
    if missing and scheduler is None:
        compile_tracer(plan, sensor)  # outside the run's time, and before any worker starts
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
