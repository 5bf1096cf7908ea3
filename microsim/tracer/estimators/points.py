"""Next-event estimation: f at exact directions, from a shadow ray at every scattering event.

The estimator of docs/conventions.md §2 read at a point instead of a cell: a beam of unit
irradiance, N paths; an event at x, reached with weight w along d, whose interaction sends
e(wi, wo) per steradian into wo (wi = -d; e = f_s(wi, wo) |n . wo| on a surface, without its
delta lobes; c p(-wi . wo) for a point scatterer of the medium: :data:`~microsim.tracer.integrators.walk.EVALUATE`),
adds

    w e(wi, wo) V(x -> wo) / (N mu_o)

to f(wi, wo) of the order the interaction makes, V the transmittance from x along wo to above
the surface (:data:`~microsim.tracer.integrators.walk.VISIBILITY`). The expectation over the paths is
the radiance leaving towards wo per unit irradiance, the BRDF there: unbiased, with no binning
and no cell average. On a Lambertian plane every path adds exactly albedo / pi. Light that a
delta lobe (a mirror, a conductor, the smooth interface of interfaced_lambert) sends towards wo
is not seen; the exit binning still counts it in the cells, and the table says which lobes were
left out (attribute ``points_delta_lobes``). Several albedos from one run: the event of order k
counts w e (c_j / c_max)^k, as an exit of order k does (:class:`microsim.core.tally.Tally`).

The points (:class:`PointSet`; keys ``[sensor] directions_deg`` and ``retro_points_deg``) are
asked about the incidence: a direction is (theta_o, phi_o) with phi_o the relative azimuth
(conventions §1), phi_i + phi_o in the scene's frame. A retro point at phase angle gamma is the
retro direction wi turned by gamma towards the normal, in the plane of incidence: theta_o =
theta_i - gamma on the side of the light, and past the normal (on the specular side) where
gamma > theta_i. ``compare --points`` and ``fit --points`` judge them
(:mod:`microsim.analysis.judge_points`). Datasets: ``brdf_points`` and
``brdf_points_order`` with their standard errors and, since the points of an incidence share
their paths, the covariance of their errors (both from the spread of the realizations), and the
points' angles and unit vectors per incidence.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np
import pydantic
from pydantic import Field

from microsim.core.frames import direction
from microsim.core.orders import ORDERS
from microsim.core.schema import Section, excerpt, is_number
from microsim.core.table_layout import Attribute, Dataset
from microsim.tracer.estimators import Estimator

#: most points (directions and retro points together) a run reads f at: each costs a shadow ray
#: per scattering event
MAX_POINTS = 256
#: kinds of point (``PointSet.spec``): a direction (theta_o, relative phi_o), a retro point (gamma)
DIRECTION_POINT, RETRO_POINT = 0.0, 1.0
WHEN = "sensor.directions_deg or sensor.retro_points_deg"


class PointsKeys(Section):
    """The points' keys of ``[sensor]``."""

    directions_deg: list[list[float]] = Field(
        [], description="exact directions [theta_o, phi_o] (phi_o the relative azimuth phi_o - phi_i; the "
                        "cells' azimuths are the scene's), deg, theta_o in [0, 90), "
                        f"phi_o in [-360, 360]: f there by next-event estimation (at most {MAX_POINTS} points "
                        "with retro_points_deg)")
    retro_points_deg: list[float] = Field(
        [], description="phase angles gamma in [0, 90) deg from the retro direction, towards the normal in the "
                        "plane of incidence: f there by next-event estimation")

    @pydantic.field_validator("directions_deg", mode="before")
    @classmethod
    def _directions(cls, value):
        """A list of [theta_o, phi_o] pairs of numbers, theta_o in [0, 90), phi_o in [-360, 360]."""
        accepted = "accepted: a list of [theta_o, phi_o] pairs, theta_o in [0, 90) and phi_o in [-360, 360] deg"
        value = value.tolist() if hasattr(value, "tolist") else value  # a numpy array from Python
        if not isinstance(value, (list, tuple)):
            raise ValueError(f"directions_deg = {excerpt(value)}: not a list; {accepted}")
        for k, pair in enumerate(value):
            if not isinstance(pair, (list, tuple)) or len(pair) != 2 or not all(map(is_number, pair)):
                raise ValueError(f"directions_deg[{k}] = {excerpt(pair)}: not a pair of numbers; {accepted}")
            theta, phi = pair
            if not 0.0 <= theta < 90.0:
                where = "below the horizon" if theta >= 90.0 else "out of range"
                raise ValueError(f"directions_deg[{k}] = {excerpt(pair)}: theta_o {where}; {accepted}")
            if not -360.0 <= phi <= 360.0:
                raise ValueError(f"directions_deg[{k}] = {excerpt(pair)}: phi_o out of range; {accepted}")
        return [[float(theta), float(phi)] for theta, phi in value]

    @pydantic.field_validator("retro_points_deg", mode="before")
    @classmethod
    def _retro_points(cls, value):
        """A list of numbers in [0, 90)."""
        accepted = "accepted: a list of phase angles in [0, 90) deg"
        value = value.tolist() if hasattr(value, "tolist") else value  # a numpy array from Python
        if not isinstance(value, (list, tuple)) or not all(map(is_number, value)):
            raise ValueError(f"retro_points_deg = {excerpt(value)}: not a list of numbers; {accepted}")
        for k, gamma in enumerate(value):
            if not 0.0 <= gamma < 90.0:
                raise ValueError(f"retro_points_deg[{k}] = {excerpt(gamma)}: out of range; {accepted}")
        return [float(gamma) for gamma in value]

    @pydantic.model_validator(mode="after")
    def _at_most_max_points(self):
        count = len(self.directions_deg) + len(self.retro_points_deg)
        if count > MAX_POINTS:
            # the key of the longer list: the one to shorten
            key = "directions_deg" if len(self.directions_deg) >= len(self.retro_points_deg) else "retro_points_deg"
            raise ValueError(f"sensor.{key}: {len(self.directions_deg):,} directions_deg and "
                             f"{len(self.retro_points_deg):,} retro_points_deg, {count:,} points; accepted: at "
                             f"most {MAX_POINTS} points together (each costs a shadow ray per scattering event)")
        return self


class PointSet(NamedTuple):
    """The points as asked (module doc), one row each: (DIRECTION_POINT, theta_o, phi_o) or
    (RETRO_POINT, gamma, 0), radians."""

    spec: np.ndarray

    @classmethod
    def of(cls, directions_deg=(), retro_points_deg=()) -> "PointSet":
        """The points ``directions_deg`` ([theta_o, phi_o] pairs) and ``retro_points_deg`` (phase
        angles gamma), in that order, degrees."""
        spec = [(DIRECTION_POINT, math.radians(t), math.radians(p)) for t, p in directions_deg]
        spec += [(RETRO_POINT, math.radians(g), 0.0) for g in retro_points_deg]
        return cls(np.array(spec, np.float64).reshape(-1, 3))

    def __len__(self) -> int:
        return len(self.spec)

    def directions(self, wi: np.ndarray, phi_i: float | None = None) -> np.ndarray:
        """Unit vectors (n, 3) of the points about the incidence wi (module doc); ``phi_i``, the
        incidence's azimuth, defines the plane of incidence where wi is the normal (else it is
        wi's own)."""
        spec = self.spec
        wi = np.asarray(wi, np.float64)
        theta_i, phi_i = math.acos(min(max(float(wi[2]), -1.0), 1.0)), _azimuth(wi, phi_i)
        theta, phi = spec[:, 1].copy(), phi_i + spec[:, 2]
        retro = spec[:, 0] == RETRO_POINT
        turned = theta_i - spec[retro, 1]  # negative: past the normal, on the specular side
        theta[retro], phi[retro] = np.abs(turned), np.where(turned >= 0.0, phi_i, phi_i + math.pi)
        return direction(theta, phi).reshape(-1, 3)

    def angles(self, wi: np.ndarray, phi_i: float | None = None):
        """(theta_o, relative phi_o in [0, 2 pi), phase angle gamma from wi) of every point about
        the incidence wi, radians."""
        w = self.directions(wi, phi_i)
        wi = np.asarray(wi, np.float64)
        relative = np.remainder(np.arctan2(w[:, 1], w[:, 0]) - _azimuth(wi, phi_i), 2.0 * math.pi)
        relative[relative > 2.0 * math.pi - 1e-12] = 0.0  # -0 by rounding
        relative[(w[:, 0] == 0.0) & (w[:, 1] == 0.0)] = 0.0
        gamma = 2.0 * np.arcsin(np.clip(np.linalg.norm(w - wi, axis=1) / 2.0, 0.0, 1.0))
        return np.arccos(np.clip(w[:, 2], -1.0, 1.0)), relative, gamma


def _azimuth(wi: np.ndarray, phi_i: float | None) -> float:
    """The incidence's azimuth: ``phi_i`` if given, else wi's own (0 where wi is the normal)."""
    if phi_i is not None:
        return float(phi_i)
    return math.atan2(wi[1], wi[0]) if wi[0] or wi[1] else 0.0


class PointsTally(NamedTuple):
    """Sums of w e V over the events (rows: the order the interaction makes, 1, 2, 3, 4+;
    columns: the sensor's points), not yet divided by N mu_o."""

    weight: np.ndarray


class Points(Estimator):
    """Next-event estimation at the points of the config (module doc): datasets brdf_points*."""

    name = "points"
    Record = PointsTally
    HOOKS = "microsim.tracer.estimators.points_hooks"
    KEYS = PointsKeys
    JUDGE = "microsim.analysis.judge_points:POINTS"
    DATASETS = tuple(
        dataset
        for name, axes, doc in (
            ("brdf_points", ("incidences", "points"), "f at each point (next-event estimation), all orders, "
             "without the delta lobes named by the points_delta_lobes attribute"),
            ("brdf_points_order", ("incidences", "orders", "points"), "brdf_points by scattering order 1, 2, 3, "
             "4+ (they sum to brdf_points)"),
        )
        for dataset in (
            Dataset(name, axes, "1/sr", doc, when=WHEN),
            Dataset(f"{name}_stderr", axes, "1/sr", f"standard error of {name}, from the spread of the realizations",
                    when=WHEN),
        )
    ) + (
        Dataset("brdf_points_covariance", ("incidences", "points", "other_points"), "1/sr^2", "covariance of the errors "
                "of brdf_points between the points of each incidence (they share their paths), from the spread "
                "of the realizations; its diagonal is brdf_points_stderr squared",
                when=WHEN, since="1.1"),
        Dataset("brdf_points_order_covariance", ("incidences", "orders", "points", "other_points"), "1/sr^2",
                "brdf_points_covariance of each order", when=WHEN, since="1.1"),
    ) + tuple(
        Dataset(f"sensor/points_{name}", axes, unit, doc, when=WHEN)
        for name, axes, unit, doc in (
            ("theta", ("incidences", "points"), "rad", "polar angle theta_o of each point about each incidence"),
            ("phi", ("incidences", "points"), "rad", "relative azimuth phi_o - phi_i of each point, in [0, 2 pi)"),
            ("gamma", ("incidences", "points"), "rad", "phase angle of each point from the incidence's retro "
             "direction"),
            ("direction", ("incidences", "points", "xyz"), "", "unit vector of each point about each incidence, "
             "in the scene's frame"),
            ("kind", ("points",), "", "what each point was asked as: 0 a direction of sensor.directions_deg, "
             "1 a phase angle of sensor.retro_points_deg"),
        )
    )
    ATTRIBUTES = (
        Attribute("points_delta_lobes", "what reflects by Dirac delta lobes in the scene, which next-event "
                  "estimation does not see (\"\" if nothing): brdf_points leaves it out, brdf counts it",
                  when=WHEN),
    )

    COVARIANT = ("brdf_points",)

    @classmethod
    def wanted(cls, config) -> bool:
        """Every run: its hooks are compiled into every tracer, so that a run with points takes
        the kernel a run without them compiled (numba specializes the kernels on the estimators'
        records, and a second kernel cost as long a compile as the first). Without points they
        loop over none, draw no random number, estimate nothing and write nothing."""
        return True

    @classmethod
    def check(cls, config) -> None:
        """Next-event estimation sees the lobes that are not a Dirac delta: a scene whose every
        material reflects by delta lobes or absorbs has nothing to show it (ValueError)."""
        keys = config.sensor
        materials = [config.material] + ([config.base] if config.base is not None else [])
        if (keys.directions_deg or keys.retro_points_deg) and not any(m.continuous for m in materials):
            kinds = ", ".join(f"{name}.kind = {m.kind!r}" for name, m in zip(("material", "base"), materials))
            key = "sensor.directions_deg" if keys.directions_deg else "sensor.retro_points_deg"
            raise ValueError(f"{key}: next-event estimation sees no light in this scene ({kinds}: delta lobes "
                             "or absorption only); accepted: a scene with a lambert or interfaced_lambert "
                             "material, or no points (the cells see delta lobes)")

    @functools.cached_property
    def points(self) -> PointSet:
        """The points its keys ask for."""
        return PointSet.of(self.keys.directions_deg, self.keys.retro_points_deg)

    def setup(self, wi, phi_i):
        return self.points.directions(wi, phi_i)

    def shadow_rays(self) -> int:
        return len(self.points)

    def shapes(self):
        return ((ORDERS, len(self.points)),)

    def reduce(self, fields, paths, incidence):
        if not len(self.points):
            return {}
        per_path = fields.weight / paths
        rows = np.vstack([per_path, per_path.sum(axis=0)])
        return {"brdf_points": rows / self.directions[incidence][:, 2]}

    def estimate_values(self):
        # the reducer keeps three numbers a value (memory_estimate); the covariance's products
        # add n_points more, counted here in thirds
        values = (ORDERS + 1) * len(self.points)
        return math.ceil(values * (3 + len(self.points)) / 3)

    @functools.cached_property
    def directions(self) -> list[np.ndarray]:
        """Per incidence of the run, the points' unit vectors about it."""
        plan = self.plan
        return [self.points.directions(plan.incidence_direction(i), plan.phi_i[i]) for i in range(plan.n_incidences)]

    def write(self, put, estimates):
        if not len(self.points):
            return
        plan = self.plan
        angles = [self.points.angles(plan.incidence_direction(i), plan.phi_i[i])
                  for i in range(plan.n_incidences)]
        for k, name in enumerate(("theta", "phi", "gamma")):
            put(f"sensor/points_{name}", np.stack([a[k] for a in angles]))
        put("sensor/points_direction", np.stack(self.directions))
        put("sensor/points_kind", self.points.spec[:, 0].astype(np.int8))
        for suffix, row in (("", ORDERS), ("_order", slice(0, ORDERS))):
            put(f"brdf_points{suffix}", np.stack([e.mean[row] for e in estimates["brdf_points"]]))
            put(f"brdf_points{suffix}_stderr", np.stack([e.stderr[row] for e in estimates["brdf_points"]]))
            put(f"brdf_points{suffix}_covariance", np.stack([e.covariance[row] for e in estimates["brdf_points"]]))

    def attributes(self) -> dict:
        if not len(self.points):
            return {}
        config = self.plan.config
        parts = [f"{name} ({m.kind}): {m.delta_lobes}" for name, m in (("material", config.material),
                                                                       ("base", config.base))
                 if m is not None and m.delta_lobes]
        return {"points_delta_lobes": "; ".join(parts)}
