"""The embreex backend of the surface tracer: one ``embreex.run`` call per segment of all live paths.

A batch of paths is traced as a loop of segments (wavefront). Each pass hands every live ray to
Embree through embreex in one call, then :func:`advance` takes every ray through its event
(:func:`~microsim.integrators.surface_transport.follow`), compacts the live paths in place and prepares
their next segments. Every pass goes through Python and embreex, which loops over single rays
and allocates its outputs; the direct backend does without both. This one needs nothing but the
embreex package: it is the fallback where the direct binding cannot load, and it traces
triangles only.

A unit's paths are traced in batches of at most ``BATCH_PATHS`` (paths keep their numbers, and
so their random streams), so that memory does not grow with ``paths``: about 70 bytes a path of
a batch (its row and embreex's outputs), 70 MB at most.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from ..tally import SEGMENTS, empty_tally
from .events import move_path
from .records import allocate_paths, allocate_rays
from .surface_transport import evaluate_on_shape, follow, prepare_segment, start_path
from .walk import EVALUATE

#: paths traced at once; their tallies are added batch after batch
BATCH_PATHS = 1 << 20


class EmbreexWorld(NamedTuple):
    """What the shared event kernels trace on this backend: the scene's arrays (Embree is called
    from Python: no handle, and no visibility query)."""

    scene: object


EVALUATE.register(EmbreexWorld)(evaluate_on_shape)


class Lanes(NamedTuple):
    """The live paths of a batch and their segments (the direct backend's workspace has more)."""

    paths: object
    rays: object


def backend(scene, threads: int, estimators):
    if threads != 1:
        raise ValueError("the embreex backend traces on one thread")
    return EmbreexBackend(scene, estimators)


def compile_kernels(beam, scene, sensor, estimators) -> None:
    """Compile (or load) spawn_paths and advance, with no embreex scene (nothing to hit)."""
    EmbreexBackend(scene, estimators, embree=_NoHits()).trace(beam, scene.arrays(), sensor)


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

    def trace(self, beam, scene, sensor):
        rows = min(beam.n_paths, BATCH_PATHS)
        if len(self.paths.weight) < rows:
            self.paths, self.rays = allocate_paths(rows), allocate_rays(rows)
        tally = empty_tally(beam.n_paths, self.estimators, beam.albedo_scale)
        for first in range(0, beam.n_paths, BATCH_PATHS):
            self._trace_batch(first, min(BATCH_PATHS, beam.n_paths - first), beam, scene, sensor, tally)
        return tally

    def _trace_batch(self, first, n, beam, scene, sensor, tally):
        """Paths first .. first+n-1 of the beam, added to ``tally``."""
        paths, rays = self.paths, self.rays
        spawn_paths(paths, rays, first, n, beam, scene)
        while n > 0:
            hit = self.embree.run(rays.origin[:n], rays.direction[:n], dists=rays.tfar[:n], output=1)
            tally.counts[SEGMENTS] += n
            n = advance(n, paths, rays, (hit["primID"], hit["Ng"]), scene, sensor, beam.max_order, tally)


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
    def run(origins, directions, dists, output):
        n = len(origins)
        return {"primID": np.full(n, -1, np.int32), "Ng": np.zeros((n, 3), np.float32)}


@numba.njit(cache=True, error_model="numpy", _nrt=False)
def spawn_paths(paths, rays, first, n, beam, scene):
    """Start paths first .. first+n-1 of the beam in rows 0 .. n-1."""
    for i in range(n):
        start_path(paths, rays, i, first + i, beam, scene)


@numba.njit(cache=True, error_model="numpy", _nrt=False)
def advance(n, paths, rays, hits, scene, sensor, max_order, tally):
    """Take every live ray through the segment Embree traced; compact survivors; return their count.

    ``hits`` = (primitive, normal) arrays from embreex; ``rays.tfar`` holds Embree's hit distances
    on entry (unchanged on a miss: the segment's length) and the next segments' lengths on return
    (survivor ``live`` is written after ray ``i >= live`` has been read).
    """
    prim, normal = hits
    live = 0
    lanes, world = Lanes(paths, rays), EmbreexWorld(scene)
    for i in range(n):
        hit = (prim[i], np.float64(rays.tfar[i]), (normal[i, 0], normal[i, 1], normal[i, 2]))
        keep, o, d = follow(lanes, i, hit, world, sensor, max_order, tally)
        if keep:
            move_path(paths, live, i)
            prepare_segment(rays, live, o, d, scene)
            live += 1
    return live
