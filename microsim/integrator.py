"""The wavefront path tracer: Embree finds hits for a whole batch of rays, numba does the rest.

A batch of paths is traced as a loop of segments. Each pass hands every live ray to Embree
in one call (float32 origins, directions and the distance ``tfar`` to the edge of the tile's
slab), then one numba kernel advances every ray: surface hits are projected onto the analytic
shape (float64), scattered by their material, roulette'd and offset; rays that reach the tile
side wrap to the opposite side; rays that reach ``z_top`` leave and are binned on the sensor by
scattering order; rays that reach ``z_bottom`` are transmitted. Live rays are compacted in
place and their next segment prepared in the same pass.

Self-intersection: a scattered ray starts from the hit projected onto the analytic surface
(for spheres and ellipsoids: onto the mesh's circumscribed surface, outside the own convex
mesh) and offset along the analytic normal by max(1e-6 x shape size, 8 float32 spacings of the
coordinates). A ray that meets a triangle from behind is inside a solid by round-off (at the
seam of overlapping shapes); it passes through and the event is counted.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from .materials import scatter
from .rng import path_state, uniform
from .scene import MaterialTable, Scene
from .sensor import cell_index
from .shapes import Shapes, surface_point

#: segment ends: the tile side (wrap), the top (leave), the bottom (transmitted)
SIDE_X, SIDE_Y, TOP, BOTTOM = 0, 1, 2, 3
#: Russian roulette: a path whose weight falls below this survives with probability weight / ROULETTE_WEIGHT
ROULETTE_WEIGHT = 0.05
#: a path scattered this many times is truncated (its weight is reported, never dropped)
MAX_INTERACTIONS = 100_000
#: a path that goes this many segments without an interaction (tile-side crossings, pass-throughs)
#: is truncated: only a ray parallel to the surface in empty space could get there
MAX_IDLE_SEGMENTS = 20_000
ORDERS = 4  # tallies for orders 1, 2, 3, 4+
FLOAT32_EPS = 2.0**-23

# indices of the energy and event counters of a batch
TRANSMITTED, TRUNCATED, ABSORBED = 0, 1, 2
N_ENERGY = 3
SEGMENTS, INSIDE_HITS, ROULETTE_KILLS = 0, 1, 2
N_COUNTS = 3


@dataclass
class BatchTally:
    """What one batch of paths produced (sums of weights, not yet divided by the path count)."""

    paths: int
    exit_weight: np.ndarray  # (ORDERS, n_cells)
    energy: np.ndarray  # (N_ENERGY,) transmitted, truncated, absorbed
    counts: np.ndarray  # (N_COUNTS,) segments, inside hits, roulette kills


class PathState:
    """Structure-of-arrays state of a batch of paths.

    The ray of each path is kept only in float32, as Embree takes it: hit points are rebuilt in
    float64 and projected onto the exact surface, and scattered rays start at least 8 float32
    spacings off it, so the rounding of origins and directions never reaches the geometry.
    """

    def __init__(self, n: int):
        self.weight = np.empty(n)
        self.order = np.empty(n, np.int32)
        self.idle = np.empty(n, np.int32)
        self.rng = np.empty(n, np.uint64)
        self.segment_end = np.empty(n, np.int8)
        self.ray_origin = np.empty((n, 3), np.float32)
        self.ray_direction = np.empty((n, 3), np.float32)
        self.ray_tfar = np.empty(n, np.float32)


def trace_batch(scene, embree_scene, sensor, wi, n_paths: int, key: np.uint64, max_order: int, state=None):
    """Trace ``n_paths`` paths arriving along -``wi``; return their :class:`BatchTally`.

    ``key`` selects the random stream (see :mod:`microsim.rng`); ``max_order`` = 0 means
    unlimited, k > 0 truncates a path at its (k+1)-th interaction. ``state`` may be a
    :class:`PathState` of at least ``n_paths`` rows to reuse.
    """
    if state is None or len(state.weight) < n_paths:
        state = PathState(n_paths)
    exit_weight = np.zeros((ORDERS, sensor.n_cells))
    energy = np.zeros(N_ENERGY)
    counts = np.zeros(N_COUNTS, np.int64)
    s = state
    geometry = (scene.tile, scene.z_top, scene.z_bottom)
    spawn_paths(n_paths, np.uint64(key), np.asarray(wi, np.float64), *geometry,
                s.weight, s.order, s.idle, s.rng, s.segment_end, s.ray_origin, s.ray_direction, s.ray_tfar)
    n = n_paths
    while n > 0:
        hit = embree_scene.run(s.ray_origin[:n], s.ray_direction[:n], dists=s.ray_tfar[:n], output=1)
        counts[SEGMENTS] += n
        n = advance(n, hit["primID"], s.ray_tfar, hit["Ng"],
                    s.weight, s.order, s.idle, s.rng, s.segment_end, s.ray_origin, s.ray_direction,
                    scene.face_shape, scene.shapes.kind, scene.shapes.params, scene.shapes.material,
                    scene.shapes.size, scene.materials.kind, scene.materials.params, *geometry,
                    sensor.ring_counts, sensor.ring_start, sensor.ring_of, max_order,
                    exit_weight, energy, counts)
    return BatchTally(n_paths, exit_weight, energy, counts)


class _NoHits:
    """Stands in for an Embree scene in which nothing can be hit."""

    @staticmethod
    def run(origins, directions, dists, output):
        n = len(origins)
        return {"primID": np.full(n, -1, np.int32), "Ng": np.zeros((n, 3), np.float32)}


def compile_kernels(sensor) -> None:
    """Compile (or load from numba's cache) the tracer's kernels in this process.

    Called before worker processes are forked, so that they inherit the machine code instead
    of each loading it again. Every scene has the same array types, so an empty one will do.
    """
    empty = Scene(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), Shapes.empty(),
                  MaterialTable.from_specs([{"kind": "absorber"}]), 1.0, 1.0, -1.0)
    trace_batch(empty, _NoHits(), sensor, np.array([0.0, 0.0, 1.0]), 1, np.uint64(0), 0)


@numba.njit(cache=True, error_model="numpy", inline="always")
def prepare_segment(i, ox, oy, oz, dx, dy, dz, tile, z_top, z_bottom, segment_end, ray_origin, ray_direction,
                    ray_tfar):
    """Store ray i in float32, and its distance to the boundary of the tile's slab and which side it meets."""
    ray_origin[i, 0], ray_origin[i, 1], ray_origin[i, 2] = ox, oy, oz
    ray_direction[i, 0], ray_direction[i, 1], ray_direction[i, 2] = dx, dy, dz
    ox, oy, oz = np.float64(ray_origin[i, 0]), np.float64(ray_origin[i, 1]), np.float64(ray_origin[i, 2])
    dx, dy, dz = np.float64(ray_direction[i, 0]), np.float64(ray_direction[i, 1]), np.float64(ray_direction[i, 2])
    # the vertical boundary first; a side is met first only if dist_side < |d_side| t, which is
    # tested without dividing (most segments end at a surface or at the top, not at a side)
    if dz > 0.0:
        t, end = (z_top - oz) / dz, TOP
    elif dz < 0.0:
        t, end = (z_bottom - oz) / dz, BOTTOM
    else:
        t, end = math.inf, TOP
    side_x = tile - ox if dx > 0.0 else ox
    if side_x < abs(dx) * t:
        t, end = side_x / abs(dx), SIDE_X
    side_y = tile - oy if dy > 0.0 else oy
    if side_y < abs(dy) * t:
        t, end = side_y / abs(dy), SIDE_Y
    segment_end[i] = end
    ray_tfar[i] = max(t, 0.0)


@numba.njit(cache=True, error_model="numpy")
def spawn_paths(n, key, wi, tile, z_top, z_bottom, weight, order, idle, rng, segment_end, ray_origin, ray_direction,
                ray_tfar):
    """Start n paths at uniform positions of the tile at z_top, travelling along -wi."""
    for i in range(n):
        rng[i] = path_state(key, i)
        x = uniform(rng, i) * tile
        y = uniform(rng, i) * tile
        weight[i] = 1.0
        order[i] = 0
        idle[i] = 0
        prepare_segment(i, x, y, z_top, -wi[0], -wi[1], -wi[2], tile, z_top, z_bottom, segment_end,
                        ray_origin, ray_direction, ray_tfar)


@numba.njit(cache=True, error_model="numpy", inline="always")
def wrap(v, tile):
    """v folded into [0, tile); v is at most one tile outside, so no division is needed."""
    if v < 0.0:
        return v + tile
    if v >= tile:
        return v - tile
    return v


@numba.njit(cache=True, error_model="numpy")
def advance(n, prim, tfar, ng, weight, order, idle, rng, segment_end, ray_origin, ray_direction,
            face_shape, shape_kind, shape_params, shape_material, shape_size, material_kind, material_params,
            tile, z_top, z_bottom, ring_counts, ring_start, ring_of, max_order, exit_weight, energy, counts):
    """Advance every live ray by the segment Embree traced; compact survivors; return their count.

    ``tfar`` holds Embree's hit distances on entry and the next segments' lengths on return
    (survivor ``live`` is written after ray ``i >= live`` has been read).
    """
    live = 0
    for i in range(n):
        ox, oy, oz = np.float64(ray_origin[i, 0]), np.float64(ray_origin[i, 1]), np.float64(ray_origin[i, 2])
        dx, dy, dz = np.float64(ray_direction[i, 0]), np.float64(ray_direction[i, 1]), np.float64(ray_direction[i, 2])
        w = weight[i]
        k = order[i]
        keep = True
        p = prim[i]
        if p >= 0:
            t = np.float64(tfar[i])
            hx, hy, hz = ox + t * dx, oy + t * dy, oz + t * dz
            s = face_shape[p]
            facing = dx * ng[i, 0] + dy * ng[i, 1] + dz * ng[i, 2]
            if facing >= 0.0:
                # back face: the ray is inside a solid by round-off (at the seam of overlapping
                # shapes); it passes through, far enough along d to clear the face in float32
                counts[INSIDE_HITS] += 1
                gap = max(1e-6 * shape_size[s], 8.0 * FLOAT32_EPS * max(abs(hx), abs(hy), abs(hz)))
                cosine = facing / math.sqrt(ng[i, 0] ** 2 + ng[i, 1] ** 2 + ng[i, 2] ** 2)
                nudge = gap / max(cosine, 1e-3)
                ox, oy, oz = wrap(hx + nudge * dx, tile), wrap(hy + nudge * dy, tile), hz + nudge * dz
                idle[i] += 1
            elif max_order > 0 and k >= max_order:
                energy[TRUNCATED] += w
                keep = False
            else:
                px, py, pz, nx, ny, nz = surface_point(shape_kind[s], shape_params[s], hx, hy, hz)
                m = shape_material[s]
                dx, dy, dz, factor, cut = scatter(material_kind[m], material_params[m], rng, i,
                                                  dx, dy, dz, nx, ny, nz)
                energy[ABSORBED] += w * (1.0 - factor - cut)
                energy[TRUNCATED] += w * cut
                w *= factor
                k += 1
                if w <= 0.0:
                    keep = False
                elif k >= MAX_INTERACTIONS:
                    energy[TRUNCATED] += w
                    keep = False
                else:
                    if w < ROULETTE_WEIGHT:
                        if uniform(rng, i) * ROULETTE_WEIGHT < w:
                            w = ROULETTE_WEIGHT
                        else:
                            counts[ROULETTE_KILLS] += 1
                            keep = False
                    spacing = FLOAT32_EPS * max(abs(px), abs(py), abs(pz))
                    offset = max(1e-6 * shape_size[s], 8.0 * spacing)
                    ox = wrap(px + offset * nx, tile)
                    oy = wrap(py + offset * ny, tile)
                    oz = pz + offset * nz
                    idle[i] = 0
        else:
            t = np.float64(tfar[i])  # Embree leaves tfar unchanged on a miss: the segment's length
            end = segment_end[i]
            if end == TOP:
                c = cell_index(dx, dy, dz, ring_counts, ring_start, ring_of)
                exit_weight[min(k, 4) - 1, c] += w
                keep = False
            elif end == BOTTOM:
                energy[TRANSMITTED] += w
                keep = False
            else:
                idle[i] += 1
                ox, oy, oz = ox + t * dx, oy + t * dy, oz + t * dz
                if end == SIDE_X:
                    ox = 0.0 if dx > 0.0 else tile
                    oy = wrap(oy, tile)
                else:
                    oy = 0.0 if dy > 0.0 else tile
                    ox = wrap(ox, tile)
        if keep and idle[i] >= MAX_IDLE_SEGMENTS:
            energy[TRUNCATED] += w
            keep = False
        if keep:
            weight[live] = w
            order[live] = k
            idle[live] = idle[i]
            rng[live] = rng[i]
            prepare_segment(live, ox, oy, oz, dx, dy, dz, tile, z_top, z_bottom, segment_end, ray_origin, ray_direction,
                            tfar)
            live += 1
    return live
