"""The medium tracer: paths through the radiative-transfer half space z < 0 (no triangles).

A path enters at the surface along -wi and runs free flights of exponential length (unit mean
free path, -ln(1 - xi)); a flight that would cross z = 0 leaves there (the run's estimators
see it); otherwise the path scatters: its weight is multiplied by the albedo c, and its new direction makes the cosine mu with the
old one, mu drawn exactly from the phase function (:func:`scatter_direction`), the azimuth
about the old direction uniform. The walk, roulette, truncation, orders and tallies are those
of every integrator (:mod:`.walk`). Paths run to completion one at a time, in chunks on threads as
on the direct surface backend (:func:`microsim.tracer.integrators.scheduler.trace_in_waves`), so a table is
bit-identical for any number of threads.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from microsim.core.tally import SEGMENTS, SINGLE_ALBEDO
from microsim.physics.phase import phase_value, sample_cosine
from microsim.physics.rng import uniform
from microsim.physics.sampling import from_local
from microsim.tracer.estimators import DEFAULT, build, setups
from microsim.tracer.integrators.events import begin_path
from microsim.tracer.integrators.records import Beam
from microsim.tracer.integrators.scheduler import trace_in_waves, wave_bytes, wave_rows, workspace
from microsim.tracer.integrators.walk import EVALUATE, EXIT, INTERACTION, VISIBILITY, trace_chunks


class Medium(NamedTuple):
    """What the medium kernels trace (their world, :mod:`.walk`): the phase function (its code in
    physics.phase.PHASES) and the albedo."""

    phase: int
    albedo: float


class MediumTracer:
    """Traces batches of paths through a half-space medium (:class:`microsim.geometry.halfspace_medium.HalfspaceMedium`)
    on ``threads`` threads; ``backend`` is accepted and unused (no Embree)."""

    #: seconds numba takes to compile the kernels of each backend, cold (AMD EPYC Zen 4, 2026-12-02;
    #: the progress line quotes it while it compiles)
    COMPILE_SECONDS = {"direct": 3, "embreex": 3}

    @staticmethod
    def working_bytes(backend: str, threads: int, paths: int, tally_bytes: int, shadow_rays: int) -> int:
        """Bytes it works in while it traces a unit of ``paths`` paths (for the memory estimate)."""
        return wave_bytes(threads, tally_bytes)

    def __init__(self, scene, sensor, backend: str = "direct", threads: int = 1, estimators=None):
        self.scene, self.sensor, self.threads = scene, sensor, threads
        self.estimators = build(DEFAULT, sensor) if estimators is None else estimators

    def trace(self, wi, n_paths: int, key, max_order: int, albedo_scale=SINGLE_ALBEDO, phi_i=None):
        """Trace ``n_paths`` paths arriving along -``wi`` on the random stream ``key``; see
        :meth:`microsim.tracer.integrators.surface.SurfaceTracer.trace`."""
        beam = Beam(np.asarray(wi, np.float64), np.uint64(key), n_paths, max_order, np.asarray(albedo_scale, np.float64))
        medium, kernel_setups = self.scene.medium, setups(self.estimators, beam.wi, phi_i)
        work = workspace(wave_rows(n_paths, self.threads), self.estimators, albedos=len(beam.albedo_scale))
        return trace_in_waves(beam, self.estimators, self.threads, work,
                              lambda *share: trace_medium_chunks(*share, beam, medium, kernel_setups, work))

    @classmethod
    def compile(cls, sensor, estimators=None, albedos: int = 1, scene=None, backend: str = "direct",
                threads: int = 1) -> None:
        """Compile (or load) the kernel before workers fork, for runs of ``albedos`` albedos,
        tracing nothing."""
        estimators = build(DEFAULT, sensor) if estimators is None else estimators
        work = workspace(1, estimators, albedos=albedos)
        beam = Beam(np.array([0.0, 0.0, 1.0]), np.uint64(0), 0, 0, np.ones(albedos))
        trace_medium_chunks(0, 0, 0, beam, Medium(0, 0.5), setups(estimators, beam.wi, 0.0), work)


@numba.njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def trace_medium_chunks(first, start, stop, beam, world, setups, work):
    """Chunks first+start .. first+stop-1 of the beam, chunk first+j into tally row j, by the walk
    (:func:`microsim.tracer.integrators.walk.trace_chunks`)."""
    trace_chunks((first, start, stop), beam, world, setups, work, enter_medium, free_flight, scatter_in_medium)


@numba.njit(cache=True, error_model="numpy", inline="always")
def enter_medium(world, work, i, number, beam):
    """Path ``number`` enters at the surface along -wi; its state is its depth z."""
    begin_path(work.paths, i, number, beam.key)
    return (-beam.wi[0], -beam.wi[1], -beam.wi[2]), 0.0


@numba.njit(cache=True, error_model="numpy", inline="always")
def free_flight(world, work, i, path, tally):
    """A free flight of exponential length: through z = 0 going up (EXIT), or to the next
    scattering (INTERACTION)."""
    d, z = path
    flight = -math.log1p(-uniform(work.paths.rng, i))
    tally.counts[SEGMENTS] += 1
    if d[2] > 0.0 and z + flight * d[2] >= 0.0:
        return EXIT, d, z
    return INTERACTION, d, z + flight * d[2]


@numba.njit(cache=True, error_model="numpy", inline="always")
def scatter_in_medium(world, paths, i, path):
    """The phase function turns the path where it is; the albedo is the weight kept."""
    d, z = path
    return scatter_direction(world.phase, paths.rng, i, d), world.albedo, 0.0, z


@VISIBILITY.register(Medium)
def transmittance(world, work, i, state, wo):
    """exp(-tau) from depth ``state`` = z (<= 0, in mean free paths) to the surface along wo: the
    optical path -z / wo_z; 0 for wo going down or level."""
    return math.exp(state / wo[2]) if wo[2] > 0.0 else 0.0


@EVALUATE.register(Medium)
def scattered(world, state, wi, wo):
    """c p(-wi . wo): the point scatterer turns the light by the angle between d = -wi and wo."""
    return world.albedo * phase_value(world.phase, -(wi[0] * wo[0] + wi[1] * wo[1] + wi[2] * wo[2]))


@numba.njit(cache=True, error_model="numpy", inline="always")
def scatter_direction(phase, states, i, d):
    """A new unit direction at the cosine mu from d drawn from the phase function of code
    ``phase`` (:func:`microsim.physics.phase.sample_cosine`), azimuth uniform."""
    mu = sample_cosine(phase, states, i)
    sine = math.sqrt(max(0.0, 1.0 - mu * mu))
    azimuth = 2.0 * math.pi * uniform(states, i)
    return from_local(sine * math.cos(azimuth), sine * math.sin(azimuth), mu, d)
