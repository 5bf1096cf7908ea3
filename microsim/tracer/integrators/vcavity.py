"""The V-cavity tracer: each path in a groove of its own, traced in the groove's cross-section.

A path draws its groove's facet slope from D(m)(m.n) (:func:`~microsim.physics.distributions.sample_slope`;
why this is the V-cavity surface exactly: :mod:`microsim.geometry.vcavities`), and enters the groove's
aperture at a uniform point. In the cross-section, with u the horizontal unit vector of m and
h = tan(theta_m), the groove is x in [-1, 1] above the two facet lines z = -h (x + 1) (the left
facet, normal m = (sin theta_m u, cos theta_m)) and z = -h (1 - x) (the right one, normal m');
a direction d moves the path by (d.u, d_z) per unit of the ray parameter t, whatever its
component along the axis. The region is convex, so a ray leaves it where it first crosses one
of its three sides going outwards: a facet (an interaction, shaded with the exact facet normal;
the hit is put on the facet line) or the aperture z = 0 (the path leaves, and the run's
estimators see it). The walk, its bookkeeping and the materials are those of every integrator
(:mod:`.walk`, :func:`microsim.tracer.materials.scatter`).

Two ways to find that crossing (``intersector``), one path body:

- :func:`meet_analytic`: the three crossings in float64; a ray leaving a facet moves inwards
  across it, so it cannot meet it again, and nothing is offset.
- :func:`meet_embree`: Embree's closest hit on the canonical groove (half-width 1, depth 1,
  :data:`CANONICAL_FACES`), the ray mapped by (x, z) -> (x, z / h) and its
  axial motion dropped, so t is the world t; its origin is lifted 8 float32 spacings off the facet
  it leaves (Embree works in float32). Embree says which facet is met (or none); the distance to
  it is then that of the float64 ray from the unlifted origin, so the lift does not move hit
  points. Rays can be logged, as on the direct backend, for the benchmark's replay through Embree
  alone.

Paths run to completion one at a time, in chunks on threads exactly as on the direct surface
backend (:func:`microsim.tracer.integrators.scheduler.trace_in_waves`): a table is bit-identical for any
number of threads.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from microsim.core.tally import SEGMENTS, SINGLE_ALBEDO
from microsim.physics.distributions import sample_slope
from microsim.physics.rng import uniform
from microsim.tracer import embree
from microsim.tracer.estimators import DEFAULT, build, setups
from microsim.tracer.integrators.events import begin_path
from microsim.tracer.integrators.records import Beam
from microsim.tracer.integrators.scheduler import trace_in_waves, wave_bytes, wave_rows, workspace
from microsim.tracer.integrators.walk import EVALUATE, EXIT, INTERACTION, STOP, VISIBILITY, trace_chunks
from microsim.tracer.materials import evaluate, scatter

#: the canonical groove the Embree intersector traces: half-width 1 in x, depth 1, y in [-1, 1]
#: (a ray's axial motion is dropped, so it never leaves y = 0); left facet (normal +x side) first
CANONICAL_VERTICES = np.array([[-1, -1, 0], [0, -1, -1], [0, 1, -1], [-1, 1, 0], [1, -1, 0], [1, 1, 0]], np.float32)
CANONICAL_FACES = np.array([[0, 1, 2], [0, 2, 3], [1, 4, 5], [1, 5, 2]], np.int32)
#: triangles of CANONICAL_FACES that make the left facet (the facet m); the others make m'
LEFT_FACET_TRIANGLES = 2


class Grooves(NamedTuple):
    """What the V-cavity kernels read: the distribution (code of ``distributions.DISTRIBUTIONS``),
    its two roughnesses, and the facets' material (kind code, parameter row)."""

    distribution: int
    roughness_x: float
    roughness_y: float
    material_code: int
    material_params: np.ndarray


class GrooveWorld(NamedTuple):
    """The world of the analytic intersector (:mod:`.walk`): the grooves' law."""

    grooves: Grooves


class EmbreeGrooveWorld(NamedTuple):
    """The world of the Embree intersector: the grooves' law, and the canonical groove's Embree scene."""

    grooves: Grooves
    handle: object


#: facets of a groove, as :func:`meet_analytic` and :func:`meet_embree` name them; NONE: no facet
LEFT, RIGHT, NONE = 0, 1, -1
#: a groove is never shallower than this (a facet drawn exactly flat: probability 2^-53)
MIN_DEPTH = 1e-12
#: the Embree query leaves a facet this far off it, in the canonical frame (8 float32 spacings of 1)
EMBREE_OFFSET = 8.0 * 2.0**-23
_SQRT_HALF = math.sqrt(0.5)


class VCavityTracer:
    """Traces batches of paths through V-cavities (:class:`microsim.geometry.vcavities.VCavities`) on
    ``threads`` threads; ``backend`` is the run's Embree binding, used by the ``embree``
    intersector only. ``log_rays`` > 0 (one thread, ``embree`` intersector) keeps the first
    ``log_rays`` Embree queries in ``ray_log`` (rows of origin, direction, tfar)."""

    #: seconds numba takes to compile the kernels of each backend, cold (AMD EPYC Zen 4, 2026-12-02;
    #: the progress line quotes it while it compiles)
    COMPILE_SECONDS = {"direct": 5, "embreex": 5}

    @staticmethod
    def working_bytes(backend: str, threads: int, paths: int, tally_bytes: int, shadow_rays: int) -> int:
        """Bytes it works in while it traces a unit of ``paths`` paths (for the memory estimate)."""
        return wave_bytes(threads, tally_bytes)

    def __init__(self, scene, sensor, backend: str = "direct", threads: int = 1, estimators=None, log_rays: int = 0):
        if log_rays and (threads != 1 or scene.intersector != "embree"):
            raise ValueError("the ray log keeps the Embree queries of one thread: give threads = 1 and the embree intersector")
        self.scene, self.sensor, self.threads, self.log_rays = scene, sensor, threads, log_rays
        self.estimators = build(DEFAULT, sensor) if estimators is None else estimators
        self.embree = embree.Scene(CANONICAL_VERTICES, CANONICAL_FACES) if scene.intersector == "embree" else None
        self.ray_log = np.zeros((0, 7), np.float32)

    def trace(self, wi, n_paths: int, key, max_order: int, albedo_scale=SINGLE_ALBEDO, phi_i=None):
        """Trace ``n_paths`` paths arriving along -``wi`` on the random stream ``key``; see
        :meth:`microsim.tracer.integrators.surface.SurfaceTracer.trace`."""
        beam = Beam(np.asarray(wi, np.float64), np.uint64(key), n_paths, max_order, np.asarray(albedo_scale, np.float64))
        grooves, kernel_setups = self.scene.grooves, setups(self.estimators, beam.wi, phi_i)
        work = workspace(wave_rows(n_paths, self.threads), self.estimators, self.log_rays, len(beam.albedo_scale))
        world = GrooveWorld(grooves) if self.embree is None else EmbreeGrooveWorld(grooves, self.embree.arrays())
        trace_share = trace_chunks_analytic if self.embree is None else trace_chunks_embree
        total = trace_in_waves(beam, self.estimators, self.threads, work,
                               lambda *share: trace_share(*share, beam, world, kernel_setups, work))
        self.ray_log = work.log[:min(work.logged[0], len(work.log))]
        return total

    @classmethod
    def compile(cls, sensor, estimators=None, albedos: int = 1, scene=None, backend: str = "direct",
                threads: int = 1) -> None:
        """Compile (or load) the kernel of the intersector of ``scene`` (its resolved parameters;
        None: both) before workers fork, for runs of ``albedos`` albedos, tracing nothing (the
        Embree one only where the library loads: its machine code links to rtcIntersect1 by
        name)."""
        beam = Beam(np.array([0.0, 0.0, 1.0]), np.uint64(0), 0, 0, np.ones(albedos))
        grooves = Grooves(0, 0.5, 0.5, 0, np.zeros(2))
        estimators = build(DEFAULT, sensor) if estimators is None else estimators
        work = workspace(1, estimators, albedos=albedos)
        intersector = None if scene is None else scene.get("intersector")
        if intersector in (None, "analytic"):
            trace_chunks_analytic(0, 0, 0, beam, GrooveWorld(grooves), setups(estimators, beam.wi, 0.0), work)
        if intersector in (None, "embree"):
            try:
                embree.available()
            except embree.EmbreeUnavailable:
                return
            handle = embree.SceneHandle(0, np.zeros(1, np.int64), np.ones(2))
            trace_chunks_embree(0, 0, 0, beam, EmbreeGrooveWorld(grooves, handle), setups(estimators, beam.wi, 0.0), work)


@numba.njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def trace_chunks_analytic(first, start, stop, beam, world, setups, work):
    """Chunks first+start .. first+stop-1 of the beam, chunk first+j into tally row j, by the walk
    (:func:`microsim.tracer.integrators.walk.trace_chunks`) with :func:`meet_analytic`."""
    trace_chunks((first, start, stop), beam, world, setups, work, start_in_groove, next_event_analytic,
                 interact_on_facet)


@numba.njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def trace_chunks_embree(first, start, stop, beam, world, setups, work):
    """:func:`trace_chunks_analytic` with :func:`meet_embree`."""
    trace_chunks((first, start, stop), beam, world, setups, work, start_in_groove, next_event_embree,
                 interact_on_facet)


@numba.njit(cache=True, error_model="numpy", inline="always")
def start_in_groove(world, work, i, number, beam):
    """Path ``number`` draws its groove's facet slope and enters the aperture at a uniform point
    (module doc). The state: the point (x, z) of the cross-section, the facet it is on (NONE),
    the facet's normal, and the groove's frame (cos and sin of the slope's azimuth, depth h,
    cos and sin of the facet angle)."""
    paths, grooves = work.paths, world.grooves
    begin_path(paths, i, number, beam.key)
    sx, sy = sample_slope(grooves.distribution, grooves.roughness_x, grooves.roughness_y, paths.rng, i)
    slope = math.sqrt(sx * sx + sy * sy)
    cu, su = (sx / slope, sy / slope) if slope > 0.0 else (1.0, 0.0)
    h = max(slope, MIN_DEPTH)
    cos_m = 1.0 / math.sqrt(1.0 + h * h)
    sin_m = h * cos_m
    x = 2.0 * uniform(paths.rng, i) - 1.0
    return (-beam.wi[0], -beam.wi[1], -beam.wi[2]), ((x, 0.0), NONE, (0.0, 0.0, 1.0), (cu, su, h, cos_m, sin_m))


@numba.njit(cache=True, error_model="numpy", inline="always")
def next_event_analytic(world, work, i, path, tally):
    """The next facet or the aperture, by :func:`meet_analytic`."""
    return groove_event(world, work, i, path, tally, meet_analytic)


@numba.njit(cache=True, error_model="numpy", inline="always")
def next_event_embree(world, work, i, path, tally):
    """The next facet or the aperture, by :func:`meet_embree`."""
    return groove_event(world, work, i, path, tally, meet_embree)


@numba.njit(cache=True, error_model="numpy", inline="always")
def groove_event(world, work, i, path, tally, meet):
    """Where the path leaves the groove's cross-section (module doc): a facet (INTERACTION, the
    point put on the facet line, the facet's normal), the aperture going up (EXIT), or nowhere
    (STOP: along the axis, level)."""
    d, state = path
    (x, z), last, _, frame = state
    cu, su, h, cos_m, sin_m = frame
    du = d[0] * cu + d[1] * su
    dz = d[2]
    facet, t = meet(world, work, i, (x, z), (du, dz), h, last)
    tally.counts[SEGMENTS] += 1
    if facet == NONE:
        return (EXIT if dz > 0.0 else STOP), d, state
    x = x + t * du
    if facet == LEFT:
        x = min(max(x, -1.0), 0.0)
        z = -h * (x + 1.0)
        n = (sin_m * cu, sin_m * su, cos_m)
    else:
        x = min(max(x, 0.0), 1.0)
        z = -h * (1.0 - x)
        n = (-sin_m * cu, -sin_m * su, cos_m)
    return INTERACTION, d, ((x, z), facet, n, frame)


@numba.njit(cache=True, error_model="numpy", inline="always")
def interact_on_facet(world, paths, i, path):
    """The facets' material scatters the path about the facet's normal; the path leaves the facet
    it is on (the state's facet: not a candidate for its next meeting)."""
    d, state = path
    grooves = world.grooves
    wo, factor, cut = scatter(grooves.material_code, grooves.material_params, paths.rng, i, d, state[2])
    return wo, factor, cut, state


@EVALUATE.register(GrooveWorld)
@EVALUATE.register(EmbreeGrooveWorld)
def evaluate_on_facet(world, state, wi, wo):
    """The facets' material at the facet's normal (the state's third item)."""
    grooves = world.grooves
    return evaluate(grooves.material_code, grooves.material_params, wi, wo, state[2])


@VISIBILITY.register(GrooveWorld)
def visible_in_groove_analytic(world, work, i, state, wo):
    """:func:`groove_visibility` by :func:`meet_analytic`."""
    return groove_visibility(world, work, i, state, wo, meet_analytic)


@VISIBILITY.register(EmbreeGrooveWorld)
def visible_in_groove_embree(world, work, i, state, wo):
    """:func:`groove_visibility` by :func:`meet_embree`."""
    return groove_visibility(world, work, i, state, wo, meet_embree)


@numba.njit(cache=True, error_model="numpy", inline="always")
def groove_visibility(world, work, i, state, wo, meet):
    """1 if the ray from the facet point of ``state`` along wo leaves the groove through its
    aperture (meeting neither facet), 0 if it meets the other facet or goes below the facet."""
    (x, z), facet, n, (cu, su, h, _, _) = state
    if wo[0] * n[0] + wo[1] * n[1] + wo[2] * n[2] <= 0.0 or wo[2] <= 0.0:
        return 0.0
    met, _ = meet(world, work, i, (x, z), (wo[0] * cu + wo[1] * su, wo[2]), h, facet)
    return 1.0 if met == NONE else 0.0


@numba.njit(cache=True, error_model="numpy", inline="always")
def meet_analytic(world, work, row, position, motion, h, last):
    """(facet or NONE, t) where the ray from ``position`` (x, z) moving by ``motion`` (du, dz)
    leaves the groove's cross-section: the smallest t at which it crosses a side going outwards
    (module doc). The facet ``last`` that the ray leaves is not a candidate (the region is convex:
    a direction scattered off a facet that rounds to grazing cannot meet it again)."""
    (x, z), (du, dz) = position, motion
    t, facet = math.inf, NONE
    if dz > 0.0:
        t = -z / dz
    if last != LEFT:
        reach = facet_distance(z + h * (x + 1.0), dz + h * du)  # z + h (x + 1) >= 0 above the left facet
        if reach < t:
            t, facet = reach, LEFT
    if last != RIGHT:
        reach = facet_distance(z + h * (1.0 - x), dz - h * du)  # z + h (1 - x) >= 0 above the right facet
        if reach < t:
            t, facet = reach, RIGHT
    return facet, t


@numba.njit(cache=True, error_model="numpy", inline="always")
def facet_distance(height, rate):
    """t at which a ray at ``height`` above a facet line (in the line's own measure), changing it
    by ``rate`` per unit t, reaches the line; inf if it moves away or along it."""
    return max(height, 0.0) / -rate if rate < 0.0 else math.inf


@numba.njit(cache=True, error_model="numpy", inline="always")
def meet_embree(world, work, row, position, motion, h, last):
    """:func:`meet_analytic` by Embree on the canonical groove (module doc)."""
    (x, z), (du, dz) = position, motion
    cx, cz, cdz = x, z / h, dz / h
    if last == LEFT:
        cx, cz = cx + EMBREE_OFFSET * _SQRT_HALF, cz + EMBREE_OFFSET * _SQRT_HALF
    elif last == RIGHT:
        cx, cz = cx - EMBREE_OFFSET * _SQRT_HALF, cz + EMBREE_OFFSET * _SQRT_HALF
    tfar = -cz / cdz if cdz > 0.0 else math.inf
    queries = work.queries
    embree.set_ray(queries[row], (cx, 0.0, cz), (du, 0.0, cdz), tfar)
    if len(work.log):
        k = work.logged[0]
        work.logged[0] = k + 1
        if k < len(work.log):
            record = queries[row]
            work.log[k, 0], work.log[k, 1], work.log[k, 2] = record.org_x, record.org_y, record.org_z
            work.log[k, 3], work.log[k, 4], work.log[k, 5] = record.dir_x, record.dir_y, record.dir_z
            work.log[k, 6] = record.tfar
    embree.trace(world.handle.handle, queries, row)
    record = queries[row]
    if record.geomID == embree.INVALID_ID:
        return NONE, 0.0
    if record.primID < LEFT_FACET_TRIANGLES:
        return LEFT, facet_distance(z + h * (x + 1.0), dz + h * du)
    return RIGHT, facet_distance(z + h * (1.0 - x), dz - h * du)
