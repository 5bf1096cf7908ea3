"""The surface tracer: the integrator of every scene kind made of triangles and spheres.

Its paths and events are :mod:`.surface_transport`'s kernels; its two backends, named as
``run.backend`` names them, call Embree and schedule paths in two ways: :mod:`.direct` (numba
calls Embree, paths run to completion, threads) and :mod:`.embreex` (one embreex call per
segment of all live paths). A scene that carries a grid (``Scene.grid``, with ``intersector =
"grid"``) is walked instead, whichever backend is named: a heightfield's height grid by :mod:`.grid`,
exact spheres' (and grains') cells by :mod:`.sphere_grid`.
"""

from __future__ import annotations

import numpy as np

from microsim.core.tally import SINGLE_ALBEDO
from microsim.tracer.estimators import DEFAULT, build, setups
from microsim.tracer.integrators import direct, embreex, grid, sphere_grid
from microsim.tracer.integrators.records import Beam
from microsim.tracer.integrators.scheduler import wave_bytes
from microsim.tracer.materials import Absorber
from microsim.tracer.scene import Scene, SceneBuilder

#: ``run.backend`` -> the module of that backend (as microsim.core.choices.BACKENDS names them): ``backend(scene, threads, estimators)`` and
#: ``compile_kernels(beam, scene, setups, estimators)``
BACKENDS = {"direct": direct, "embreex": embreex}


class SurfaceTracer:
    """Traces batches of paths through one realization of a surface scene (the integrator of
    every scene kind made of triangles and spheres), on one of two Embree backends:

    - ``"direct"`` (:mod:`.direct`): numba calls Embree itself; a chunk of paths is traced to
      completion in one call, chunks in parallel on ``threads`` threads sharing the scene;
      native spheres;
    - ``"embreex"`` (:mod:`.embreex`): one ``embreex.run`` call per segment of every live
      path, then :func:`.embreex.advance`; triangles only; one thread. The fallback where the direct
      binding cannot load, and the reference the direct backend is checked against.
    """

    #: seconds numba takes to compile the kernels of each backend, cold (AMD EPYC Zen 4, 2026-12-02;
    #: the progress line quotes it while it compiles)
    COMPILE_SECONDS = {"direct": 20, "embreex": 7}

    @staticmethod
    def working_bytes(backend: str, threads: int, paths: int, tally_bytes: int, shadow_rays: int) -> int:
        """Bytes it works in while it traces a unit of ``paths`` paths (for the memory estimate):
        the embreex backend's batch of path rows and shadow queue, or a wave's chunk tallies."""
        if backend == "embreex":
            return embreex.batch_bytes(paths, shadow_rays)
        return wave_bytes(threads, tally_bytes)

    def __init__(self, scene: Scene, sensor, backend: str = "direct", threads: int = 1, estimators=None):
        self.scene, self.sensor = scene, sensor
        self.arrays = scene.arrays()
        self.estimators = build(DEFAULT, sensor) if estimators is None else estimators
        module = backend_module(backend) if scene.grid is None else walker_of(scene.grid)
        self.backend = module.backend(scene, threads, self.estimators)

    def trace(self, wi, n_paths: int, key, max_order: int, albedo_scale=SINGLE_ALBEDO, phi_i=None):
        """Trace ``n_paths`` paths arriving along -``wi``; return their :class:`~microsim.core.tally.Tally`.

        ``key`` selects the random stream (see :mod:`microsim.physics.rng`); ``max_order`` = 0 means
        unlimited, k > 0 truncates a path at its (k+1)-th interaction; ``albedo_scale`` holds
        c_j / c_max for a run of several albedos (:class:`~microsim.core.tally.Tally`); ``phi_i``, the
        incidence's azimuth, sets the plane of incidence where wi is the normal (for the
        estimators' setups, :func:`microsim.tracer.estimators.setups`).
        """
        beam = Beam(np.asarray(wi, np.float64), np.uint64(key), n_paths, max_order,
                    np.asarray(albedo_scale, np.float64))
        return self.backend.trace(beam, self.arrays, setups(self.estimators, beam.wi, phi_i))

    @classmethod
    def compile(cls, sensor, estimators=None, albedos: int = 1, scene=None, backend: str = "direct",
                threads: int = 1) -> None:
        """Compile (or load from numba's cache) the kernels of ``backend`` in this process, for
        runs of ``albedos`` albedos (one, or several: tallies of another shape, another kernel)
        and these ``estimators`` (None: the default ones; ``scene``, the run's resolved
        parameters, changes nothing).

        Called before worker processes are forked, so that they inherit the machine code instead
        of each loading it again. Every scene has the same array types, so a small one will do;
        nothing is committed to Embree (its threads would not survive the fork).
        """
        builder = SceneBuilder(1.0)
        builder.add_base_plane(-0.5, Absorber(kind="absorber"))
        beam = Beam(np.array([0.0, 0.0, 1.0]), np.uint64(0), 1, 0, np.ones(albedos))
        estimators = build(DEFAULT, sensor) if estimators is None else estimators
        module = backend_module(backend)
        if scene is not None and scene.get("intersector") == "grid":
            module = grid if scene.get("kind") == "heightfield" else sphere_grid  # spheres' or grains' cells
        module.compile_kernels(beam, builder.build(1.0, -1.0, {}), setups(estimators, beam.wi, 0.0), estimators)


def walker_of(cells):
    """The module that walks a scene's grid: :mod:`.sphere_grid` for sphere cells, :mod:`.grid` for
    a height grid."""
    return sphere_grid if isinstance(cells, sphere_grid.SphereCells) else grid


def backend_module(name: str):
    """The module of backend ``name``."""
    if name not in BACKENDS:
        raise ValueError(f"unknown backend {name!r}; known: {', '.join(BACKENDS)}")
    return BACKENDS[name]
