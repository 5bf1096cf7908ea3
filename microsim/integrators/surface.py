"""The surface tracer: Embree finds hits for a whole batch of rays, numba does the rest.

A batch of paths is traced as a loop of segments (wavefront). Each pass hands every live ray to
Embree in one call (float32 origins, directions and the distance ``tfar`` to the edge of the
tile's slab); then :func:`advance` takes every ray through one event: a surface hit is
projected onto the analytic shape (float64), scattered by its material, roulette'd and offset
(:func:`interact`); a ray that meets a face from behind passes through (:func:`pass_through`);
a ray that reaches the tile side wraps to the opposite side (:func:`wrap_side`); a ray that
reaches ``z_top`` leaves and is binned on the sensor by scattering order; one that reaches
``z_bottom`` is transmitted. Live paths are compacted in place and their next segment prepared
in the same pass (:func:`prepare_segment`).

Reference counting: :func:`spawn_paths` and :func:`advance` allocate nothing, and are compiled
without numba's reference-counting runtime (``_nrt=False``), as are the kernels they call
without inlining (``scatter``, ``surface_point``, ``move_path``; a callee compiled with it
would bring its increfs along). With it, numba's IR inlining of the event kernels increfs and
decrefs every array of each bundle passed to them (14 atomic pairs per interaction): the kernel
ran 80 % slower (0.27 s against 0.15 s for the 1.75 M segments of 200 000 paths on the
phi = 0.3 scene); without it, 0.13 s. A kernel of the tracer therefore never allocates.

Self-intersection: a scattered ray starts from the hit projected onto the analytic surface
(for spheres and ellipsoids: onto the mesh's circumscribed surface, outside the own convex
mesh) and offset along the analytic normal by the :func:`clearance` max(OFFSET_SIZE x shape
size, OFFSET_SPACINGS float32 spacings of the coordinates). A ray that meets a triangle from
behind is inside a solid by round-off (at the seam of overlapping shapes); it passes through and
the event is counted.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..materials import Absorber, scatter
from ..rng import path_state, uniform
from ..scene import MaterialTable, Scene
from ..shapes import Shapes, surface_point
from .events import MAX_IDLE_SEGMENTS, exit_top, move_path, survives_interaction, truncate
from .records import (
    ABSORBED, INSIDE_HITS, SEGMENTS, TRANSMITTED, TRUNCATED, Hits, allocate_paths, allocate_rays, empty_tally,
)

#: segment ends: the tile side (wrap), the top (leave), the bottom (transmitted)
SIDE_X, SIDE_Y, TOP, BOTTOM = 0, 1, 2, 3
FLOAT32_EPS = 2.0**-23
#: a ray leaves a surface at least OFFSET_SIZE x the shape's size and OFFSET_SPACINGS float32
#: spacings of its coordinates away from it
OFFSET_SIZE = 1e-6
OFFSET_SPACINGS = 8.0
#: a ray passing a back face at a grazing angle is nudged as if at this cosine at least
MIN_PASS_COSINE = 1e-3


def embree_scene(scene: Scene):
    """A committed Embree scene of the triangles (built in the process that traces)."""
    from embreex import mesh_construction, rtcore_scene

    committed = rtcore_scene.EmbreeScene()
    mesh_construction.TriangleMesh(committed, scene.vertices, scene.faces)
    probe = np.zeros((1, 3), np.float32)
    committed.run(probe, probe + np.float32([0, 0, 1]), dists=np.zeros(1, np.float32))  # commits the BVH
    return committed


class SurfaceTracer:
    """Traces batches of paths through one realization of a surface scene (the integrator of
    every triangle-based scene kind). ``embree`` replaces the Embree scene built from ``scene``."""

    def __init__(self, scene: Scene, sensor, embree=None):
        self.scene = scene
        self.sensor = sensor
        self.arrays = scene.arrays()
        self.embree = embree_scene(scene) if embree is None else embree
        self.paths, self.rays = allocate_paths(0), allocate_rays(0)

    def trace(self, wi, n_paths: int, key, max_order: int):
        """Trace ``n_paths`` paths arriving along -``wi``; return their :class:`~records.Tally`.

        ``key`` selects the random stream (see :mod:`microsim.rng`); ``max_order`` = 0 means
        unlimited, k > 0 truncates a path at its (k+1)-th interaction.
        """
        if len(self.paths.weight) < n_paths:
            self.paths, self.rays = allocate_paths(n_paths), allocate_rays(n_paths)
        paths, rays = self.paths, self.rays
        tally = empty_tally(n_paths, self.sensor.n_cells)
        spawn_paths(paths, rays, n_paths, np.uint64(key), np.asarray(wi, np.float64), self.arrays)
        n = n_paths
        while n > 0:
            hit = self.embree.run(rays.origin[:n], rays.direction[:n], dists=rays.tfar[:n], output=1)
            tally.counts[SEGMENTS] += n
            n = advance(n, paths, rays, Hits(hit["primID"], hit["Ng"]), self.arrays, self.sensor, max_order, tally)
        return tally

    @classmethod
    def compile(cls, sensor) -> None:
        """Compile (or load from numba's cache) the kernels in this process.

        Called before worker processes are forked, so that they inherit the machine code instead
        of each loading it again. Every scene has the same array types, so an empty one will do.
        """
        empty = Scene(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), Shapes.empty(),
                      MaterialTable.of([Absorber(kind="absorber")]), 1.0, 1.0, -1.0)
        cls(empty, sensor, _NoHits()).trace(np.array([0.0, 0.0, 1.0]), 1, 0, 0)


class _NoHits:
    """Stands in for an Embree scene in which nothing can be hit."""

    @staticmethod
    def run(origins, directions, dists, output):
        n = len(origins)
        return {"primID": np.full(n, -1, np.int32), "Ng": np.zeros((n, 3), np.float32)}


@numba.njit(cache=True, error_model="numpy", _nrt=False)
def spawn_paths(paths, rays, n, key, wi, scene):
    """Start n paths at uniform positions of the tile at z_top, travelling along -wi."""
    for i in range(n):
        paths.rng[i] = path_state(key, i)
        x = uniform(paths.rng, i) * scene.tile
        y = uniform(paths.rng, i) * scene.tile
        paths.weight[i] = 1.0
        paths.order[i] = 0
        paths.idle[i] = 0
        prepare_segment(rays, i, (x, y, scene.z_top), (-wi[0], -wi[1], -wi[2]), scene)


@numba.njit(cache=True, error_model="numpy", _nrt=False)
def advance(n, paths, rays, hits, scene, sensor, max_order, tally):
    """Take every live ray through the segment Embree traced; compact survivors; return their count.

    ``rays.tfar`` holds Embree's hit distances on entry and the next segments' lengths on return
    (survivor ``live`` is written after ray ``i >= live`` has been read).
    """
    live = 0
    for i in range(n):
        o = (np.float64(rays.origin[i, 0]), np.float64(rays.origin[i, 1]), np.float64(rays.origin[i, 2]))
        d = (np.float64(rays.direction[i, 0]), np.float64(rays.direction[i, 1]), np.float64(rays.direction[i, 2]))
        t = np.float64(rays.tfar[i])  # Embree leaves tfar unchanged on a miss: the segment's length
        keep = True
        p = hits.prim[i]
        if p >= 0:
            h = (o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2])
            s = scene.face_shape[p]
            ng = (hits.normal[i, 0], hits.normal[i, 1], hits.normal[i, 2])
            facing = d[0] * ng[0] + d[1] * ng[1] + d[2] * ng[2]
            if facing >= 0.0:
                tally.counts[INSIDE_HITS] += 1
                o = pass_through(h, d, facing, ng, scene.shape_size[s], scene.tile)
                paths.idle[i] += 1
            elif max_order > 0 and paths.order[i] >= max_order:
                truncate(paths, i, tally)
                keep = False
            else:
                keep, o, d = interact(paths, i, h, d, s, scene, tally)
        else:
            end = rays.end[i]
            if end == TOP:
                exit_top(paths, i, d, sensor, tally)
                keep = False
            elif end == BOTTOM:
                tally.energy[TRANSMITTED] += paths.weight[i]
                keep = False
            else:
                paths.idle[i] += 1
                o = wrap_side(o, d, t, end, scene.tile)
        if keep and paths.idle[i] >= MAX_IDLE_SEGMENTS:
            truncate(paths, i, tally)
            keep = False
        if keep:
            move_path(paths, live, i)
            prepare_segment(rays, live, o, d, scene)
            live += 1
    return live


@numba.njit(cache=True, error_model="numpy", inline="always")
def interact(paths, i, h, d, s, scene, tally):
    """Path i meets shape s at h going along d: scatter it by the shape's material.

    Returns (survives, origin of the next segment off the surface, new direction); the path's
    weight and order are updated, absorbed and truncated weight tallied.
    """
    p, n = surface_point(scene.shape_code[s], scene.shape_params[s], h)
    m = scene.shape_material[s]
    d, factor, cut = scatter(scene.material_code[m], scene.material_params[m], paths.rng, i, d, n)
    w = paths.weight[i]
    tally.energy[ABSORBED] += w * (1.0 - factor - cut)
    tally.energy[TRUNCATED] += w * cut
    paths.weight[i] = w * factor
    paths.order[i] += 1
    if not survives_interaction(paths, i, tally):
        return False, p, d
    paths.idle[i] = 0
    offset = clearance(p, scene.shape_size[s])
    return True, wrap_point(p, n, offset, scene.tile), d


@numba.njit(cache=True, error_model="numpy", inline="always")
def pass_through(h, d, facing, ng, size, tile):
    """Origin past a back face hit at h: far enough along d to clear the face in float32."""
    cosine = facing / math.sqrt(ng[0] ** 2 + ng[1] ** 2 + ng[2] ** 2)
    nudge = clearance(h, size) / max(cosine, MIN_PASS_COSINE)
    return wrap_point(h, d, nudge, tile)


@numba.njit(cache=True, error_model="numpy", inline="always")
def clearance(p, size):
    """Distance a ray keeps from the surface it leaves at p (see module doc)."""
    return max(OFFSET_SIZE * size, OFFSET_SPACINGS * FLOAT32_EPS * max(abs(p[0]), abs(p[1]), abs(p[2])))


@numba.njit(cache=True, error_model="numpy", inline="always")
def wrap_point(p, v, distance, tile):
    """p + distance v, folded into the tile in x and y."""
    return wrap(p[0] + distance * v[0], tile), wrap(p[1] + distance * v[1], tile), p[2] + distance * v[2]


@numba.njit(cache=True, error_model="numpy", inline="always")
def wrap_side(o, d, t, end, tile):
    """The ray from o along d reaches the tile side ``end`` at t: continue from the opposite side."""
    x, y, z = o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]
    if end == SIDE_X:
        return (0.0 if d[0] > 0.0 else tile), wrap(y, tile), z
    return wrap(x, tile), (0.0 if d[1] > 0.0 else tile), z


@numba.njit(cache=True, error_model="numpy", inline="always")
def wrap(v, tile):
    """v folded into [0, tile); v is at most one tile outside, so no division is needed."""
    if v < 0.0:
        return v + tile
    if v >= tile:
        return v - tile
    return v


@numba.njit(cache=True, error_model="numpy", inline="always")
def prepare_segment(rays, i, o, d, scene):
    """Store ray i in float32, with its distance to the boundary of the tile's slab and which side it meets."""
    rays.origin[i, 0], rays.origin[i, 1], rays.origin[i, 2] = o
    rays.direction[i, 0], rays.direction[i, 1], rays.direction[i, 2] = d
    ox, oy, oz = np.float64(rays.origin[i, 0]), np.float64(rays.origin[i, 1]), np.float64(rays.origin[i, 2])
    dx, dy, dz = np.float64(rays.direction[i, 0]), np.float64(rays.direction[i, 1]), np.float64(rays.direction[i, 2])
    # the vertical boundary first; a side is met first only if dist_side < |d_side| t, which is
    # tested without dividing (most segments end at a surface or at the top, not at a side)
    if dz > 0.0:
        t, end = (scene.z_top - oz) / dz, TOP
    elif dz < 0.0:
        t, end = (scene.z_bottom - oz) / dz, BOTTOM
    else:
        t, end = math.inf, TOP
    side_x = scene.tile - ox if dx > 0.0 else ox
    if side_x < abs(dx) * t:
        t, end = side_x / abs(dx), SIDE_X
    side_y = scene.tile - oy if dy > 0.0 else oy
    if side_y < abs(dy) * t:
        t, end = side_y / abs(dy), SIDE_Y
    rays.end[i] = end
    rays.tfar[i] = max(t, 0.0)
