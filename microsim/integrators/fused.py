"""The direct backend of the surface tracer: numba calls Embree itself, paths run to completion.

The paths of a unit are cut into chunks of ``CHUNK_PATHS`` consecutive paths, and the chunks
into waves of up to ``WAVE_CHUNKS_PER_THREAD`` per thread. Each chunk is traced to completion
into a tally of its own, segment after segment (``rtcIntersect1`` on an ``RTCRayHit`` record of
its own, then the shared event kernels of :mod:`.surface`), with no Python between segments:
two paths at a time (``SLOTS``), both queries then both events, so that the processor overlaps
the two paths' work; a slot whose path ends takes the chunk's next path (:func:`trace_chunk`).
``threads`` Python threads share a wave, one numba call (:func:`trace_chunks`) each for a
contiguous share of its chunks (:func:`thread_shares`); the call releases the GIL, and all
threads share one committed Embree scene. The chunk tallies are then summed in chunk order
(:func:`add_chunks`). A path's random stream is keyed by its number, and a chunk's order of
events depends on its paths alone, so a table depends neither on the number of threads nor on
which thread traced which chunk: bit-identical for any thread count.

Time outside Embree per path (1 thread, the same rays replayed through rtcIntersect1 alone;
processes of two versions alternated, 400 k paths, best of 7, medians of 3 processes). These
replays wrote their hits into fresh arrays, and so also timed about 10 ns a ray of first writes
to new pages: the differences between versions below hold, but each time is short by about
10 ns a segment. Against a replay into arrays written beforehand (``benchmarks/throughput.py``),
the time outside Embree is 24-31 ns a segment on the micrograins (ratio 0.75-0.80) and
47-52 ns a segment on the spheres at normal incidence (0.84-0.85):

- Micrograins (``benchmarks/throughput.py``'s scene, 2.23 segments a path, Embree about
  205 ns a path): 83 ns with 2048-path chunks in waves of 8 a thread; 46 ns now. What it took:
  the exit binning without its search loop and mostly without its edge test
  (:func:`microsim.sensor.cell_index`), the ellipsoid projection without divisions, the
  conductor's Fresnel in one division, and longer chunks: a chunk zeroes and fills a tally of
  TALLY_ROWS x cells doubles (130 kB at 3240 cells), and a fresh one every 2048 paths evicted
  the sensor's tables and Embree's nodes from the cache; every wave also costs about 0.1 ms of
  Python (the calls' typing of the bundles), so a wave should be long.
- The two slots: on spheres (phi = 0.3, about 7 segments a path) one path at a time took
  368 ns a path and two slots 299 ns (ratio to raw Embree 0.842 against 0.869); on the
  micrograins one path at a time was a little faster, 42 against 46 ns (0.840 against 0.827).
  Two slots stay; one slot compiles in about 10 s instead of 27. A loop over K slots, one copy
  of the kernels, was slower than both, and the more so as K grew (K = 2, 4, 8).
- Chunks are 8192 paths: 16 384 was as fast on one thread, but a unit of 50 000 paths made
  of three such chunks cannot be split evenly between two threads.
- Spelling the side tests of :func:`.surface.prepare_segment` so as to divide once made it
  slower (+3 ns): LLVM's speculative divisions there shorten the path to the next query.
- Where the micrograins' 64 ns go (fair replay, versions with a part cut out, processes
  alternated, medians of 3 or 4): the exit binning takes 15 ns a path (every exit binned to
  cell 0: 49 ns, ratio 0.757 against 0.802), of which the cell lookup about 9 ns and the
  tally's scattered adds about 6 (cell from z alone: 56 ns); the conductor's Fresnel 2.6 ns
  (a constant 0.9: 64.3 against 66.9). So even free binning leaves the ratio near 0.80. The
  floor: with absorbing grains and base (a path is its start, one query and one absorption)
  the same geometry takes 18.6-20 ns a path outside Embree, ratio 0.815-0.831; at 91 ns a
  query, 0.85 allows 16 ns a segment for everything. A chunk tally laid out cell by cell (a
  cell's rows in one cache line, through a strided view) was slower: 72 against 65 ns. Binning
  each chunk's exits in a pass after it, in the same order (the same table to the bit), gained
  2.5 ns (64.7 against 67.2, within the noise): not kept.
- Where a micrograin segment's 120 ns go (perf's cpu-clock samples of this kernel): 70 % in
  Embree (84 ns: less than the replay's 90) and 30 %, 36 ns, in this kernel's code, spread thin
  (no instruction above 0.9 % of the samples; the largest, the tally's scattered adds). A ratio
  of 0.85 needs at most 22 ns. Other designs on the same paths, each in processes of its own
  against the same replay (none kept): a kernel cut down to this scene's physics (conductor
  grains, Lambertian base; no order cap, inside-hit test, idle count, energy tally, albedo axis
  or ray log), the same table to 4e-14: 113 ns a segment, ratio 0.80. Lanes of 2, 8 or 32 paths,
  their queries back to back and then their events grouped by what was hit (nothing, the base, a
  grain), the same table: 129-138 ns, 0.67-0.70. Embree's packets (rtcIntersect8/16) on the
  logged queries, in the kernel's order: 83 against 91 ns a ray; primary rays alone, sorted
  along a Morton curve, 70 against 83-85 (they are 45 % of the segments). The events' arithmetic
  as branch-free selects over 64 lanes in arrays, on synthetic hits: numba's LLVM left it scalar
  (cos and sin calls, fifteen arrays that may alias), 57 against 25 ns an event for the
  branching form.

Memory is one scene per process, a few hundred bytes per path row, and the tallies of one wave
(WAVE_CHUNKS_PER_THREAD x threads x TALLY_ROWS x cells doubles).

Python threads rather than a numba ``prange``: numba's parallel loops take no tuples of arrays
(the named bundles), and its OpenMP layer is not fork-safe (the runner forks worker processes
after compiling; a process forked after GNU OpenMP ran aborts). With one call per chunk the
Python around the calls (numba's typing of the bundles, the pool) took 12 % of the time; with
one call per thread and wave it is negligible.
"""

from __future__ import annotations

import math
from collections import namedtuple
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np

from .. import embree
from .records import COUNT_NAMES, ENERGY_NAMES, SEGMENTS, TALLY_ROWS, Rays, Tally, allocate_paths, empty_tally
from .surface import follow, prepare_segment, start_path

#: paths of one chunk: traced in order by one thread, into a tally of their own (module doc)
CHUNK_PATHS = 8192
#: chunks of a wave per thread, each thread tracing a contiguous share in one call; the wave's
#: chunk tallies are then summed in chunk order
WAVE_CHUNKS_PER_THREAD = 4
#: paths of a chunk traced side by side (:func:`trace_chunk`)
SLOTS = 2

#: SLOTS rows per chunk of a wave (the paths it is tracing, their segments and Embree queries)
#: and one row per chunk (its tally); and the ray log (origin, direction, tfar of every query,
#: in order; empty unless asked for)
Workspace = namedtuple("Workspace", ["paths", "rays", "records", "exit_weight", "energy", "counts", "log",
                                     "logged"])


def workspace(rows: int, width: int, log_rays: int = 0, albedos: int = 1) -> Workspace:
    """Tallies of ``width`` bins (sensor.tally_width) for ``rows`` chunks (of ``albedos`` albedos
    each), and SLOTS path rows (paths, queries) for each: two query records at least, as
    the views into a single record would be contiguous, which numba types apart (a second
    compile of every kernel)."""
    records = embree.ray_hits(SLOTS * rows)
    rays = Rays(*embree.ray_views(records), np.zeros(SLOTS * rows, np.int8))  # segments written into the queries
    axis = (albedos,) if albedos > 1 else ()  # one albedo: no albedo axis (records.Tally)
    return Workspace(allocate_paths(SLOTS * rows), rays, records,
                     np.zeros((rows, *axis, TALLY_ROWS, width)), np.zeros((rows, *axis, len(ENERGY_NAMES))),
                     np.zeros((rows, len(COUNT_NAMES)), np.int64), np.zeros((log_rays, 7), np.float32),
                     np.zeros(1, np.int64))


def backend(scene, threads: int):
    return FusedBackend(scene, threads)


def compile_kernels(beam, scene, sensor) -> None:
    """Compile (or load) :func:`trace_chunks` for these types, tracing nothing: no Embree call,
    no device. The library is loaded first: the kernel's machine code links to rtcIntersect1 by
    name (without it, loading the code segfaults)."""
    embree.available()
    work = workspace(1, sensor.tally_width, albedos=len(beam.albedo_scale))
    trace_chunks(0, 0, 0, beam, scene.arrays(), embree.SceneHandle(0, np.zeros(1, np.int64), np.ones(2)), sensor, work)
    compile_tally_sums(beam, work)


def compile_tally_sums(beam, work) -> None:
    """Compile (or load) :func:`add_chunks` for the tallies of this beam and workspace, adding
    nothing: :func:`trace_in_waves` calls it after a unit's first wave."""
    add_chunks(empty_tally(0, work.exit_weight.shape[-1], beam.albedo_scale), work, 0)


class FusedBackend:
    """The scene in a committed Embree scene of its own, traced by chunks on ``threads`` threads.

    ``log_rays`` > 0 (one thread only) keeps the first ``log_rays`` queries, in the order they
    are made, in ``ray_log`` (rows of origin, direction, tfar): the throughput benchmark replays
    them through Embree alone.
    """

    name = "direct"

    def __init__(self, scene, threads: int = 1, log_rays: int = 0):
        if log_rays and threads != 1:
            raise ValueError("the ray log keeps the order of one thread: give threads = 1")
        self.embree = embree.Scene(scene.vertices, scene.faces, scene.spheres, sphere_scale=scene.sphere_scale)
        self.threads, self.log_rays = threads, log_rays
        self.ray_log = np.zeros((0, 7), np.float32)

    def trace(self, beam, scene, sensor):
        work = workspace(wave_rows(beam.n_paths, self.threads), sensor.tally_width, self.log_rays, len(beam.albedo_scale))
        handle = self.embree.arrays()
        total = trace_in_waves(beam, sensor.tally_width, self.threads, work,
                               lambda *share: trace_chunks(*share, beam, scene, handle, sensor, work))
        self.ray_log = work.log[:min(work.logged[0], len(work.log))]
        return total


def wave_rows(n_paths: int, threads: int) -> int:
    """Chunk rows a workspace needs for ``n_paths`` paths on ``threads`` threads: one wave's chunks."""
    return min(WAVE_CHUNKS_PER_THREAD * threads, max(math.ceil(n_paths / CHUNK_PATHS), 1))


def trace_in_waves(beam, width: int, threads: int, work: Workspace, trace_share):
    """The tally of the beam's paths cut into chunks of CHUNK_PATHS, traced in waves of
    :func:`wave_rows` chunks on ``threads`` threads: ``trace_share(first, start, stop)`` traces
    chunks first+start .. first+stop-1 into the tally rows start .. stop-1 of ``work``, releasing
    the GIL; each wave's rows are added in chunk order (:func:`add_chunks`)."""
    n_chunks = math.ceil(beam.n_paths / CHUNK_PATHS)
    wave_chunks = WAVE_CHUNKS_PER_THREAD * threads
    total = empty_tally(beam.n_paths, width, beam.albedo_scale)
    with ThreadPoolExecutor(threads) as pool:
        for first in range(0, n_chunks, wave_chunks):
            count = min(wave_chunks, n_chunks - first)
            shares = [(first, a, b) for a, b in thread_shares(first, count, beam.n_paths, threads) if b > a]
            if len(shares) == 1:
                trace_share(*shares[0])  # one share: no hand-over to a pool thread
            else:
                list(pool.map(lambda share: trace_share(*share), shares))
            add_chunks(total, work, count)
    return total


def thread_shares(first: int, count: int, n_paths: int, threads: int) -> list[tuple[int, int]]:
    """Chunks first .. first+count-1 cut into ``threads`` contiguous shares (start, stop) of about
    equal paths (the last chunk of a unit may be short)."""
    done = np.minimum((first + np.arange(count + 1)) * CHUNK_PATHS, n_paths) - first * CHUNK_PATHS  # before chunk k
    targets = done[-1] * np.arange(threads + 1) / threads
    edges = np.abs(done[None, :] - targets[:, None]).argmin(axis=1)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]


@numba.njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def trace_chunks(first, start, stop, beam, scene, handle, sensor, work):
    """Trace chunks first+start .. first+stop-1 of the beam to completion, chunk first+j into tally
    row j, its paths in path row j (see :func:`trace_chunk`)."""
    for j in range(start, stop):
        chunk = first + j
        trace_chunk(chunk * CHUNK_PATHS, min((chunk + 1) * CHUNK_PATHS, beam.n_paths), SLOTS * j, beam, scene, handle,
                    sensor, work, chunk_tally(work, j, beam))


@numba.njit(cache=True, error_model="numpy", inline="always")
def chunk_tally(work, j, beam):
    """Tally row j of the workspace, zeroed: where chunk j of a wave adds its paths."""
    tally = Tally(0, work.exit_weight[j], work.energy[j], work.counts[j], beam.albedo_scale)
    tally.exit_weight[:] = 0.0
    tally.energy[:] = 0.0
    tally.counts[:] = 0
    return tally


@numba.njit(cache=True, error_model="numpy", inline="always")
def trace_chunk(begin, end, row, beam, scene, handle, sensor, work, tally):
    """Paths begin .. end-1, two at a time in rows ``row`` and ``row + 1``: both queries, then both
    events, so that the processor overlaps the two paths' event arithmetic (independent chains of
    divisions, square roots and random numbers); a slot whose path ends takes the next path.
    One body serves both slots and the last one alone: numba inlines the event kernels twice
    (with a third copy for the last slot, the kernel took 56 s to compile)."""
    a, b = row, row + 1
    busy_a, busy_b, number = False, False, begin
    if number < end:
        start_path(work.paths, work.rays, a, number, beam, scene)
        busy_a, number = True, number + 1
    if number < end:
        start_path(work.paths, work.rays, b, number, beam, scene)
        busy_b, number = True, number + 1
    while busy_a or busy_b:
        if busy_a:
            query(handle, work, a)
        if busy_b:
            query(handle, work, b)
        tally.counts[SEGMENTS] += busy_a + busy_b
        if busy_a:
            busy_a, number = event(work, a, number, end, handle, beam, scene, sensor, tally)
        if busy_b:
            busy_b, number = event(work, b, number, end, handle, beam, scene, sensor, tally)


@numba.njit(cache=True, error_model="numpy", inline="always")
def event(work, row, number, end, handle, beam, scene, sensor, tally):
    """The path in ``row`` met the hit Embree left in its record: follow it, and prepare its next
    segment, or start path ``number`` in its row if it ended and paths are left. Returns (row
    busy, next path number)."""
    prim, t, normal = embree.hit_of(handle, work.records, row)
    alive, o, d = follow(work.paths, work.rays, row, (prim, np.float64(t), normal), scene, sensor, beam.max_order,
                         tally)
    if alive:
        prepare_segment(work.rays, row, o, d, scene)
        return True, number
    if number < end:
        start_path(work.paths, work.rays, row, number, beam, scene)
        return True, number + 1
    return False, number


@numba.njit(cache=True, error_model="numpy", _nrt=False)
def add_chunks(total, work, count):
    """Add the tallies of rows 0 .. count-1 to ``total``, in row (= chunk) order, whatever thread
    traced which chunk."""
    for j in range(count):
        _add_row(total.exit_weight, work.exit_weight, j)
        _add_row(total.energy, work.energy, j)
        for k in range(work.counts.shape[1]):
            total.counts[k] += work.counts[j, k]


@numba.njit(cache=True, error_model="numpy", _nrt=False)
def _add_row(total, rows, j):
    """total += rows[j], elementwise, for the ranks a tally takes (records.Tally: one albedo has
    no albedo axis; the rank of an argument is known when numba compiles)."""
    if total.ndim == 1:
        for a in range(total.shape[0]):
            total[a] += rows[j, a]
    elif total.ndim == 2:
        for a in range(total.shape[0]):
            for b in range(total.shape[1]):
                total[a, b] += rows[j, a, b]
    else:
        for a in range(total.shape[0]):
            for b in range(total.shape[1]):
                for c in range(total.shape[2]):
                    total[a, b, c] += rows[j, a, b, c]


@numba.njit(cache=True, error_model="numpy", inline="always")
def query(handle, work, j):
    """Embree's closest hit on the segment in row j, left in its record (and the query logged if
    a ray log is kept)."""
    rays = work.rays
    embree.clear_hit(work.records[j])  # the segment is in the query already (prepare_segment)
    if len(work.log):
        k = work.logged[0]
        work.logged[0] = k + 1
        if k < len(work.log):
            for axis in range(3):
                work.log[k, axis] = rays.origin[j, axis]
                work.log[k, 3 + axis] = rays.direction[j, axis]
            work.log[k, 6] = rays.tfar[j]
    embree.trace(handle.handle, work.records, j)
