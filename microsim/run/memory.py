"""A run's memory, estimated before anything is traced, and the refusal of a run that cannot fit."""

from __future__ import annotations

import math

from microsim.run import executors
from microsim.run.plan import Plan, PlanError
from microsim.tracer import estimators

#: what the main process holds before any scene (interpreter, numpy, numba, Embree, kernels):
#: 225 MiB resident measured on phi = 0.3
PROCESS_BYTES = 250 * 2**20
#: what a forked worker adds before its scene: 50 MiB proportional set size measured (the rest
#: is shared with the main process, copy on write)
WORKER_BYTES = 100 * 2**20


def memory_estimate(plan: Plan, workers: int, spawned: bool = False) -> int:
    """Peak bytes of a run, all processes: each tracing process (the main one, or one worker per
    block of units, forked or, with ``spawned``, started afresh as Dask's are) holds one
    realization's scene (the generator's ``scene_bytes``; two with ``plan.builds_ahead``: the next
    one is built while one traces), what its tracers work in while they trace (the tracer's own
    ``working_bytes``: a batch of path rows, or the chunk tallies of a wave; a tracer a thread
    where units are traced side by side) and its units' tallies (two realizations' side by side);
    the main process sums into per-incidence estimates and buffers the tallies of units that
    arrive early (up to all but one worker's share)."""
    albedos = max(1, len(plan.albedos))
    tally = 8 * albedos * sum(estimator.tally_values() for estimator in plan.estimators)
    units = len(plan.units)
    processes = len(executors.split(plan.units, max(1, workers)))
    side_by_side = executors.side_by_side(plan, math.ceil(units / processes))
    # side by side: a tracer of one thread on each thread, and two realizations' tallies held
    tracers, tracer_threads, held = (plan.threads, 1, 2 * plan.n_incidences) if side_by_side else (1, plan.threads, 2)
    working = tracers * plan.tracer_class.working_bytes(plan.backend, tracer_threads, plan.paths_per_realization,
                                                        tally, estimators.shadow_rays(plan.estimators))
    tracing = (1 + plan.builds_ahead) * plan.generator.scene_bytes(plan.scene) + working + held * tally
    estimates = 8 * albedos * sum(estimator.estimate_values() for estimator in plan.estimators)
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


def check_memory(plan: Plan, workers: int, spawned: bool = False) -> None:
    """Refuse (PlanError, one line) a run whose :func:`memory_estimate` exceeds the free memory;
    where it fits with one scene a process and not with two, it builds no realization ahead
    (``plan.builds_ahead`` turned off)."""
    need, free = memory_estimate(plan, workers, spawned), available_memory()
    if free is not None and need > free and plan.builds_ahead:
        plan.builds_ahead = False
        need = memory_estimate(plan, workers, spawned)
    size = getattr(plan.generator, "SIZE", "lower the scene's tile or depth")
    if free is not None and need > free:
        raise PlanError(f"this run needs about {need / 2**30:.3g} GiB of memory (scene "
                        f"{plan.generator.scene_bytes(plan.scene) / 2**30:.3g} GiB a tracing process, sensor.cells "
                        f"{plan.sensor.n_cells}) and {free / 2**30:.3g} GiB are free: {size}; or lower sensor.cells "
                        "or --workers")
