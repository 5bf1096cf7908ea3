"""The surface transport: paths through triangles and spheres, one segment and one event at a time.

A path starts at a uniform point of the tile at ``z_top`` (:func:`start_path`). Each segment is
stored in float32 as Embree takes it, with its distance ``tfar`` to the boundary of the tile's
slab and which boundary that is (:func:`prepare_segment`). Embree finds the closest hit on it;
:func:`follow` takes the path through the event there: a surface hit is projected onto the
analytic shape (float64), then :func:`~microsim.tracer.integrators.walk.take_event` scatters it by its
material and offsets it (:func:`interact_on_shape`), and books it;
a ray that meets a surface from behind passes through (:func:`pass_through`); a ray that reaches
the tile side wraps to the opposite side (:func:`wrap_side`); one that reaches ``z_top`` leaves
(the run's estimators see it); one that reaches ``z_bottom`` is transmitted.
The tile is [0, L_x) x [0, L_y) (``scene.period``, :class:`microsim.tracer.scene.SceneArrays`): x is
folded and wrapped by L_x, y by L_y (for a square tile, the arithmetic of a tile of one side).
These kernels are shared by the surface tracer's two backends (:mod:`.surface`), which differ
only in how they call Embree and schedule paths: :mod:`.direct` and :mod:`.embreex`.

Reference counting: the backends' kernels allocate nothing and are compiled without numba's
reference-counting runtime (``_nrt=False``), as are the kernels they call without inlining
(``scatter``, ``surface_point``, ``move_path``; a callee compiled with it would bring its increfs
along). With it, numba's IR inlining of the event kernels increfs and decrefs every array of
each bundle passed to them (14 atomic pairs per interaction), about as long as the kernel's own
work. A kernel of the tracer therefore never allocates.

Self-intersection: a scattered ray starts from the hit projected onto the analytic surface (for
meshed spheres and ellipsoids: onto the mesh's circumscribed surface, outside the own convex
mesh; native spheres are exact) and offset along the analytic normal by the :func:`clearance`
max(OFFSET_SIZE x shape size, OFFSET_SPACINGS float32 spacings of the coordinates). Embree may
still report the own sphere at a tiny distance for a grazing ray, from behind (its exit); a ray
that meets a surface from behind is inside a solid by round-off (also at the seams of
overlapping shapes): it passes through and the event is counted. At the clearance a ray leaving
a native sphere does not meet that sphere again, where a fixed offset of 1e-6 does not suffice.

(measurements: docs/developer/performance.md, section 'Surface transport: reference counting and
self-intersection')
"""

from __future__ import annotations

import math

import numba
import numpy as np

from microsim.core.tally import INSIDE_HITS
from microsim.physics.rng import uniform
from microsim.tracer.integrators.events import MAX_IDLE_SEGMENTS, begin_path
from microsim.tracer.integrators.walk import EXIT, IDLE, INTERACTION, TRANSMISSION, take_event
from microsim.tracer.materials import evaluate, scatter
from microsim.tracer.shapes import surface_point

#: segment ends: the tile side (wrap), the top (leave), the bottom (transmitted)
SIDE_X, SIDE_Y, TOP, BOTTOM = 0, 1, 2, 3
FLOAT32_EPS = 2.0**-23
#: a ray leaves a surface at least OFFSET_SIZE x the shape's size and OFFSET_SPACINGS float32
#: spacings of its coordinates away from it
OFFSET_SIZE = 1e-6
OFFSET_SPACINGS = 8.0
#: a ray passing a back face at a grazing angle is nudged as if at this cosine at least
MIN_PASS_COSINE = 1e-3


@numba.njit(cache=True, error_model="numpy", inline="always")
def start_path(paths, rays, i, number, beam, scene):
    """Path ``number`` of the beam starts in row i: a uniform point of the tile at z_top, along -wi."""
    begin_path(paths, i, number, beam.key)
    x = uniform(paths.rng, i) * scene.period[0]
    y = uniform(paths.rng, i) * scene.period[1]
    prepare_segment(rays, i, (x, y, scene.z_top), (-beam.wi[0], -beam.wi[1], -beam.wi[2]), scene)


@numba.njit(cache=True, error_model="numpy", inline="always")
def follow(work, i, hit, world, setups, max_order, tally):
    """Path i traced the segment in row i of ``work.rays`` and met ``hit`` = (primitive or -1, its
    distance t, Embree's float32 geometric normal); take it through the event there
    (:func:`microsim.tracer.integrators.walk.take_event`). ``world``: a backend's world, whose ``scene``
    holds the scene's arrays.

    Returns (alive, origin, direction) of its next segment: a surface hit scatters (or passes a
    back face, or is truncated by ``max_order``); a miss leaves through the top (exit),
    the bottom (transmitted) or a tile side (wrapped).
    """
    rays, scene = work.rays, world.scene
    o = (np.float64(rays.origin[i, 0]), np.float64(rays.origin[i, 1]), np.float64(rays.origin[i, 2]))
    d = (np.float64(rays.direction[i, 0]), np.float64(rays.direction[i, 1]), np.float64(rays.direction[i, 2]))
    p, t, ng = hit
    kind, state = IDLE, (o, (0.0, 0.0, 0.0), -1)
    if p >= 0:
        h = (o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2])
        s = scene.prim_shape[p]
        facing = d[0] * ng[0] + d[1] * ng[1] + d[2] * ng[2]
        if facing >= 0.0:
            tally.counts[INSIDE_HITS] += 1
            state = (pass_through(h, d, facing, ng, scene.shape_size[s], scene.period), state[1], -1)
        else:
            q, n = surface_point(scene.shape_code[s], scene.shape_params[s], h, d)
            kind, state = INTERACTION, (q, n, s)
    else:
        end = rays.end[i]
        if end == TOP:
            kind = EXIT
        elif end == BOTTOM:
            kind = TRANSMISSION
        else:
            state = (wrap_side(o, d, t, end, scene.period), state[1], -1)
    alive, d, state = take_event(world, work, i, (kind, d, state), max_order, setups, tally, interact_on_shape)
    return alive, state[0], d


@numba.njit(cache=True, error_model="numpy", inline="always")
def interact_on_shape(world, paths, i, path):
    """The material of the shape met scatters the path about the shape's normal at the point (the
    path's state: the point, the normal, the shape); the next segment starts off the surface,
    the :func:`clearance` along its normal."""
    d, (p, n, s) = path
    scene = world.scene
    m = scene.shape_material[s]
    wo, factor, cut = scatter(scene.material_code[m], scene.material_params[m], paths.rng, i, d, n)
    if paths.order[i] == 0:
        paths.from_base[i] = m == scene.base_material
    paths.idle[i] = 0
    return wo, factor, cut, (wrap_point(p, n, clearance(p, scene.shape_size[s]), scene.period), n, s)


def evaluate_on_shape(world, state, wi, wo):
    """The material of the shape met, at the shape's normal there (``state`` = (point, normal,
    shape)): what both backends register as their worlds' :data:`~.walk.EVALUATE`."""
    p, n, s = state
    scene = world.scene
    m = scene.shape_material[s]
    return evaluate(scene.material_code[m], scene.material_params[m], wi, wo, n)


@numba.njit(cache=True, error_model="numpy", inline="always")
def visible_through_tile(world, work, i, state, wo, blocked):
    """1 if the ray from the surface point of ``state`` = (point, normal, shape), lifted off the
    surface as a scattered ray is (the clearance along the normal), reaches z_top along wo without
    meeting anything, wrapping at the tile's sides as often as it takes (``blocked(world, work,
    i)``, a backend's query, on each piece, stored in row i); 0 if it is blocked, or wo goes
    below the surface's tangent plane or down."""
    scene = world.scene
    p, n, s = state
    if wo[0] * n[0] + wo[1] * n[1] + wo[2] * n[2] <= 0.0 or wo[2] <= 0.0:
        return 0.0
    rays = work.rays
    o = wrap_point(p, n, clearance(p, scene.shape_size[s]), scene.period)
    for _ in range(MAX_IDLE_SEGMENTS):
        prepare_segment(rays, i, o, wo, scene)
        end, t = rays.end[i], np.float64(rays.tfar[i])
        if blocked(world, work, i):
            return 0.0
        if end == TOP:
            return 1.0
        o = (np.float64(rays.origin[i, 0]), np.float64(rays.origin[i, 1]), np.float64(rays.origin[i, 2]))
        o = wrap_side(o, wo, t, end, scene.period)
    return 0.0


@numba.njit(cache=True, error_model="numpy", inline="always")
def pass_through(h, d, facing, ng, size, period):
    """Origin past a back face hit at h: far enough along d to clear the face in float32 (folded
    into the tile of sides ``period``)."""
    cosine = facing / math.sqrt(ng[0] ** 2 + ng[1] ** 2 + ng[2] ** 2)
    nudge = clearance(h, size) / max(cosine, MIN_PASS_COSINE)
    return wrap_point(h, d, nudge, period)


@numba.njit(cache=True, error_model="numpy", inline="always")
def clearance(p, size):
    """Distance a ray keeps from the surface it leaves at p (see module doc)."""
    return max(OFFSET_SIZE * size, OFFSET_SPACINGS * FLOAT32_EPS * max(abs(p[0]), abs(p[1]), abs(p[2])))


@numba.njit(cache=True, error_model="numpy", inline="always")
def wrap_point(p, v, distance, period):
    """p + distance v, folded into the tile of sides ``period`` = (L_x, L_y) in x and y."""
    return wrap(p[0] + distance * v[0], period[0]), wrap(p[1] + distance * v[1], period[1]), p[2] + distance * v[2]


@numba.njit(cache=True, error_model="numpy", inline="always")
def wrap_side(o, d, t, end, period):
    """The ray from o along d reaches the side ``end`` of the tile of sides ``period`` = (L_x, L_y)
    at t: continue from the opposite side."""
    x, y, z = o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]
    if end == SIDE_X:
        return (0.0 if d[0] > 0.0 else period[0]), wrap(y, period[1]), z
    return wrap(x, period[0]), (0.0 if d[1] > 0.0 else period[1]), z


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
    side_x = scene.period[0] - ox if dx > 0.0 else ox
    if side_x < abs(dx) * t:
        t, end = side_x / abs(dx), SIDE_X
    side_y = scene.period[1] - oy if dy > 0.0 else oy
    if side_y < abs(dy) * t:
        t, end = side_y / abs(dy), SIDE_Y
    rays.end[i] = end
    rays.tfar[i] = max(t, 0.0)
