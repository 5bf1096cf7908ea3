"""The medium tracer: paths through the radiative-transfer half space z < 0 (no triangles).

A path enters at the surface along -wi and runs free flights of exponential length (unit mean
free path, -ln(1 - xi)); a flight that would cross z = 0 leaves there and is binned on the
sensor by order (:func:`~microsim.integrators.events.exit_top`); otherwise the path scatters:
its weight is multiplied by the albedo c, and its new direction makes the cosine mu with the
old one, mu drawn exactly from the phase function (:func:`scatter_direction`), the azimuth
about the old direction uniform. Roulette, truncation, orders and tallies are those of every
integrator (:mod:`.events`). Paths run to completion one at a time, in chunks on threads as
on the direct surface backend (:func:`microsim.integrators.scheduler.trace_in_waves`), so a table is
bit-identical for any number of threads.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from ..physics.phase import sample_cosine
from ..physics.rng import uniform
from ..physics.sampling import from_local
from .events import begin_path, cut_at_max_order, exit_top, interacted
from .records import SEGMENTS, SINGLE_ALBEDO, Beam
from .scheduler import CHUNK_PATHS, chunk_tally, compile_tally_sums, trace_in_waves, wave_rows, workspace

class Medium(NamedTuple):
    """What the medium kernels read: the phase function (its code in physics.phase.PHASES) and the albedo."""

    phase: int
    albedo: float



class MediumTracer:
    """Traces batches of paths through a half-space medium (:class:`geometry.halfspace_medium.HalfspaceMedium`)
    on ``threads`` threads; ``backend`` is accepted and unused (no Embree)."""

    #: seconds numba takes to compile the kernels of each backend, cold (AMD EPYC Zen 4, 2026-12-02;
    #: the progress line quotes it while it compiles)
    COMPILE_SECONDS = {"direct": 3, "embreex": 3}

    def __init__(self, scene, sensor, backend: str = "direct", threads: int = 1):
        self.scene, self.sensor, self.threads = scene, sensor, threads

    def trace(self, wi, n_paths: int, key, max_order: int, albedo_scale=SINGLE_ALBEDO):
        """Trace ``n_paths`` paths arriving along -``wi`` on the random stream ``key``; see
        :meth:`microsim.integrators.surface.SurfaceTracer.trace`."""
        beam = Beam(np.asarray(wi, np.float64), np.uint64(key), n_paths, max_order, np.asarray(albedo_scale, np.float64))
        medium, sensor = self.scene.medium, self.sensor.toward(beam.wi)
        work = workspace(wave_rows(n_paths, self.threads), sensor.tally_width, albedos=len(beam.albedo_scale))
        return trace_in_waves(beam, sensor.tally_width, self.threads, work,
                              lambda first, start, stop: trace_chunks(first, start, stop, beam, medium, sensor, work))

    @classmethod
    def compile(cls, sensor, backend: str = "direct", threads: int = 1, albedos: int = 1) -> None:
        """Compile (or load) the kernel before workers fork, for runs of ``albedos`` albedos,
        tracing nothing."""
        work = workspace(1, sensor.tally_width, albedos=albedos)
        beam = Beam(np.array([0.0, 0.0, 1.0]), np.uint64(0), 0, 0, np.ones(albedos))
        trace_chunks(0, 0, 0, beam, Medium(0, 0.5), sensor, work)
        compile_tally_sums(beam, work)


@numba.njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def trace_chunks(first, start, stop, beam, medium, sensor, work):
    """Chunks first+start .. first+stop-1 of the beam, chunk first+j into tally row j."""
    for j in range(start, stop):
        tally = chunk_tally(work, j, beam)
        chunk = first + j
        for number in range(chunk * CHUNK_PATHS, min((chunk + 1) * CHUNK_PATHS, beam.n_paths)):
            trace_path(work.paths, j, number, beam, medium, sensor, tally)


@numba.njit(cache=True, error_model="numpy", inline="always")
def trace_path(paths, row, number, beam, medium, sensor, tally):
    """Path ``number`` of the beam, in ``row``, from the surface until it leaves, is absorbed or
    is truncated (module doc)."""
    begin_path(paths, row, number, beam.key)
    z = 0.0
    d = (-beam.wi[0], -beam.wi[1], -beam.wi[2])
    while True:
        flight = -math.log1p(-uniform(paths.rng, row))
        tally.counts[SEGMENTS] += 1
        if d[2] > 0.0 and z + flight * d[2] >= 0.0:
            exit_top(paths, row, d, sensor, tally)
            return
        if cut_at_max_order(paths, row, beam.max_order, tally):
            return
        z += flight * d[2]
        d = scatter_direction(medium.phase, paths.rng, row, d)
        if not interacted(paths, row, medium.albedo, 0.0, tally):
            return


@numba.njit(cache=True, error_model="numpy", inline="always")
def scatter_direction(phase, states, i, d):
    """A new unit direction at the cosine mu from d drawn from the phase function of code
    ``phase`` (:func:`microsim.physics.phase.sample_cosine`), azimuth uniform."""
    mu = sample_cosine(phase, states, i)
    sine = math.sqrt(max(0.0, 1.0 - mu * mu))
    azimuth = 2.0 * math.pi * uniform(states, i)
    return from_local(sine * math.cos(azimuth), sine * math.sin(azimuth), mu, d)
