"""The sphere-grid backend of the surface tracer: exact spheres met by walking a uniform grid.

A scene of exact spheres traced with ``intersector = "grid"`` (geometry/poisson_spheres.py,
geometry/packed_spheres.py, and the grains of geometry/micrograins.py) is the same spheres as
Embree's native ones, its periodic images included, but no Embree scene is built: the slab
[0, L_x) x [0, L_y) x [z_bottom, z_top] is cut into cells (:class:`SphereCells`, each listing
every sphere that reaches into it), and a segment's
first hit is found by walking the cells it crosses, in order (Amanatides and Woo's traversal),
testing each listed sphere with the exact ray-sphere roots in float64 on the float64 centres (the
shapes' own, where Embree has float32). As Embree does, a sphere is met at its nearer root at or
beyond the origin, else at its farther one (from inside: a back face, which the path passes);
the walk ends in the first cell whose exit lies beyond the nearest root found, or at the
segment's end. The ``[base]``, if any, is met where the segment reaches it before any sphere. Segments start in
the tile and end at its sides (:func:`~.surface_transport.prepare_segment`), so the walk needs
no wrap. Spheres that stand for ellipsoids (micrograins: the native spheres of the frame scaled by
``scene.sphere_scale`` in x and y) are walked in that frame: the segment is mapped into it (the
ray parameter t is the same in both frames) and the sphere's normal back by the inverse
transpose, as Embree's instance does. The events are :mod:`.surface_transport`'s, as on the other backends; one path at a
time; next-event estimation's shadow rays walk the same grid. The cell side: see
geometry/sphere_cells.py; the speeds: docs/developer/performance.md, "Sphere scenes: a grid
walk against Embree".
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


class SphereCells(NamedTuple):
    """A slab's spheres on a uniform grid, as the walk reads it. ``spheres`` (E, 4) float64: x, y,
    z, r of each listed sphere, cell after cell (``starts`` (cells + 1,) into it; cell (a, b, k)
    is number (a counts[1] + b) counts[2] + k), ``prims`` (E,) the primitive each is in the scene;
    ``counts`` (3,) the cells along x, y, z and ``side`` (3,) their sides, from the corner
    (0, 0, ``z_low``); the [base]'s height and primitive (-1: no base); ``scale`` (2,) the x and
    y factors of the spheres' frame (1, 1: the world's)."""

    spheres: np.ndarray
    prims: np.ndarray
    starts: np.ndarray
    counts: np.ndarray
    side: np.ndarray
    z_low: float
    base_z: float
    base_prim: int
    scale: np.ndarray


class SphereGridWorld(NamedTuple):
    """What the sphere-grid backend's kernels trace: the scene's arrays and its sphere cells."""

    scene: object
    cells: SphereCells


def empty_cells() -> SphereCells:
    """A grid of one empty cell: what the kernels are compiled on."""
    return SphereCells(np.zeros((0, 4)), np.zeros(0, np.int64), np.zeros(2, np.int64), np.ones(3, np.int64),
                       np.ones(3), 0.0, -math.inf, -1, np.ones(2))


def backend(scene, threads: int, estimators):
    return SphereGridBackend(scene, estimators, threads)


def compile_kernels(beam, scene, setups, estimators) -> None:
    """Compile (or load) :func:`trace_chunks` for these types, tracing nothing."""
    work = workspace(1, estimators, albedos=len(beam.albedo_scale))
    trace_chunks(0, 0, 0, beam, SphereGridWorld(scene.arrays(), empty_cells()), setups, work)


class SphereGridBackend:
    """The scene's sphere cells (``scene.grid``), traced by chunks on ``threads`` threads."""

    name = "sphere_grid"

    def __init__(self, scene, estimators, threads: int = 1):
        if not isinstance(scene.grid, SphereCells):
            raise ValueError("the sphere-grid backend traces sphere scenes with intersector = 'grid' only")
        self.cells, self.estimators, self.threads = scene.grid, estimators, threads

    def trace(self, beam, scene, setups):
        work = workspace(wave_rows(beam.n_paths, self.threads), self.estimators, 0, len(beam.albedo_scale))
        world = SphereGridWorld(scene, self.cells)
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
                hit = segment_hit(world.cells, work.rays, row)
                alive, o, d = follow(work, row, hit, world, setups, beam.max_order, tally)
                if alive:
                    prepare_segment(work.rays, row, o, d, scene)


@numba.njit(cache=True, error_model="numpy", inline="always")
def segment_hit(cells, rays, i):
    """(primitive or -1, t, outward normal) of the first sphere (or the base) the segment in row i
    meets, the ray in float32 as Embree would take it, up to its tfar; in the spheres' frame,
    the normal mapped back to the world's (module doc)."""
    o, d = in_frame(cells.scale, rays.origin[i], rays.direction[i])
    prim, t, n = walk(cells, o, d, np.float64(rays.tfar[i]))
    return prim, t, (n[0] * cells.scale[0], n[1] * cells.scale[1], n[2])


@numba.njit(cache=True, error_model="numpy", inline="always")
def in_frame(scale, origin, direction):
    """(o, d) in float64 of a float32 ray, mapped into the frame scaled by ``scale`` in x and y."""
    o = (np.float64(origin[0]) * scale[0], np.float64(origin[1]) * scale[1], np.float64(origin[2]))
    d = (np.float64(direction[0]) * scale[0], np.float64(direction[1]) * scale[1], np.float64(direction[2]))
    return o, d


@numba.njit(cache=True, error_model="numpy", _nrt=False)
def walk(cells, o, d, end):
    """(primitive, t, outward unit normal) of the first sphere (or the base) the ray o + t d meets
    for t in [0, end]; (-1, end, (0, 0, 1)) if none. The ray starts in the slab's tile."""
    nx, ny, nz = cells.counts[0], cells.counts[1], cells.counts[2]
    ix, step_x, next_x, delta_x = axis_start(o[0], d[0], cells.side[0], nx)
    iy, step_y, next_y, delta_y = axis_start(o[1], d[1], cells.side[1], ny)
    iz, step_z, next_z, delta_z = axis_start(o[2] - cells.z_low, d[2], cells.side[2], nz)
    inverse_length2 = 1.0 / (d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    best, best_entry = math.inf, -1
    while True:
        cell = (ix * ny + iy) * nz + iz
        for e in range(cells.starts[cell], cells.starts[cell + 1]):
            t = sphere_root(cells.spheres[e], o, d, inverse_length2, best)
            if t < best:
                best, best_entry = t, e
        exit_t = min(next_x, next_y, next_z)
        if best <= exit_t or exit_t >= end:
            break
        if next_x == exit_t:
            ix += step_x
            next_x += delta_x
            if ix < 0 or ix >= nx:
                break
        elif next_y == exit_t:
            iy += step_y
            next_y += delta_y
            if iy < 0 or iy >= ny:
                break
        else:
            iz += step_z
            next_z += delta_z
            if iz < 0 or iz >= nz:
                break
    if cells.base_prim >= 0 and d[2] < 0.0:
        t = (cells.base_z - o[2]) / d[2]
        if 0.0 <= t <= end and t < best:  # the base before any sphere (grains' lower halves lie under it)
            return cells.base_prim, t, (0.0, 0.0, 1.0)
    if best <= end:
        s = cells.spheres[best_entry]
        r = 1.0 / s[3]
        normal = ((o[0] + best * d[0] - s[0]) * r, (o[1] + best * d[1] - s[1]) * r, (o[2] + best * d[2] - s[2]) * r)
        return cells.prims[best_entry], best, normal
    return -1, end, (0.0, 0.0, 1.0)


def first_hits(cells, origins, directions, tfar):
    """(primitive or -1, t) of :func:`walk` on each ray (rows of ``origins``, ``directions`` and
    ``tfar``, float32 as the tracer's queries are, in the world's frame): a batch of queries
    replayed, as the tests and the throughput benchmark replay the tracer's."""
    prims, ts = np.empty(len(origins), np.int64), np.empty(len(origins))
    fill_first_hits(cells, origins, directions, tfar, prims, ts)
    return prims, ts


@numba.njit(cache=True, error_model="numpy")
def fill_first_hits(cells, origins, directions, tfar, prims, ts):
    """:func:`first_hits` into ``prims`` and ``ts`` (a timed replay writes into arrays written before)."""
    for k in range(len(origins)):
        o, d = in_frame(cells.scale, origins[k], directions[k])
        prims[k], ts[k], _ = walk(cells, o, d, np.float64(tfar[k]))


@numba.njit(cache=True, error_model="numpy", inline="always")
def axis_start(p, d, side, count):
    """Along one axis, for a ray at p (from the grid's corner) along d: its cell (clamped to the
    grid), the step, the t of the first cell boundary it crosses and the t between boundaries."""
    index = min(max(int(math.floor(p / side)), 0), count - 1)
    if d > 0.0:
        return index, 1, ((index + 1) * side - p) / d, side / d
    if d < 0.0:
        return index, -1, (index * side - p) / d, -side / d
    return index, 0, math.inf, math.inf


@numba.njit(cache=True, error_model="numpy", inline="always")
def sphere_root(sphere, o, d, inverse_length2, best):
    """t >= 0 at which the ray o + t d meets the sphere (x, y, z, r) = ``sphere``: the nearer root,
    else (from inside) the farther one; inf if neither (``inverse_length2`` = 1 / |d|^2), or if,
    from outside, the sphere lies behind the origin or its nearer root at ``best`` or beyond (told
    without the square root: -b - best >= 0 and (-b - best)^2 >= disc; one branch for the three
    misses, which most listed spheres are)."""
    ox, oy, oz = o[0] - sphere[0], o[1] - sphere[1], o[2] - sphere[2]
    b = (ox * d[0] + oy * d[1] + oz * d[2]) * inverse_length2
    c = (ox * ox + oy * oy + oz * oz - sphere[3] * sphere[3]) * inverse_length2
    disc = b * b - c
    beyond = -b - best
    if (disc < 0.0) | ((c > 0.0) & ((b > 0.0) | ((beyond >= 0.0) & (beyond * beyond >= disc)))):
        return math.inf
    root = math.sqrt(disc)
    if -b - root >= 0.0:
        return -b - root
    if -b + root >= 0.0:
        return -b + root
    return math.inf


EVALUATE.register(SphereGridWorld)(evaluate_on_shape)


@VISIBILITY.register(SphereGridWorld)
def visible_over_sphere_grid(world, work, i, state, wo):
    """:func:`~.surface_transport.visible_through_tile`, the walk on each piece."""
    return visible_through_tile(world, work, i, state, wo, met_on_sphere_grid)


@numba.njit(cache=True, error_model="numpy", inline="always")
def met_on_sphere_grid(world, work, i):
    """Whether the segment in row i meets a sphere (or the base)."""
    return segment_hit(world.cells, work.rays, i)[0] >= 0
