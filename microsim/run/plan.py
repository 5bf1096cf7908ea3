"""The plan of a run: everything a worker needs to trace any unit of it (picklable).

A run is realizations x incidences of paths. Each realization is one batch: an independent
geometry sample, traced with an independent random stream for every incidence, with the same
number of paths; work is cut into units (realization r, incidence i), the random stream of a
unit keyed by (seed, r, i) and the geometry of realization r by (seed, r), so that a unit's
tally does not depend on which process traced it. The plan resolves what the config leaves
open here (the backend, and the scene as that backend can trace it), and builds the run's
parts (its sensor, estimators and tracer class) once, when first asked.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from microsim import geometry
from microsim.core.frames import direction
from microsim.core.tally import SINGLE_ALBEDO
from microsim.tracer import embree, estimators, integrators
from microsim.tracer.sensor import Sensor


@dataclass
class Plan:
    """Everything a worker needs to trace any unit of a run (picklable). Its parts (the sensor,
    the estimators and the tracer class) are built once, when first asked, and travel with it: a
    forked worker inherits them, a Dask worker unpickles them. The generator, a module, is looked
    up each time (a module does not pickle)."""

    config: object
    scene: dict  # resolved scene parameters
    theta_i: np.ndarray
    phi_i: np.ndarray
    sensor_cells: int
    realizations: int
    paths_per_realization: int
    backend: str  # resolved run.backend: "direct" or "embreex"
    backend_note: str  # why "auto" fell back to embreex ("" otherwise)
    threads: int = 1
    albedos: tuple = ()  # the material's albedos traced together (conventions §4); () for one
    estimator_names: tuple = estimators.DEFAULT  # the run's estimators (microsim.tracer.estimators)
    #: a process of two threads or more builds the next realization while one traces, and holds
    #: both (microsim.run.executors.trace_units), unless two scenes would not fit (microsim.run.memory)
    builds_ahead: bool = False

    @functools.cached_property
    def albedo_scale(self) -> np.ndarray:
        """c_j / c_max of every albedo traced together (microsim.core.tally.Tally); [1] for a run of one."""
        if not self.albedos:
            return SINGLE_ALBEDO
        return np.asarray(self.albedos, np.float64) / max(self.albedos)

    @classmethod
    def from_config(cls, config, threads: int = 1, workers: int = 1) -> "Plan":
        """The plan of a validated config on ``workers`` processes of ``threads`` threads; raises
        PlanError (one line) if it cannot be traced here. The backend, and the scene as that
        backend can trace it, are resolved here, and every substitution is said in backend_note."""
        run = config.run
        theta = np.radians(np.asarray(config.illumination.theta_i_deg, dtype=np.float64))
        phi = np.radians(np.asarray(config.illumination.azimuths_deg(), dtype=np.float64))
        backend, notes = resolve_backend(run.backend, check=workers == 1)
        if backend == "embreex" and threads > 1:
            if run.backend == "embreex":
                raise PlanError(f"--threads {threads}: the embreex backend traces on one thread; use --workers")
            threads, notes = 1, notes + ["one thread (the embreex backend has no threads)"]
        generator = geometry.SCENES[config.scene.kind]
        try:
            config, substitution = generator.for_backend(config, backend)
        except ValueError as err:  # a scene that backend cannot trace (geometry/__init__.py)
            raise PlanError(str(err)) from None
        notes += [substitution] if substitution else []
        return cls(config, generator.resolve(config), theta, phi, config.sensor.cells, run.realizations,
                   math.ceil(run.paths / run.realizations), backend, "; ".join(notes), threads, albedos_of(config),
                   estimators.names_for(config), threads > 1)

    @property
    def n_incidences(self) -> int:
        return len(self.theta_i)

    @property
    def paths(self) -> int:
        """Paths traced per incidence."""
        return self.realizations * self.paths_per_realization

    @functools.cached_property
    def units(self) -> list[tuple[int, int]]:
        """(realization, incidence) in the order tallies are summed."""
        return [(r, i) for r in range(self.realizations) for i in range(self.n_incidences)]

    def incidence_direction(self, i: int) -> np.ndarray:
        return direction(self.theta_i[i], self.phi_i[i])

    @functools.cached_property
    def sensor(self) -> Sensor:
        """The run's sensor: its cells."""
        return Sensor.build(self.sensor_cells)

    @functools.cached_property
    def estimators(self) -> tuple:
        """The run's estimators on its sensor (microsim.tracer.estimators)."""
        return estimators.build(self.estimator_names, self.sensor, self)

    @property
    def generator(self):
        """The scene generator module of the config's scene kind."""
        return geometry.SCENES[self.config.scene.kind]

    @functools.cached_property
    def tracer_class(self):
        """The integrator class that traces the scenes of this run (named by the generator)."""
        return integrators.get(self.generator.INTEGRATOR)

    @property
    def tracer_options(self) -> dict:
        return {"backend": self.backend, "threads": self.threads}


class PlanError(ValueError):
    """A config that cannot be traced on this machine: the message is one line."""


def albedos_of(config) -> tuple:
    """The albedos of a run of several (conventions §4), () for a run of one; PlanError where a
    list cannot be traced as one run: every interaction must be with the Lambertian material or
    absorb everything (microsim.core.tally.Tally)."""
    base = config.base
    if base is not None and len(getattr(base, "albedos", ())) > 1:
        raise PlanError("base.albedo: a list of albedos is taken by [material] only")
    albedos = getattr(config.material, "albedos", ())
    if len(albedos) <= 1:
        return ()
    if base is not None and base.kind != "absorber":
        raise PlanError(f"material.albedo = {list(albedos)}: several albedos from one run need every interaction "
                        f"to be with the material or absorb everything; here [base] is {base.kind!r} "
                        "(give it kind = \"absorber\", or run one albedo at a time)")
    return albedos


def resolve_backend(requested: str, check: bool = True) -> tuple[str, list[str]]:
    """(backend, [why "auto" fell back]): "direct" where the Embree binding loads, else "embreex".

    ``check`` = False (a process about to fork workers) only loads the library: its layout
    check commits a scene, which starts Embree's threads; each worker then checks for itself.
    """
    if requested == "embreex":
        return "embreex", []
    try:
        embree.load() if check else embree.available()
    except embree.EmbreeUnavailable as err:
        if requested == "direct":
            raise PlanError(f"run.backend = 'direct': {err}") from None
        return "embreex", [f"the direct backend is unavailable ({err})"]
    return "direct", []
