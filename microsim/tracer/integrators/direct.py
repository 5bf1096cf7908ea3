"""The direct backend of the surface tracer: numba calls Embree itself, paths run to completion.

Each chunk of paths (:mod:`.scheduler`) is traced to completion into a tally of its own, segment
after segment (``rtcIntersect1`` on an ``RTCRayHit`` record of its own, then the shared event
kernels of :mod:`.surface_transport`), with no Python between segments: two paths at a time
(``SLOTS``), both queries then both events, so that the processor overlaps the two paths' work;
a slot whose path ends takes the chunk's next path (:func:`trace_chunk`). All threads share one
committed Embree scene. Memory is one scene per process, a few hundred bytes per path row, and
the tallies of one wave. Why two slots, chunks of 8192 paths, and the designs measured against
this kernel: docs/developer/performance.md.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from microsim.core.tally import SEGMENTS
from microsim.tracer import embree
from microsim.tracer.integrators.scheduler import (
    CHUNK_PATHS,
    ROW_STRIDE,
    chunk_tally,
    trace_in_waves,
    wave_rows,
    workspace,
)
from microsim.tracer.integrators.surface_transport import (
    evaluate_on_shape,
    follow,
    prepare_segment,
    start_path,
    visible_through_tile,
)
from microsim.tracer.integrators.walk import EVALUATE, VISIBILITY


class DirectWorld(NamedTuple):
    """What the direct backend's kernels trace: the scene's arrays, and its committed Embree scene."""

    scene: object
    handle: object


def backend(scene, threads: int, estimators):
    return DirectBackend(scene, estimators, threads)


def compile_kernels(beam, scene, setups, estimators) -> None:
    """Compile (or load) :func:`trace_chunks` for these types, tracing nothing: no Embree call,
    no device. The library is loaded first: the kernel's machine code links to rtcIntersect1 by
    name (without it, loading the code segfaults)."""
    embree.available()
    work = workspace(1, estimators, albedos=len(beam.albedo_scale))
    world = DirectWorld(scene.arrays(), embree.SceneHandle(0, np.zeros(1, np.int64), np.ones(2)))
    trace_chunks(0, 0, 0, beam, world, setups, work)


class DirectBackend:
    """The scene in a committed Embree scene of its own, traced by chunks on ``threads`` threads.

    ``log_rays`` > 0 (one thread only) keeps the first ``log_rays`` queries, in the order they
    are made, in ``ray_log`` (rows of origin, direction, tfar): the throughput benchmark replays
    them through Embree alone.
    """

    name = "direct"

    def __init__(self, scene, estimators, threads: int = 1, log_rays: int = 0):
        if log_rays and threads != 1:
            raise ValueError("the ray log keeps the order of one thread: give threads = 1")
        self.embree = embree.Scene(scene.vertices, scene.faces, scene.spheres, sphere_scale=scene.sphere_scale)
        self.estimators, self.threads, self.log_rays = estimators, threads, log_rays
        self.ray_log = np.zeros((0, 7), np.float32)

    def trace(self, beam, scene, setups):
        work = workspace(wave_rows(beam.n_paths, self.threads), self.estimators, self.log_rays, len(beam.albedo_scale))
        world = DirectWorld(scene, self.embree.arrays())
        total = trace_in_waves(beam, self.estimators, self.threads, work,
                               lambda *share: trace_chunks(*share, beam, world, setups, work))
        self.ray_log = work.log[:min(work.logged[0], len(work.log))]
        return total


@numba.njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def trace_chunks(first, start, stop, beam, world, setups, work):
    """Trace chunks first+start .. first+stop-1 of the beam to completion, chunk first+j into tally
    row j, its paths in path row j (see :func:`trace_chunk`)."""
    for j in range(start, stop):
        chunk = first + j
        trace_chunk(chunk * CHUNK_PATHS, min((chunk + 1) * CHUNK_PATHS, beam.n_paths), ROW_STRIDE * j, beam, world,
                    setups, work, chunk_tally(work, j, beam))


@numba.njit(cache=True, error_model="numpy", inline="always")
def trace_chunk(begin, end, row, beam, world, setups, work, tally):
    """Paths begin .. end-1, two at a time in rows ``row`` and ``row + 1``: both queries, then both
    events, so that the processor overlaps the two paths' event arithmetic (independent chains of
    divisions, square roots and random numbers); a slot whose path ends takes the next path.
    One body serves both slots and the last one alone, so numba inlines the event kernels twice,
    not three times (compile times: docs/developer/performance.md, 'The direct backend')."""
    scene, handle = world
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
            busy_a, number = event(work, a, (number, end), beam, world, setups, tally)
        if busy_b:
            busy_b, number = event(work, b, (number, end), beam, world, setups, tally)


@numba.njit(cache=True, error_model="numpy", inline="always")
def event(work, row, waiting, beam, world, setups, tally):
    """The path in ``row`` met the hit Embree left in its record: follow it, and prepare its next
    segment, or start path ``number`` of ``waiting`` = (number, end) in its row if it ended and
    paths are left. Returns (row busy, next path number)."""
    (number, end), (scene, handle) = waiting, world
    prim, t, normal = embree.hit_of(handle, work.queries, row)
    alive, o, d = follow(work, row, (prim, np.float64(t), normal), world, setups, beam.max_order, tally)
    if alive:
        prepare_segment(work.rays, row, o, d, scene)
        return True, number
    if number < end:
        start_path(work.paths, work.rays, row, number, beam, scene)
        return True, number + 1
    return False, number


@numba.njit(cache=True, error_model="numpy", inline="always")
def query(handle, work, j):
    """Embree's closest hit on the segment in row j, left in its record (and the query logged if
    a ray log is kept)."""
    rays = work.rays
    embree.clear_hit(work.queries[j])  # the segment is in the query already (prepare_segment)
    if len(work.log):
        k = work.logged[0]
        work.logged[0] = k + 1
        if k < len(work.log):
            for axis in range(3):
                work.log[k, axis] = rays.origin[j, axis]
                work.log[k, 3 + axis] = rays.direction[j, axis]
            work.log[k, 6] = rays.tfar[j]
    embree.trace(handle.handle, work.queries, j)


EVALUATE.register(DirectWorld)(evaluate_on_shape)


@VISIBILITY.register(DirectWorld)
def visible_through_embree(world, work, i, state, wo):
    """:func:`~.surface_transport.visible_through_tile`, Embree's occluded query on each piece."""
    return visible_through_tile(world, work, i, state, wo, occluded_in_embree)


@numba.njit(cache=True, error_model="numpy", inline="always")
def occluded_in_embree(world, work, i):
    """Whether anything lies on the segment in row i (Embree's occluded query)."""
    return embree.is_occluded(world.handle.handle, work.queries, i)
