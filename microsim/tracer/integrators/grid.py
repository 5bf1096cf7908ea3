"""The grid backend of the surface tracer: a heightfield's triangles met by walking its grid.

A heightfield traced with ``intersector = "grid"`` (geometry/heightfield.py) is the same
triangles as with ``"triangles"``, two a cell split as :func:`microsim.geometry.heightfield.triangulate`
splits them, but no Embree scene is built: a segment's first hit is found by walking the cells
its projection crosses, in order (Amanatides and Woo's traversal), each skipped unless the
segment's height over it reaches the cell's highest corner, else its two triangles tested
(Moller and Trumbore), in float64 on the float64 heights (Embree: float32 vertices). The first hit
ends the walk, as does rising above the surface's highest point; a segment that meets no facet
meets the ``[base]``, if any. The events are :mod:`.surface_transport`'s, as on the other two
backends; one path at a time (the walk has no latency to hide). Why, and what it gains:
docs/developer/performance.md, "Gaussian heightfields: triangles or a grid walk".
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from microsim.core.tally import SEGMENTS
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


class HeightGrid(NamedTuple):
    """A periodic heightfield as the walk reads it: heights (n, n) float64, sample (i, j) at
    (i pixel, j pixel); each cell's highest corner; the highest point; the primitive of the tile's
    own face 0 in the scene (faces numbered as triangulate numbers them: cell c = i n + j has
    faces c and n^2 + c); the [base]'s height and primitive (-1: no base)."""

    heights: np.ndarray
    top: np.ndarray
    pixel: float
    highest: float
    first_face: int
    base_z: float
    base_prim: int

    @classmethod
    def of(cls, heights, pixel: float, first_face: int, base_z: float = -math.inf, base_prim: int = -1):
        heights = np.ascontiguousarray(heights, np.float64)
        corners = ((0, 0), (-1, 0), (0, -1), (-1, -1))  # (i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)
        top = np.maximum.reduce([np.roll(heights, shift, axis=(0, 1)) for shift in corners])
        return cls(heights, top, float(pixel), float(top.max()), int(first_face), float(base_z), int(base_prim))


class GridWorld(NamedTuple):
    """What the grid backend's kernels trace: the scene's arrays and its height grid."""

    scene: object
    grid: HeightGrid


def backend(scene, threads: int, estimators):
    return GridBackend(scene, estimators, threads)


def compile_kernels(beam, scene, setups, estimators) -> None:
    """Compile (or load) :func:`trace_chunks` for these types, tracing nothing."""
    work = workspace(1, estimators, albedos=len(beam.albedo_scale))
    world = GridWorld(scene.arrays(), HeightGrid.of(np.zeros((2, 2)), 1.0, 0))
    trace_chunks(0, 0, 0, beam, world, setups, work)


class GridBackend:
    """The scene's height grid (``scene.grid``), traced by chunks on ``threads`` threads."""

    name = "grid"

    def __init__(self, scene, estimators, threads: int = 1):
        if scene.grid is None:
            raise ValueError("the grid backend traces heightfields with intersector = 'grid' only")
        self.grid, self.estimators, self.threads = scene.grid, estimators, threads

    def trace(self, beam, scene, setups):
        work = workspace(wave_rows(beam.n_paths, self.threads), self.estimators, 0, len(beam.albedo_scale))
        world = GridWorld(scene, self.grid)
        return trace_in_waves(beam, self.estimators, self.threads, work,
                              lambda *share: trace_chunks(*share, beam, world, setups, work))


@numba.njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def trace_chunks(first, start, stop, beam, world, setups, work):
    """Trace chunks first+start .. first+stop-1 of the beam to completion, chunk first+j into tally
    row j, its paths one after the other in path row ROW_STRIDE j."""
    scene = world.scene
    for j in range(start, stop):
        chunk, row = first + j, ROW_STRIDE * j
        tally = chunk_tally(work, j, beam)
        for number in range(chunk * CHUNK_PATHS, min((chunk + 1) * CHUNK_PATHS, beam.n_paths)):
            start_path(work.paths, work.rays, row, number, beam, scene)
            alive = True
            while alive:
                tally.counts[SEGMENTS] += 1
                hit = segment_hit(world, work.rays, row)
                alive, o, d = follow(work, row, hit, world, setups, beam.max_order, tally)
                if alive:
                    prepare_segment(work.rays, row, o, d, scene)


@numba.njit(cache=True, error_model="numpy", inline="always")
def segment_hit(world, rays, i):
    """(primitive or -1, t, geometric normal) of the first facet the segment in row i meets (as
    Embree would report it: the ray in float32, up to its tfar)."""
    o = (np.float64(rays.origin[i, 0]), np.float64(rays.origin[i, 1]), np.float64(rays.origin[i, 2]))
    d = (np.float64(rays.direction[i, 0]), np.float64(rays.direction[i, 1]), np.float64(rays.direction[i, 2]))
    face, t = walk(world.grid, o, d, np.float64(rays.tfar[i]))
    if face < 0:
        return -1, t, (0.0, 0.0, 1.0)
    prm = world.scene.shape_params[world.scene.prim_shape[face]]
    return face, t, (prm[3], prm[4], prm[5])


@numba.njit(cache=True, error_model="numpy", _nrt=False)
def walk(grid, o, d, end):
    """(primitive, t) of the first facet (or the base) the ray o + t d meets for t in [0, end];
    (-1, end) if none. The ray starts in the tile and ends at or before its boundary."""
    h = grid.heights
    n, pixel = h.shape[0], grid.pixel
    i = min(max(int(o[0] / pixel), 0), n - 1)
    j = min(max(int(o[1] / pixel), 0), n - 1)
    step_i = 1 if d[0] > 0.0 else -1
    step_j = 1 if d[1] > 0.0 else -1
    next_i = ((i + (d[0] > 0.0)) * pixel - o[0]) / d[0] if d[0] != 0.0 else math.inf
    next_j = ((j + (d[1] > 0.0)) * pixel - o[1]) / d[1] if d[1] != 0.0 else math.inf
    delta_i = pixel / abs(d[0]) if d[0] != 0.0 else math.inf
    delta_j = pixel / abs(d[1]) if d[1] != 0.0 else math.inf
    t0 = 0.0
    while t0 <= end:
        if d[2] >= 0.0 and o[2] + t0 * d[2] > grid.highest:
            break
        t1 = min(next_i, next_j, end)
        if min(o[2] + t0 * d[2], o[2] + t1 * d[2]) <= grid.top[i, j]:
            face, t = cell_hit(h, pixel, i, j, o, d)
            # a hit beyond the cell's span belongs to another cell (met there, or not at all)
            if face >= 0 and t <= end and t <= t1 * (1.0 + 1e-12) + 1e-12:
                return grid.first_face + face, t
        if next_i < next_j:
            i += step_i
            t0, next_i = next_i, next_i + delta_i
        else:
            j += step_j
            t0, next_j = next_j, next_j + delta_j
        if i < 0 or i >= n or j < 0 or j >= n:
            break
    if grid.base_prim >= 0 and d[2] < 0.0:
        t = (grid.base_z - o[2]) / d[2]
        if 0.0 <= t <= end:
            return grid.base_prim, t
    return -1, end


def first_hits(grid, origins, directions, tfar):
    """(primitive or -1, t) of :func:`walk` on each ray (rows of ``origins``, ``directions`` and
    ``tfar``, float32 as the tracer's queries are): a batch of queries replayed, as the tests and
    the benchmarks replay the tracer's."""
    prims, ts = np.empty(len(origins), np.int64), np.empty(len(origins))
    fill_first_hits(grid, origins, directions, tfar, prims, ts)
    return prims, ts


@numba.njit(cache=True, error_model="numpy")
def fill_first_hits(grid, origins, directions, tfar, prims, ts):
    """:func:`first_hits` into ``prims`` and ``ts`` (a timed replay writes into arrays written before)."""
    for k in range(len(origins)):
        o = (np.float64(origins[k, 0]), np.float64(origins[k, 1]), np.float64(origins[k, 2]))
        d = (np.float64(directions[k, 0]), np.float64(directions[k, 1]), np.float64(directions[k, 2]))
        prims[k], ts[k] = walk(grid, o, d, np.float64(tfar[k]))


@numba.njit(cache=True, error_model="numpy", inline="always")
def cell_hit(h, pixel, i, j, o, d):
    """(face, t) of the nearer of cell (i, j)'s two triangles on the ray (either side), (-1, inf)
    if neither: faces c and n^2 + c of cell c = i n + j, split as triangulate splits it."""
    n = h.shape[0]
    i1, j1 = (i + 1) % n, (j + 1) % n
    x0, y0 = i * pixel, j * pixel
    a = (x0, y0, h[i, j])
    b = (x0 + pixel, y0, h[i1, j])
    c = (x0 + pixel, y0 + pixel, h[i1, j1])
    e = (x0, y0 + pixel, h[i, j1])
    if (i + j) % 2 == 0:
        first, second = triangle_hit(o, d, a, b, c), triangle_hit(o, d, a, c, e)
    else:
        first, second = triangle_hit(o, d, a, b, e), triangle_hit(o, d, b, c, e)
    cell = i * n + j
    if first <= second:
        return (cell, first) if first < math.inf else (-1, first)
    return n * n + cell, second


@numba.njit(cache=True, error_model="numpy", inline="always")
def triangle_hit(o, d, a, b, c):
    """t >= 0 at which the ray o + t d crosses triangle abc (either side), inf if it does not
    (Moller and Trumbore)."""
    e1 = (b[0] - a[0], b[1] - a[1], b[2] - a[2])
    e2 = (c[0] - a[0], c[1] - a[1], c[2] - a[2])
    p = (d[1] * e2[2] - d[2] * e2[1], d[2] * e2[0] - d[0] * e2[2], d[0] * e2[1] - d[1] * e2[0])
    det = e1[0] * p[0] + e1[1] * p[1] + e1[2] * p[2]
    if det == 0.0:
        return math.inf
    inv = 1.0 / det
    s = (o[0] - a[0], o[1] - a[1], o[2] - a[2])
    u = (s[0] * p[0] + s[1] * p[1] + s[2] * p[2]) * inv
    if u < 0.0 or u > 1.0:
        return math.inf
    q = (s[1] * e1[2] - s[2] * e1[1], s[2] * e1[0] - s[0] * e1[2], s[0] * e1[1] - s[1] * e1[0])
    v = (d[0] * q[0] + d[1] * q[1] + d[2] * q[2]) * inv
    if v < 0.0 or u + v > 1.0:
        return math.inf
    t = (e2[0] * q[0] + e2[1] * q[1] + e2[2] * q[2]) * inv
    return t if t >= 0.0 else math.inf


EVALUATE.register(GridWorld)(evaluate_on_shape)


@VISIBILITY.register(GridWorld)
def visible_over_grid(world, work, i, state, wo):
    """:func:`~.surface_transport.visible_through_tile`, the walk on each piece."""
    return visible_through_tile(world, work, i, state, wo, met_on_grid)


@numba.njit(cache=True, error_model="numpy", inline="always")
def met_on_grid(world, work, i):
    """Whether the segment in row i meets a facet (or the base)."""
    return segment_hit(world, work.rays, i)[0] >= 0
