"""Integrators: what traces a scene. Each generator names its own (``geometry`` module attribute
``INTEGRATOR``), and the runner looks it up here, so that it assumes neither triangles nor Embree.

An integrator is a class built from one realization of a scene, the sensor and the run's
options, ``Tracer(scene, sensor, backend=..., threads=..., estimators=...)``, with
``trace(wi, n_paths, key, max_order, albedo_scale, phi_i=None) -> microsim.core.tally.Tally`` (the
paths of one unit of work, on the random stream ``key``, tallied by the run's estimators for
every albedo of ``albedo_scale``, each estimator set up for the incidence of azimuth ``phi_i``
(:func:`microsim.tracer.estimators.setups`);
the tally must not depend on ``threads``) and a classmethod
``compile(sensor, estimators, albedos, scene, backend, threads)`` that compiles the kernels of
that run, and no other, before worker processes fork, and a static method
``working_bytes(backend, threads, paths, tally_bytes, shadow_rays)``, the bytes it works in while it
traces a unit (the run's memory estimate adds it to the scene's). Every integrator is a transport driven by
one walk (:mod:`.walk`: the handling of each event, the path loop), with the queries of
next-event estimation registered on its world (:data:`.walk.EVALUATE`, :data:`.walk.VISIBILITY`,
and :data:`.walk.SEE` where visibility is answered later); the per-path records and the
bookkeeping of an interaction (roulette, truncation) are in :mod:`.records` and :mod:`.events`,
the scheduling of chunks on threads in :mod:`.scheduler`.
"""

import importlib

#: integrator name (a generator's INTEGRATOR) -> "module:class" of its tracer, imported on use
#: (reading a table or its records must not import a tracer)
INTEGRATORS = {"surface": "microsim.tracer.integrators.surface:SurfaceTracer",
               "vcavity": "microsim.tracer.integrators.vcavity:VCavityTracer",
               "medium": "microsim.tracer.integrators.medium:MediumTracer"}


def get(name: str):
    """The tracer class of integrator ``name``."""
    module, cls = INTEGRATORS[name].split(":")
    return getattr(importlib.import_module(module), cls)
