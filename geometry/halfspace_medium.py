"""The radiative-transfer half space (docs/conventions.md §5.5): the volumetric reference.

The half space z < 0 holds independent point scatterers with unit mean free path (lengths are
in mean free paths), single-scattering albedo c = ``[material] albedo`` (``kind = "lambert"``:
the scatterer's albedo) and the phase function ``phase``:

- ``lambert_sphere``: the phase function of a Lambertian sphere, d'Eon 2021, Eq. 1,
  what the analytic Lambert-sphere BRDF approximates (``microsim.physics.phase``);
- ``isotropic``: 1 / (4 pi), whose half space has Chandrasekhar's closed form (``rte_isotropic``).

The albedo is in the table's config (a run of several albedos traces the largest, conventions §4).
No triangles: the medium integrator (:mod:`microsim.tracer.integrators.medium`) samples exponential
free flights and exact phase-function directions. Nothing random belongs to a realization (the
medium is homogeneous): a realization is an independent batch of paths. Every resolved value
is in the table's ``scene/`` attrs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from pydantic import Field

from microsim.core.schema import Section
from microsim.physics.phase import PHASES
from microsim.tracer.integrators.medium import Medium

KIND = "halfspace_medium"
INTEGRATOR = "medium"
#: a small whole run config of this kind, fixed seed (the generator protocol, geometry/__init__.py): what
#: the conformance test of every kind (tests/test_scene_kinds.py) and the CLI fuzzer start from
EXAMPLE = {"scene": {"kind": "halfspace_medium", "phase": "isotropic"},
           "material": {"kind": "lambert", "albedo": 0.5},
           "illumination": {"theta_i_deg": [0.0, 60.0]}, "sensor": {"cells": 24},
           "run": {"paths": 4000, "realizations": 4, "seed": 1}}
class Config(Section):
    kind: Literal["halfspace_medium"]
    phase: Literal[tuple(PHASES)] = Field("lambert_sphere", description="phase function of the point scatterers")


@dataclass
class HalfspaceMedium:
    """One realization: the medium's law (nothing random is drawn before tracing)."""

    medium: Medium
    info: dict = field(default_factory=dict)


def check(config) -> None:
    if config.base is not None:
        raise ValueError("base: not used by scene kind 'halfspace_medium' (the medium fills z < 0); remove [base]")
    if config.material.kind != "lambert":
        raise ValueError(f"material.kind = {config.material.kind!r}: scene kind 'halfspace_medium' takes 'lambert' "
                         "(its albedo is the scatterers' single-scattering albedo)")


def for_backend(config, backend: str):
    """(config, note): the medium needs no Embree at all."""
    return config, ""


def resolve(config) -> dict:
    phase = config.scene.phase
    return {"kind": KIND, "phase": phase, "phase_sampling": PHASES[phase].sampling, "mean_free_path": 1.0,
            "triangles": 0, "max_mesh_error": 0.0}


def scene_bytes(resolved: dict) -> int:
    """Two numbers."""
    return 4096


def generate(resolved: dict, config, rng: np.random.Generator) -> HalfspaceMedium:
    """The medium of a realization: its law only (the scatterers' albedo: the largest of a list)."""
    return HalfspaceMedium(Medium(PHASES[resolved["phase"]].code, max(config.material.albedos)), dict(resolved))
