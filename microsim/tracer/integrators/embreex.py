"""The embreex backend of the surface tracer: one ``embreex.run`` call per segment of all live paths.

A batch of paths is traced as a loop of segments (wavefront). Each pass hands every live ray to
Embree through embreex in one call, then :func:`advance` takes every ray through its event
(:func:`~microsim.tracer.integrators.surface_transport.follow`), compacts the live paths in place and prepares
their next segments. Every pass goes through Python and embreex, which loops over single rays
and allocates its outputs; the direct backend does without both. This one needs nothing but the
embreex package: it is the fallback where the direct binding cannot load, and it traces
triangles only.

Next-event estimation: Embree cannot be asked from inside the kernel, so the world's
:data:`~.walk.SEE` queues each shadow ray (from the point lifted off the surface, with the
estimator's payload) in a :class:`ShadowQueue`; after each pass, the queued rays are traced
through the tile a segment at a time (embreex's occluded query, wrapping at the tile's sides as
the direct backend's visibility does) and the payload of every ray that reaches ``z_top`` goes
to the estimators (:func:`microsim.tracer.estimators.hooks.each_seen`).

A unit's paths are traced in batches of at most ``BATCH_PATHS`` (paths keep their numbers, and
so their random streams), so that memory does not grow with ``paths``: about 70 bytes a path of
a batch (its row and embreex's outputs), 70 MB at most; with k points, batches of BATCH_PATHS / k
paths, and a shadow queue of at most BATCH_PATHS rays (SHADOW_BYTES each, about 60 MB).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from microsim.core.tally import SEGMENTS, empty_tally
from microsim.tracer.estimators import shadow_rays
from microsim.tracer.estimators.hooks import each_seen
from microsim.tracer.integrators.events import MAX_IDLE_SEGMENTS, move_path
from microsim.tracer.integrators.records import allocate_paths, allocate_rays
from microsim.tracer.integrators.surface_transport import (
    TOP,
    clearance,
    evaluate_on_shape,
    follow,
    prepare_segment,
    start_path,
    wrap_point,
    wrap_side,
)
from microsim.tracer.integrators.walk import EVALUATE, SEE

#: paths traced at once; their tallies are added batch after batch
BATCH_PATHS = 1 << 20
#: bytes of a queued shadow ray (its segment, payload and wraps) and of embreex's output for it
SHADOW_BYTES = 60
#: bytes a path row takes while its batch is traced (row, ray, outputs)
PATH_ROW_BYTES = 80


def batch_bytes(paths: int, shadow_rays: int) -> int:
    """Bytes the embreex backend works in for a unit of ``paths`` paths whose estimators queue
    ``shadow_rays`` shadow rays per event: a batch of path rows and its shadow queue."""
    rows = min(paths, BATCH_PATHS // max(shadow_rays, 1))
    return rows * (PATH_ROW_BYTES + shadow_rays * SHADOW_BYTES)


class ShadowQueue(NamedTuple):
    """Shadow rays waiting for Embree: their segments (as :class:`~.records.Rays`), their payloads
    (amount, point, order: :func:`microsim.tracer.estimators.points_hooks.on_interaction`), the tile sides each
    has wrapped at, and how many are queued (``count[0]``). A pass queues at most a ray a point
    for each path of the batch (one interaction a path), so rows x points never overflow."""

    rays: object
    amount: np.ndarray
    point: np.ndarray
    order: np.ndarray
    wraps: np.ndarray
    count: np.ndarray


def shadow_queue(capacity: int) -> ShadowQueue:
    return ShadowQueue(allocate_rays(capacity), np.zeros(capacity), np.zeros(capacity, np.int64),
                       np.zeros(capacity, np.int64), np.zeros(capacity, np.int32), np.zeros(1, np.int64))


class EmbreexWorld(NamedTuple):
    """What the shared event kernels trace on this backend: the scene's arrays (Embree is called
    from Python: no handle), and the queue of shadow rays that next-event estimation asks for."""

    scene: object
    shadows: ShadowQueue


EVALUATE.register(EmbreexWorld)(evaluate_on_shape)


@SEE.register(EmbreexWorld)
def queue_shadow_ray(world, work, i, state, wo, payload):
    """Queue the shadow ray from the surface point of ``state`` = (point, normal, shape), lifted
    as a scattered ray is, along wo, with ``payload``; none for wo below the surface's tangent
    plane or going down. Returns 0: what it sees is handed back later (module doc)."""
    scene, queue = world
    p, n, s = state
    if wo[0] * n[0] + wo[1] * n[1] + wo[2] * n[2] <= 0.0 or wo[2] <= 0.0:
        return 0.0
    j = queue.count[0]
    if j >= len(queue.amount):  # a pass has one interaction a path and a path k points at most
        raise IndexError("the shadow queue is full")
    queue.count[0] = j + 1
    prepare_segment(queue.rays, j, wrap_point(p, n, clearance(p, scene.shape_size[s]), scene.period), wo, scene)
    queue.amount[j], queue.point[j], queue.order[j] = payload
    queue.wraps[j] = 0
    return 0.0


class Lanes(NamedTuple):
    """The live paths of a batch and their segments (the direct backend's workspace has more)."""

    paths: object
    rays: object


def backend(scene, threads: int, estimators):
    if threads != 1:
        raise ValueError("the embreex backend traces on one thread")
    return EmbreexBackend(scene, estimators)


def compile_kernels(beam, scene, setups, estimators) -> None:
    """Compile (or load) spawn_paths, advance and settle_shadows, with no embreex scene (nothing
    to hit)."""
    EmbreexBackend(scene, estimators, embree=_NoHits()).trace(beam, scene.arrays(), setups)
    settle_shadows(0, shadow_queue(0), _NoHits.run(np.zeros((0, 3)), None, None, query="OCCLUDED"), scene.arrays(),
                   empty_tally(0, estimators, beam.albedo_scale))


class EmbreexBackend:
    """The scene's triangles in an embreex scene, traced a segment of every live path at a time."""

    name = "embreex"

    def __init__(self, scene, estimators, embree=None):
        """``embree``: any object with embreex's ``run(origins, directions, dists, output=1)`` in
        place of the embreex scene of ``scene`` (the throughput benchmark records rays through it)."""
        if embree is None and len(scene.spheres):
            raise ValueError("native spheres need the direct Embree backend (backend = \"direct\"); "
                             "the embreex backend traces triangles only (give subdivisions or mesh_error)")
        self.embree = embree_scene(scene.vertices, scene.faces) if embree is None else embree
        self.estimators = estimators
        self.paths, self.rays = allocate_paths(0), allocate_rays(0)

    def trace(self, beam, scene, setups):
        rays = shadow_rays(self.estimators)
        batch = BATCH_PATHS // max(rays, 1)
        rows = min(beam.n_paths, batch)
        if len(self.paths.weight) < rows:
            self.paths, self.rays = allocate_paths(rows), allocate_rays(rows)
        world = EmbreexWorld(scene, shadow_queue(rows * rays))
        tally = empty_tally(beam.n_paths, self.estimators, beam.albedo_scale)
        for first in range(0, beam.n_paths, batch):
            self._trace_batch(first, min(batch, beam.n_paths - first), beam, world, setups, tally)
        return tally

    def _trace_batch(self, first, n, beam, world, setups, tally):
        """Paths first .. first+n-1 of the beam, added to ``tally``."""
        paths, rays, scene = self.paths, self.rays, world.scene
        spawn_paths(paths, rays, first, n, beam, scene)
        while n > 0:
            hit = self.embree.run(rays.origin[:n], rays.direction[:n], dists=rays.tfar[:n], output=1)
            tally.counts[SEGMENTS] += n
            n = advance(n, paths, rays, (hit["primID"], hit["Ng"]), world, setups, beam.max_order, tally)
            self._see_shadows(world, tally)

    def _see_shadows(self, world, tally):
        """Trace the queued shadow rays to the top of the tile or until occluded, a segment of all
        of them per embreex call, and hand the payload of each that gets there to the estimators."""
        shadows = world.shadows
        m = int(shadows.count[0])
        while m > 0:
            rays = shadows.rays
            blocked = self.embree.run(rays.origin[:m], rays.direction[:m], dists=rays.tfar[:m], query="OCCLUDED")
            m = settle_shadows(m, shadows, blocked, world.scene, tally)
        shadows.count[0] = 0


def embree_scene(vertices, faces):
    """A committed embreex scene of the triangles (built in the process that traces)."""
    from embreex import mesh_construction, rtcore_scene

    if not len(faces):
        return _NoHits()
    committed = rtcore_scene.EmbreeScene()
    mesh_construction.TriangleMesh(committed, vertices, faces)
    probe = np.zeros((1, 3), np.float32)
    committed.run(probe, probe + np.float32([0, 0, 1]), dists=np.zeros(1, np.float32))  # commits the BVH
    return committed


class _NoHits:
    """Stands in for an embreex scene in which nothing can be hit."""

    @staticmethod
    def run(origins, directions, dists, output=None, query="INTERSECT"):
        n = len(origins)
        if query == "OCCLUDED":
            return np.full(n, -1, np.int32)
        return {"primID": np.full(n, -1, np.int32), "Ng": np.zeros((n, 3), np.float32)}


@numba.njit(cache=True, error_model="numpy", _nrt=False)
def spawn_paths(paths, rays, first, n, beam, scene):
    """Start paths first .. first+n-1 of the beam in rows 0 .. n-1."""
    for i in range(n):
        start_path(paths, rays, i, first + i, beam, scene)


@numba.njit(cache=True, error_model="numpy", _nrt=False)
def settle_shadows(m, shadows, blocked, scene, tally):
    """Take the m queued shadow rays through the segment Embree tested (``blocked``: the geometry
    hit, -1 for none): a blocked ray is dropped, one that reached the top hands its payload to
    every estimator, one that reached a tile side wraps to the other and is queued again
    (compacted; dropped after MAX_IDLE_SEGMENTS wraps, as the direct backend's visibility).
    Returns how many are queued again."""
    rays = shadows.rays
    live = 0
    for j in range(m):
        if blocked[j] >= 0:
            continue
        end = rays.end[j]
        if end == TOP:
            each_seen(tally.estimates, tally, (shadows.amount[j], shadows.point[j], shadows.order[j]))
            continue
        if shadows.wraps[j] + 1 >= MAX_IDLE_SEGMENTS:
            continue
        o = (np.float64(rays.origin[j, 0]), np.float64(rays.origin[j, 1]), np.float64(rays.origin[j, 2]))
        d = (np.float64(rays.direction[j, 0]), np.float64(rays.direction[j, 1]), np.float64(rays.direction[j, 2]))
        o = wrap_side(o, d, np.float64(rays.tfar[j]), end, scene.period)
        shadows.amount[live], shadows.point[live], shadows.order[live] = shadows.amount[j], shadows.point[j], shadows.order[j]
        shadows.wraps[live] = shadows.wraps[j] + 1
        prepare_segment(rays, live, o, d, scene)
        live += 1
    return live


@numba.njit(cache=True, error_model="numpy", _nrt=False)
def advance(n, paths, rays, hits, world, setups, max_order, tally):
    """Take every live ray through the segment Embree traced; compact survivors; return their count.

    ``hits`` = (primitive, normal) arrays from embreex; ``world`` the scene's arrays and the
    shadow queue (:class:`EmbreexWorld`); ``rays.tfar`` holds Embree's hit distances
    on entry (unchanged on a miss: the segment's length) and the next segments' lengths on return
    (survivor ``live`` is written after ray ``i >= live`` has been read).
    """
    prim, normal = hits
    live, scene = 0, world.scene
    lanes = Lanes(paths, rays)
    for i in range(n):
        hit = (prim[i], np.float64(rays.tfar[i]), (normal[i, 0], normal[i, 1], normal[i, 2]))
        keep, o, d = follow(lanes, i, hit, world, setups, max_order, tally)
        if keep:
            move_path(paths, live, i)
            prepare_segment(rays, live, o, d, scene)
            live += 1
    return live
