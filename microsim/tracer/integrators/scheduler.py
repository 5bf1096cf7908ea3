"""The scheduler every integrator shares: a unit's paths in chunks, chunks in waves on threads.

The paths of a unit are cut into chunks of ``CHUNK_PATHS`` consecutive paths, and the chunks
into waves of up to ``WAVE_CHUNKS_PER_THREAD`` per thread. Each chunk is traced to completion
into a tally of its own (a row of the :class:`Workspace`) by a kernel the integrator gives,
``trace_share(first, start, stop)``: ``threads`` Python threads share a wave, each claiming the
next chunk as it ends one (:func:`trace_claimed`), one numba call a chunk releasing the GIL. The
chunk tallies are then summed in chunk order (:func:`microsim.core.tally.add_rows`). A path's random stream is
keyed by its number, and a chunk's order of events depends on its paths alone, so a table
depends neither on the number of threads nor on which thread traced which chunk: bit-identical
for any thread count.

Python threads rather than a numba ``prange``: numba's parallel loops take no tuples of arrays
(the named bundles), and its OpenMP layer is not fork-safe (the runner forks worker processes
after compiling). The calling thread traces beside a pool of ``threads - 1`` threads, which
also builds the next realization while this one traces (:mod:`microsim.run.executors`, where
a process of units enough traces them side by side instead, a unit on one thread each); the
pool lives as long as the process (starting two threads for each unit took 6 % of a two-thread
run of runs/spheres_phi030.toml), and a forked child starts a pool of its own. Chunk and wave
sizes, and what they cost: docs/developer/performance.md.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import threading
from collections import namedtuple
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np

from microsim.core.tally import COUNT_NAMES, ENERGY_NAMES, Tally, add_rows, albedo_axis, empty_tally
from microsim.tracer import embree
from microsim.tracer.integrators.records import Rays, allocate_paths

#: paths of one chunk: traced in order by one thread, into a tally of their own (module doc)
CHUNK_PATHS = 8192
#: chunks of a wave per thread (the threads claim them one by one); the wave's chunk tallies are
#: then summed in chunk order
WAVE_CHUNKS_PER_THREAD = 4


def wave_bytes(threads: int, tally_bytes: int) -> int:
    """Bytes a tracer of chunks in waves works in on ``threads`` threads: a wave's chunk tallies
    (``tally_bytes`` each) and their ROW_STRIDE path rows (an RTCRayHit record and the path's
    fields: under 128 bytes a row)."""
    return WAVE_CHUNKS_PER_THREAD * threads * (tally_bytes + 128 * ROW_STRIDE)
#: paths of a chunk traced side by side (:func:`trace_chunk`)
SLOTS = 2
#: path rows from one chunk's first to the next's: SLOTS are used, and the gap keeps the rows two
#: threads write on every event (random state, weight, order, the segment's query) off each
#: other's cache lines (64 rows of the narrowest field, int8, fill a 64-byte line)
ROW_STRIDE = 64

#: ROW_STRIDE path rows per chunk of a wave, SLOTS of them used (the paths it is tracing, their
#: segments and Embree queries: RTCRayHit records), and one row per chunk (its tally: the
#: estimators' records, lost energy, counts, the last two a cache line apart); and the ray
#: log (origin, direction, tfar of every query, in order; empty unless asked for)
Workspace = namedtuple("Workspace", ["paths", "rays", "queries", "estimates", "energy", "counts", "log", "logged"])


def workspace(rows: int, estimators, log_rays: int = 0, albedos: int = 1) -> Workspace:
    """Tallies of ``estimators`` for ``rows`` chunks (of ``albedos`` albedos each), and ROW_STRIDE
    path rows (paths, queries) for each, SLOTS used (two query records at least, as the views
    into a single record would be contiguous, which numba types apart: a second compile of every
    kernel)."""
    queries = embree.ray_hits(ROW_STRIDE * rows)
    rays = Rays(*embree.ray_views(queries), np.zeros(ROW_STRIDE * rows, np.int8))  # segments written into the queries
    return Workspace(allocate_paths(ROW_STRIDE * rows), rays, queries,
                     tuple(estimator.allocate(rows, albedos) for estimator in estimators),
                     line_apart_rows(rows, (*albedo_axis(albedos), len(ENERGY_NAMES)), np.float64),
                     line_apart_rows(rows, (len(COUNT_NAMES),), np.int64),
                     np.zeros((log_rays, 7), np.float32), np.zeros(1, np.int64))


def line_apart_rows(rows: int, shape: tuple, dtype) -> np.ndarray:
    """Zeros (max(rows, 2), *shape), each row contiguous and starting a cache line (64 bytes) or
    more after the last one ends: rows that threads add to on every segment share no line. Two
    rows at least: numpy flags a view of one row contiguous whatever its stride, and numba would
    type a one-row workspace (what a tracer is compiled on) apart from a run's, compiling every
    kernel twice."""
    rows = max(rows, 2)
    row_bytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
    stride = -(-row_bytes // 64) * 64 + 64
    buffer = np.zeros(rows * stride + 64, np.uint8)
    start = -buffer.ctypes.data % 64
    inner = np.lib.stride_tricks.as_strided(np.zeros(1, dtype), shape).strides  # C order within a row
    return np.lib.stride_tricks.as_strided(buffer[start:start + rows * stride].view(dtype), (rows, *shape), (stride, *inner))


def wave_rows(n_paths: int, threads: int) -> int:
    """Chunk rows a workspace needs for ``n_paths`` paths on ``threads`` threads: one wave's chunks."""
    return min(WAVE_CHUNKS_PER_THREAD * threads, max(math.ceil(n_paths / CHUNK_PATHS), 1))


def trace_in_waves(beam, estimators, threads: int, work: Workspace, trace_share):
    """The tally of the beam's paths cut into chunks of CHUNK_PATHS, traced in waves of
    :func:`wave_rows` chunks on ``threads`` threads: ``trace_share(first, start, stop)`` traces
    chunks first+start .. first+stop-1 into the tally rows start .. stop-1 of ``work``, releasing
    the GIL; each wave's rows are added in chunk order (:func:`microsim.core.tally.add_rows`).
    Raises Abandoned before a wave once the run this thread traces for has ended (:func:`abandoned_when`)."""
    n_chunks = math.ceil(beam.n_paths / CHUNK_PATHS)
    wave_chunks = WAVE_CHUNKS_PER_THREAD * threads
    total = empty_tally(beam.n_paths, estimators, beam.albedo_scale)
    for first in range(0, n_chunks, wave_chunks):
        if (ended := getattr(_RUN_ENDED, "event", None)) is not None and ended.is_set():
            raise Abandoned
        count = min(wave_chunks, n_chunks - first)
        clear_rows(work, count)
        if threads == 1:
            trace_share(first, 0, count)
        else:
            trace_claimed(first, count, threads, trace_share)
        add_rows(total, work.estimates, work.energy, work.counts, count)
    return total


def trace_claimed(first: int, count: int, threads: int, trace_share) -> None:
    """Chunks first .. first+count-1 traced by this thread and the pool's, each thread claiming
    the next chunk not yet claimed as it ends one: a pool thread busy elsewhere (building the next
    realization) joins when it is free, and is not waited for if the chunks are all claimed by then."""
    claims = itertools.count()  # next() is atomic under the GIL

    def trace_chunks():
        while (k := next(claims)) < count:
            trace_share(first, k, k + 1)

    helpers = [pool(threads).submit(trace_chunks) for _ in range(threads - 1)]
    try:
        trace_chunks()
    finally:
        for helper in helpers:  # every chunk ends before its row is read, or the run fails
            if not helper.cancel():
                helper.result()


class Abandoned(Exception):
    """A trace ended between two waves: the run it traced for has ended (:func:`abandoned_when`)."""


#: per thread: the event at which its traces end (:func:`abandoned_when`)
_RUN_ENDED = threading.local()


@contextlib.contextmanager
def abandoned_when(event: threading.Event):
    """Traces on this thread raise Abandoned before their next wave once ``event`` is set: the run
    they trace for has ended in an error, and would not use their tallies."""
    _RUN_ENDED.event = event
    try:
        yield
    finally:
        _RUN_ENDED.event = None


#: this process's pools: threads -> a pool of threads - 1 threads (module doc)
_POOLS: dict = {}


def pool(threads: int) -> ThreadPoolExecutor:
    """The pool of ``threads - 1`` threads that trace a wave's chunks beside the calling thread."""
    if threads not in _POOLS:
        _POOLS[threads] = ThreadPoolExecutor(threads - 1, thread_name_prefix="microsim-trace")
    return _POOLS[threads]


os.register_at_fork(after_in_child=_POOLS.clear)  # a forked child has none of its parent's threads


def clear_rows(work: Workspace, count: int) -> None:
    """Zero the tallies of rows 0 .. count-1 of ``work``."""
    for record in work.estimates:
        for field in record:
            field[:count] = 0.0
    work.energy[:count] = 0.0
    work.counts[:count] = 0


@numba.njit(cache=True, error_model="numpy", inline="always")
def chunk_tally(work, j, beam):
    """Tally row j of the workspace (zeroed by :func:`clear_rows`): where chunk j of a wave adds its paths."""
    return Tally(0, j, work.estimates, work.energy[j], work.counts[j], beam.albedo_scale)
