"""Executors: where the units of a run are traced (docs/conventions.md §7, ``--executor``).

An executor is a function ``execute(plan, units, emit, workers, scheduler)`` that traces the
units (realization r, incidence i) it is given and calls ``emit(unit, tally, scene_info)`` in
the main process as each one ends, in any order. It knows nothing of the reduction: the runner
sums tallies in unit order whatever their order of arrival, and a unit's tally depends only on
(seed, r, i) (:mod:`microsim.physics.rng`), so every executor writes the same table bit for bit.

- ``local``: in this process (one block of units), or on forked worker processes, one
  contiguous block each (a worker builds each realization of its block once).
- ``dask``: on a dask.distributed cluster, one task per realization (its scene is built once
  per task, and a worker of one thread holds one scene at a time); a ``LocalCluster`` of
  ``workers`` processes when no scheduler address is given. A task whose worker dies is run
  again elsewhere by the scheduler; only that realization's units are traced twice.

Forked workers die with the run: each asks Linux for SIGKILL when its parent dies (prctl
PR_SET_PDEATHSIG, so even a SIGKILL of the main process takes them along), ignores SIGINT (a
terminal sends it to the whole group; the main process decides), and is killed by the main
process as soon as the run ends in any other way than success (an exception, a signal turned
into one by the CLI); a signal in the microseconds of a worker's start can leave that worker to
PR_SET_PDEATHSIG alone, which kills it when the main process exits.
"""

from __future__ import annotations

import collections
import ctypes
import logging
import multiprocessing
import multiprocessing.connection
import os
import signal
import threading
import uuid
from concurrent import futures
from concurrent.futures import ThreadPoolExecutor
from itertools import groupby

import numpy as np

from microsim.core import interrupts
from microsim.physics.rng import geometry_rng, stream_key
from microsim.tracer.integrators import scheduler

#: Linux prctl option: the signal a process gets when its parent dies
PR_SET_PDEATHSIG = 1
#: how often the scheduler may lose a task's worker before it gives up on the task
DASK_ALLOWED_FAILURES = 3
#: how long a client tries to reach a scheduler given by its address
SCHEDULER_TIMEOUT = "20s"


class WorkerFailed(RuntimeError):
    """A worker process raised, or died, or the cluster went away; the message is one line."""


class SchedulerUnreachable(ValueError):
    """No Dask scheduler answers at the address given; the message is one line."""


#: units a thread at least for a process to trace its units side by side, one a thread
#: (:func:`trace_units`); with fewer, the units' chunks are shared instead
UNITS_A_THREAD = 4


def side_by_side(plan, n_units: int) -> bool:
    """Whether a process traces its ``n_units`` units side by side, one a thread, each on one
    thread (:func:`trace_units`): on two threads or more, with two scenes held, and units enough."""
    return plan.threads > 1 and plan.builds_ahead and n_units >= UNITS_A_THREAD * plan.threads


def trace_units(plan, units, emit) -> None:
    """Trace ``units`` in order in this process, calling ``emit(unit, tally, scene_info)`` in unit
    order. Units enough on two threads or more (:func:`side_by_side`): the units side by side, one
    a thread (:func:`_trace_side_by_side`). Otherwise one unit at a time, its chunks shared by the
    threads; the scene of a realization is built once for its consecutive units, and with
    ``plan.builds_ahead`` the next one is built on the tracer's pool while this one traces (its
    thread claims chunks again when done), so that a build leaves no thread idle."""
    if side_by_side(plan, len(units)):
        _trace_side_by_side(plan, units, emit)
        return
    build = realization_builder(plan, plan.threads)
    current = scene = tracer = None
    ahead = None  # (realization, future of its (scene, tracer))
    try:
        for position, (r, i) in enumerate(units):
            if r != current:
                scene = tracer = None  # the previous realization's scene and acceleration structure go first
                scene, tracer = ahead[1].result() if ahead is not None and ahead[0] == r else build(r)
                current = r
                following = next((s for s, _ in units[position:] if s != r), None)
                ahead = (following, scheduler.pool(plan.threads).submit(build, following)) \
                    if plan.builds_ahead and following is not None else None
            emit((r, i), trace_unit(plan, tracer, r, i), scene.info)
    finally:
        if ahead is not None and not ahead[1].cancel():  # on an error: a build under way ends first
            futures.wait([ahead[1]])


def _trace_side_by_side(plan, units, emit) -> None:
    """The units on ``plan.threads`` threads of a pool, a unit a thread (its tracer on one thread:
    the same tally bit for bit), in the order they come: each realization's build, then its units,
    the tasks of two realizations queued at a time; a realization's scene is let go, and the
    realization after the next queued, when its last unit is emitted. Tallies are emitted in
    unit order from this thread, which only waits. On an error (or an interrupt) here, what has
    not started is dropped, traces under way end before their next wave, and this returns when
    the pool's threads are free."""
    build = realization_builder(plan, 1)
    ended = threading.Event()

    def trace(built, r, i):
        scene, tracer = built.result()
        with scheduler.abandoned_when(ended):
            return trace_unit(plan, tracer, r, i), scene.info

    realizations = [(r, list(block)) for r, block in groupby(units, key=lambda unit: unit[0])]
    queued = collections.deque()  # (unit, future of (tally, info), last unit of its realization)
    builds = []  # the futures of the realizations' builds, in order
    pool = unit_pool(plan.threads)

    def queue(k):
        if k < len(realizations):
            r, block = realizations[k]
            builds.append(pool.submit(build, r))
            queued.extend((unit, pool.submit(trace, builds[-1], *unit), n == len(block) - 1)
                          for n, unit in enumerate(block))

    queue(0)
    queue(1)
    following = 2
    try:
        while queued:
            unit, future, last = queued.popleft()
            emit(unit, *future.result())
            if last:
                queue(following)
                following += 1
    finally:
        if queued:  # an error: nothing more is traced or built, and no thread is left at work
            ended.set()
            pending = [future for _, future, _ in reversed(queued)] + builds[::-1]
            futures.wait([future for future in pending if not future.cancel()])


#: this process's pools of unit tracers: threads -> a pool of that many threads
_UNIT_POOLS: dict = {}


def unit_pool(threads: int) -> ThreadPoolExecutor:
    """The pool of ``threads`` threads that trace units side by side (:func:`_trace_side_by_side`)."""
    if threads not in _UNIT_POOLS:
        _UNIT_POOLS[threads] = ThreadPoolExecutor(threads, thread_name_prefix="microsim-unit")
    return _UNIT_POOLS[threads]


os.register_at_fork(after_in_child=_UNIT_POOLS.clear)  # a forked child has none of its parent's threads


def trace_unit(plan, tracer, r: int, i: int):
    """The tally of unit (r, i) on realization r's ``tracer``: its paths at incidence i, on the
    random stream of (seed, r, i)."""
    return tracer.trace(plan.incidence_direction(i), plan.paths_per_realization, stream_key(plan.config.run.seed, r, i),
                        plan.config.run.max_order, plan.albedo_scale, plan.phi_i[i])


def realization_builder(plan, threads: int):
    """``build(r)``: realization r's (scene, its tracer on ``threads`` threads); its geometry is
    keyed by (seed, r) alone, so the scene does not depend on the thread that builds it."""
    sensor, estimators, tracer_class = plan.sensor, plan.estimators, plan.tracer_class  # built here, once
    options = {**plan.tracer_options, "threads": threads}

    def build(r):
        scene = plan.generator.generate(plan.scene, plan.config, geometry_rng(plan.config.run.seed, r))
        return scene, tracer_class(scene, sensor, estimators=estimators, **options)

    return build


def split(units: list, parts: int) -> list[list]:
    """Contiguous blocks of nearly equal size."""
    edges = np.linspace(0, len(units), parts + 1).round().astype(int)
    return [units[a:b] for a, b in zip(edges[:-1], edges[1:]) if b > a]


def local(plan, units, emit, workers: int = 1, scheduler: str | None = None) -> None:
    """Trace ``units`` in this process (one block) or on ``workers`` forked processes."""
    blocks = split(units, max(1, workers))
    if len(blocks) <= 1:
        trace_units(plan, units, emit)
        return
    _trace_on_workers(plan, blocks, emit)


def _worker(connection, parent: int, plan, units) -> None:
    """A worker process: dies with its parent, leaves SIGINT to it (and keeps a signal ignored as
    its parent found it, as under nohup), sends (unit, tally, info) for each unit, then ("done",),
    or ("error", one line) on its own pipe."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for signum in (signal.SIGTERM, signal.SIGHUP):
        if signal.getsignal(signum) is not signal.SIG_IGN:
            signal.signal(signum, signal.SIG_DFL)
    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
        prctl.argtypes = [ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong]
        prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):  # not Linux: the parent still kills its workers on the way out
        pass
    if os.getppid() != parent:  # the parent died before the request
        os._exit(1)
    try:
        trace_units(plan, units, lambda unit, tally, info: connection.send((unit, tally, info)))
        connection.send(("done",))
    except Exception as err:  # noqa: BLE001 - sent as text: an exception need not pickle
        connection.send(("error", _one_line(err)))


def _one_line(err: BaseException) -> str:
    return f"{type(err).__name__}: {' '.join(str(err).split())}"


def _trace_on_workers(plan, blocks, emit) -> None:
    """One forked worker per block, each with a pipe of its own (a worker killed mid-message
    cannot block the others, and its end of file shows at once). Every worker is killed if this
    returns any other way than with every worker done."""
    context = multiprocessing.get_context("fork")
    processes, readers = [], {}
    try:
        for block in blocks:
            reader, writer = context.Pipe(duplex=False)
            process = context.Process(target=_worker, args=(writer, os.getpid(), plan, block), daemon=True)
            processes.append(process)
            process.start()
            writer.close()  # only the worker writes: its death is an end of file here
            readers[reader] = process
        while readers:
            for reader in multiprocessing.connection.wait(list(readers)):
                process = readers[reader]
                try:
                    message = reader.recv()
                except EOFError:
                    process.join(timeout=5)
                    raise WorkerFailed(f"a worker process died (exit code {process.exitcode})") from None
                if message[0] == "done":
                    del readers[reader]
                elif message[0] == "error":
                    raise WorkerFailed(f"a worker failed: {message[1]}")
                else:
                    emit(*message)
    finally:
        for process in processes:
            if process.is_alive():
                process.kill()
        for process in processes:
            process.join(timeout=5)
        for reader in readers:
            reader.close()


def _trace_task(plan, units) -> list:
    """A Dask task: the units of one realization, traced on the worker; [(unit, tally, info)]."""
    done = []
    trace_units(plan, units, lambda unit, tally, info: done.append((unit, tally, info)))
    return done


def _start_fork_server() -> None:
    """Start multiprocessing's fork server (once a process) with SIGINT ignored in it and in
    the workers of a local Dask cluster it forks (:mod:`microsim.tracer.jit.forkserver_preload`, imported
    first; the server starts with SIGINT blocked, as this thread has it meanwhile, so that a
    Ctrl-C before that import waits and is discarded). A fork server that something else
    started first keeps its own disposition.

    This process's SIGINT is never ignored, not even for the milliseconds the server takes to
    start: a Ctrl-C then would be lost (``tests/test_signals.py``), as the kernel hands a signal
    to any thread that does not block it (Embree's, numba's). The resource tracker is started
    first: its start unblocks SIGINT in this thread as it ends, which the server would inherit."""
    from multiprocessing import forkserver, resource_tracker

    from distributed.utils import get_mp_context

    get_mp_context()  # distributed's list of modules the server imports once, for every worker
    preload = [name for name in forkserver._forkserver._preload_modules if name != "microsim.tracer.jit.forkserver_preload"]
    forkserver.set_forkserver_preload(["microsim.tracer.jit.forkserver_preload", *preload])
    resource_tracker.ensure_running()
    with interrupts.blocked_in_new_threads():
        forkserver.ensure_running()


def dask(plan, units, emit, workers: int = 1, scheduler: str | None = None) -> None:
    """Trace ``units`` on the dask.distributed cluster at ``scheduler``, or on a LocalCluster of
    ``workers`` single-threaded worker processes; one task per realization, results emitted as
    tasks end. The cluster made here is closed on the way out, whatever the way."""
    try:
        from dask import config as dask_config
        from distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise WorkerFailed("--executor dask needs dask.distributed: install the extra dask: "
                           "pip install -e '.[dask]' in microsim's clone") from None
    from distributed import CancelledError
    from distributed import TimeoutError as DaskTimeout
    from distributed.comm.core import CommClosedError

    cluster = client = futures = None
    # distributed's own reports of a lost cluster (tracebacks): ours is one line
    logs = [logging.getLogger(name) for name in list(logging.root.manager.loggerDict)
            if name == "distributed" or name.startswith("distributed.")]
    levels = [log.level for log in logs]
    for log in logs:
        log.setLevel(logging.CRITICAL)
    token = uuid.uuid4().hex[:12]  # task keys of this run, unlike any other run's on a shared cluster
    with dask_config.set({"distributed.scheduler.allowed-failures": DASK_ALLOWED_FAILURES,
                          "distributed.worker.multiprocessing-method": "forkserver"}):
        try:
            if scheduler is None:
                _start_fork_server()
                # its HTTP server on a free port (None takes 8787, and warns in 4 lines if another run holds it)
                cluster = LocalCluster(n_workers=max(1, workers), threads_per_worker=1, processes=True,
                                       dashboard_address=":0", silence_logs=logging.CRITICAL)
                client = Client(cluster)
            else:
                try:
                    client = Client(scheduler, timeout=SCHEDULER_TIMEOUT)
                except (OSError, ValueError, TypeError, DaskTimeout) as err:  # nobody there, or not a scheduler
                    raise SchedulerUnreachable(f"--scheduler {scheduler}: cannot reach a Dask scheduler there "
                                               f"({_one_line(err)})") from None
            futures = {future.key: future for future in (
                client.submit(_trace_task, plan, list(block), key=f"microsim-{token}-r{r}", pure=False)
                for r, block in groupby(units, key=lambda unit: unit[0]))}
            finished = as_completed(list(futures.values()))
            while futures:
                try:
                    future = next(finished)
                    if future.status == "error":
                        raise WorkerFailed(f"a dask task failed: {_one_line(future.exception())}")
                    messages = future.result()
                except (CancelledError, CommClosedError, DaskTimeout, OSError) as err:  # the cluster went away
                    raise WorkerFailed(f"the Dask cluster was lost ({_one_line(err)})") from None
                # let the cluster forget the result at once: a worker that dies holding it would
                # otherwise be made to trace it again
                del futures[future.key]
                future.release()
                for message in messages:
                    emit(*message)
        finally:
            if client is not None:
                if futures:
                    client.cancel(list(futures.values()))
                client.close()
            if cluster is not None:
                cluster.close()
            for log, level in zip(logs, levels):
                log.setLevel(level)
