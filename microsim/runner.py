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

Workers are forked processes that die with the run: each asks Linux for SIGKILL when its parent
dies (prctl PR_SET_PDEATHSIG, so even a SIGKILL of the main process takes them along), ignores
SIGINT (a terminal sends it to the whole group; the main process decides), and is killed by the
main process as soon as the run ends in any other way than success (an exception, a signal
turned into one by the CLI). Memory is estimated before anything is traced
(:func:`memory_estimate`) and a run that cannot fit is refused.
"""

from __future__ import annotations

import ctypes
import math
import multiprocessing
import os
import queue
import signal
import time
from dataclasses import dataclass, field

import numpy as np

import geometry

from .frames import direction
from . import embree, integrators
from .integrators import fused, wavefront
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


#: what a process holds before any scene (interpreter, numpy, numba, Embree, compiled kernels)
PROCESS_BYTES = 300 * 2**20
#: bytes a path row of the embreex backend takes while its batch is traced (row, ray, outputs)
PATH_ROW_BYTES = 80
#: Linux prctl option: the signal a process gets when its parent dies
PR_SET_PDEATHSIG = 1


def memory_estimate(plan: Plan, sensor: Sensor, workers: int) -> int:
    """Peak bytes of a run, all processes: each tracing process holds one realization's scene
    (the generator's ``scene_bytes``), a batch of path rows or the chunk tallies of a wave, and
    its unit's tally; the main process sums into per-incidence estimates and buffers the tallies
    of units that arrive early (up to all but one worker's share)."""
    tally = ORDERS * sensor.n_cells * 8
    if plan.backend == "embreex":
        paths = min(plan.paths_per_realization, wavefront.BATCH_PATHS) * PATH_ROW_BYTES
    else:
        paths = fused.WAVE_CHUNKS_PER_THREAD * plan.threads * (tally + 1024)
    tracing = PROCESS_BYTES + plan.generator.scene_bytes(plan.scene) + paths + 2 * tally
    units = len(plan.units)
    reducing = 3 * plan.n_incidences * (ORDERS + 1) * sensor.n_cells * 8 + units * tally * (workers - 1) // workers
    return tracing * workers + reducing + (PROCESS_BYTES if workers > 1 else 0)


def available_memory() -> int | None:
    """MemAvailable of /proc/meminfo in bytes (None where there is none)."""
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def check_memory(plan: Plan, sensor: Sensor, workers: int) -> None:
    """Refuse (PlanError, one line) a run whose :func:`memory_estimate` exceeds the free memory."""
    need, free = memory_estimate(plan, sensor, workers), available_memory()
    if free is not None and need > free:
        raise PlanError(f"this run needs about {need / 2**30:.3g} GiB of memory ({workers} process(es), scene "
                        f"{plan.generator.scene_bytes(plan.scene) / 2**30:.3g} GiB each, sensor.cells "
                        f"{sensor.n_cells}) and {free / 2**30:.3g} GiB are free: lower the scene's tile or depth, "
                        f"sensor.cells or --workers")


def _worker(q, parent: int, plan: Plan, units) -> None:
    """A worker process: dies with its parent, leaves SIGINT to it, sends (unit, tally, info) or
    ("error", exception) on ``q``."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for name in ("SIGTERM", "SIGHUP"):
        signal.signal(getattr(signal, name), signal.SIG_DFL)
    try:
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):  # not Linux: the parent still kills its workers on the way out
        pass
    if os.getppid() != parent:  # the parent died before the request
        os._exit(1)
    try:
        trace_units(plan, units, lambda unit, tally, info: q.put((unit, tally, info)))
    except BaseException as err:  # noqa: BLE001 - every failure goes to the parent, which raises it
        q.put(("error", err))


def split(units: list, parts: int) -> list[list]:
    """Contiguous blocks of nearly equal size."""
    edges = np.linspace(0, len(units), parts + 1).round().astype(int)
    return [units[a:b] for a, b in zip(edges[:-1], edges[1:]) if b > a]


def run(config, workers: int = 1, threads: int = 1, progress=None) -> Result:
    """Trace a validated config on ``workers`` processes of ``threads`` threads each;
    ``progress(unit, paths)`` is called as units complete. Raises PlanError (one line)."""
    plan = Plan.from_config(config, threads, workers)
    sensor = Sensor.build(plan.sensor_cells)
    check_memory(plan, sensor, workers)
    reducer = _Reducer(plan, sensor)
    start = time.perf_counter()

    def collect(unit, tally, info):
        reducer.add(unit, tally, info)
        if progress is not None:
            progress(unit, tally.paths)

    blocks = split(plan.units, max(1, workers))
    if len(blocks) <= 1:
        trace_units(plan, plan.units, collect)
    else:
        plan.tracer_class.compile(sensor, **plan.tracer_options)
        _trace_on_workers(plan, blocks, reducer, collect)
    reducer.result.wall_time = time.perf_counter() - start
    return reducer.result


def _trace_on_workers(plan: Plan, blocks, reducer, collect) -> None:
    """One forked worker per block; every worker is killed if this returns any other way than
    with every unit collected."""
    context = multiprocessing.get_context("fork")
    q = context.Queue()
    processes = [context.Process(target=_worker, args=(q, os.getpid(), plan, block), daemon=True)
                 for block in blocks]
    try:
        for process in processes:
            process.start()
        while not reducer.done:
            try:
                message = q.get(timeout=0.2)
            except queue.Empty:
                dead = [p for p in processes if p.exitcode not in (None, 0)]
                if dead:
                    raise RuntimeError(f"a worker process died (exit code {dead[0].exitcode})") from None
                continue
            if message[0] == "error":
                raise message[1]
            collect(*message)
    finally:
        for process in processes:
            if process.is_alive():
                process.kill()
        for process in processes:
            process.join(timeout=5)
        q.close()
