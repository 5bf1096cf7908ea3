"""Generators of random microgeometry, one module per scene kind (docs/conventions.md §5).

A generator module provides ``KIND``; ``INTEGRATOR``, the name of the integrator that traces
its scenes (a key of ``microsim.tracer.integrators.INTEGRATORS``; "surface" for Embree triangles);
``Config``, the pydantic model of its ``[scene]`` table; ``check(config)``, cross-section rules
(raises ValueError with a one-line message); ``for_backend(config, backend) -> (config, note)``,
the config as that Embree backend can trace it (the note says what was substituted, "" if
nothing; ValueError, one line, if that backend cannot trace the scene); ``resolve(config) -> dict``, every scene parameter
with its defaults filled in (stored in the table's ``scene/`` attrs); ``scene_bytes(resolved)``,
about how much memory one realization takes once built for Embree (the runner refuses a run
that cannot fit); and
``generate(resolved, config, rng)``, one random realization in the form its integrator takes
(for "surface", a ``microsim.tracer.scene.Scene`` assembled with ``SceneBuilder``).
And ``EXAMPLE``: a small whole run config of the kind (a dictionary as a TOML config parses:
``scene``, ``material``, ``illumination``, ``sensor`` and ``run``, a few thousand paths, a fixed
seed; a file it names is relative to the repository's root), from which the conformance test
of every kind (tests/test_scene_kinds.py: the white furnace, reciprocity, thread identity, a bad
key refused in one line) and the CLI fuzzer (microsim.testing.fuzzing) start, so that a new
kind is tested and fuzzed with no change to either.
Optionally ``SIZE``, the advice the memory refusal gives on a scene's size
(default: lower the scene's tile or depth).
"""

from microsim.geometry import (
    halfspace_medium,
    heightfield,
    mesh,
    micrograins,
    packed_spheres,
    plane,
    poisson_spheres,
    vcavities,
)

SCENES = {module.KIND: module for module in (plane, poisson_spheres, packed_spheres, micrograins, vcavities,
                                            halfspace_medium, mesh, heightfield)}
