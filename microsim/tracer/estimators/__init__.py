"""Estimators: what the events of a path add to a table.

An estimator is one module with one :class:`Estimator` subclass and one line in
:data:`ESTIMATORS`. It declares

- its config keys: a :class:`microsim.core.schema.Section` class ``KEYS`` whose fields join
  ``[sensor]`` (the config's ``SensorSection`` is the sensor's cells and every estimator's keys),
  and what it checks of the whole config (:meth:`Estimator.check`);
- its kernel record for an incidence (:meth:`Estimator.setup`: the sensor's cells, the rings
  about wi, the points' unit vectors), which its hooks read;
- its tally fields: a ``NamedTuple`` class ``Record`` (defined in its module, so that numba
  can cache the kernels that take it) whose fields are float64 arrays of the shapes
  :meth:`Estimator.shapes` gives; the tracer allocates them per chunk of paths, after a row
  axis and an albedo axis in a run of several albedos (:class:`microsim.core.tally.Tally`);
- its hooks, numba implementations registered on its ``Record`` class in :mod:`.hooks`, in the
  module its ``HOOKS`` names (``exit_bins_hooks``, ``points_hooks``: the declaration imports no
  numba, so that reading a table imports no kernel):
  ``on_exit`` (a path leaves the surface) and ``on_interaction`` (a path is about to interact),
  each called with the estimator's record and its setup; the walk of every integrator calls
  them (:mod:`microsim.tracer.integrators.walk`);
- its reduction of a unit's fields to per-realization estimates, named (:meth:`Estimator.reduce`);
  the reducer keeps the mean and standard error of each name over the realizations;
- the datasets it writes (:meth:`Estimator.write`), from those estimates;
- how ``compare`` and ``fit`` judge them: ``JUDGE`` names a
  :class:`microsim.analysis.judges.Judge` ("module:attribute"), which the analysis imports when
  it judges (the tracer never does).

The config, the reducer (:mod:`microsim.run.reduction`), the unit store, the table writer,
``compare``, ``fit`` and the CLI read the estimators' declarations and know none of them by name.
The estimators: :mod:`.exit_bins`, the binning of exits on the sensor's cells; :mod:`.retro_rings`,
a finer binning about the retro direction; :mod:`.points`, next-event estimation at exact
directions.
"""

from __future__ import annotations

import importlib
import math
from typing import ClassVar

import numpy as np

from microsim.core.tally import albedo_axis

#: estimator name -> "module:class", imported on use; a run uses every estimator whose
#: :meth:`Estimator.wanted` says so, in this order
ESTIMATORS = {"exit_bins": "microsim.tracer.estimators.exit_bins:ExitBins",
              "retro_rings": "microsim.tracer.estimators.retro_rings:RetroRingBins",
              "points": "microsim.tracer.estimators.points:Points"}
#: the estimators of a tracer used without a run (tests, benchmarks): every run's, so that it takes
#: the kernel a run compiled (numba specializes the kernels on the estimators' records)
DEFAULT = ("exit_bins", "retro_rings", "points")


class Estimator:
    """What one estimator adds to a run (module doc); built for a run's ``sensor`` and ``plan``
    (:class:`microsim.run.plan.Plan`; None for a tracer used without a run), reading its keys
    from ``keys`` (a section with its ``KEYS``' fields), else from the plan's ``[sensor]``, else
    their defaults."""

    name: ClassVar[str]
    #: the NamedTuple class of its tally fields (the kernels' hooks are registered on it)
    Record: ClassVar[type]
    #: the module that registers its kernel hooks, imported when an estimator is made or
    #: unpickled (None: its own module registers them); apart, so that reading a table, which
    #: reads the estimators' declarations, imports no kernel
    HOOKS: ClassVar[str | None] = None
    #: the datasets it writes (microsim.core.table_layout.Dataset): the table's declared layout
    DATASETS: ClassVar[tuple] = ()
    #: the attributes of the table's root it writes (microsim.core.table_layout.Attribute)
    ATTRIBUTES: ClassVar[tuple] = ()
    #: the names of :meth:`reduce` whose estimates share their paths along the last axis: the
    #: reducer keeps their covariance too (microsim.run.reduction.Estimate.covariance)
    COVARIANT: ClassVar[tuple] = ()
    #: its keys of ``[sensor]`` (a microsim.core.schema.Section class), or None
    KEYS: ClassVar[type | None] = None
    #: "module:attribute" of the microsim.analysis.judges.Judge that compares a model with what it
    #: writes, or None (nothing to judge)
    JUDGE: ClassVar[str | None] = None

    def __init__(self, sensor, plan=None, keys=None):
        self.sensor, self.plan = sensor, plan
        if keys is None and self.KEYS is not None:
            keys = plan.config.sensor if plan is not None else self.KEYS()
        self.keys = keys
        self.register_hooks()

    def __setstate__(self, state):
        """Unpickled (the plan of a Dask worker): its hooks are registered in this process too,
        so that a kernel compiled here calls them."""
        self.__dict__.update(state)
        self.register_hooks()

    @classmethod
    def register_hooks(cls) -> None:
        """Import the module that registers its kernel hooks (``HOOKS``; its own module does where
        it is None), so that a tracer compiled in this process calls them."""
        if cls.HOOKS is not None:
            importlib.import_module(cls.HOOKS)

    @classmethod
    def wanted(cls, config) -> bool:
        """Whether a run of ``config`` uses this estimator."""
        return True

    @classmethod
    def check(cls, config) -> None:
        """Refuse (ValueError, one line naming the key) a whole config its keys do not fit."""

    def setup(self, wi: np.ndarray, phi_i: float):
        """Its kernel record for the incidence wi of azimuth ``phi_i`` (what its hooks read besides
        its tally): a numba-typed value whose type is the same at every incidence."""
        return np.zeros(0)

    def shadow_rays(self) -> int:
        """Shadow rays it may queue per scattering event (a backend sizes its queue by them)."""
        return 0

    def shapes(self) -> tuple[tuple[int, ...], ...]:
        """The shape of each field of ``Record``, without the row and albedo axes."""
        raise NotImplementedError

    def allocate(self, rows: int, albedos: int):
        """A zero ``Record`` of ``rows`` rows (and an albedo axis if ``albedos`` > 1)."""
        return self.Record(*(np.zeros((rows, *albedo_axis(albedos), *shape)) for shape in self.shapes()))

    def tally_values(self) -> int:
        """How many numbers a row of its tally holds, for one albedo (for the memory estimate)."""
        return sum(math.prod(shape) for shape in self.shapes())

    def reduce(self, fields, paths: int, incidence: int) -> dict[str, np.ndarray]:
        """The estimates of one unit (``fields``: its ``Record`` for one albedo, without the row
        and albedo axes; ``paths`` traced at incidence number ``incidence``), by name."""
        raise NotImplementedError

    def estimate_values(self) -> int:
        """How many numbers :meth:`reduce` returns for one unit (for the memory estimate)."""
        raise NotImplementedError

    def exited(self, estimates: dict[str, np.ndarray]) -> float:
        """The share of the unit's energy that left through the top, as these estimates count it,
        for the energy balance: one estimator of a run counts it (the exit binning), every other
        returns 0."""
        return 0.0

    def write(self, put, estimates: dict) -> None:
        """Write the datasets: ``put(name, array)`` stores one; ``estimates`` maps each name of
        :meth:`reduce` to its per-incidence :class:`microsim.run.reduction.Estimate` list."""
        raise NotImplementedError

    def attributes(self) -> dict:
        """The attributes of the table's root it writes (those of ``ATTRIBUTES``), by name."""
        return {}


def get(name: str) -> type[Estimator]:
    """The estimator class registered as ``name``."""
    module, cls = ESTIMATORS[name].split(":")
    return getattr(importlib.import_module(module), cls)


def datasets() -> tuple:
    """The datasets every registered estimator may write (``Estimator.DATASETS``), in order."""
    return tuple(dataset for name in ESTIMATORS for dataset in get(name).DATASETS)


def attributes() -> tuple:
    """The root attributes every registered estimator may write (``Estimator.ATTRIBUTES``), in order."""
    return tuple(attribute for name in ESTIMATORS for attribute in get(name).ATTRIBUTES)


def classes() -> tuple[type[Estimator], ...]:
    """Every registered estimator class, in order."""
    return tuple(get(name) for name in ESTIMATORS)


def keys() -> tuple[type, ...]:
    """The ``[sensor]`` key sections the registered estimators declare, in order."""
    return tuple(cls.KEYS for cls in classes() if cls.KEYS is not None)


def setups(estimators, wi: np.ndarray, phi_i: float) -> tuple:
    """The kernel records of ``estimators`` for the incidence wi of azimuth ``phi_i``, a tuple
    parallel to their tallies' (:meth:`Estimator.setup`)."""
    return tuple(estimator.setup(wi, phi_i) for estimator in estimators)


def shadow_rays(estimators) -> int:
    """Shadow rays ``estimators`` may queue per scattering event, together."""
    return sum(estimator.shadow_rays() for estimator in estimators)


def names_for(config) -> tuple[str, ...]:
    """The estimators a run of ``config`` uses."""
    return tuple(name for name in ESTIMATORS if get(name).wanted(config))


def build(names, sensor, plan=None) -> tuple[Estimator, ...]:
    """The estimators ``names`` (of a run: ``plan``) on ``sensor``, their kernel hooks registered."""
    return tuple(get(name)(sensor, plan) for name in names)
