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

The points are the sensor's (:mod:`microsim.tracer.sensor`: ``[sensor] directions_deg`` and
``retro_points_deg``), turned toward each incidence. Datasets: ``brdf_points`` and
``brdf_points_order`` with their standard errors and, since the points of an incidence share
their paths, the covariance of their errors (both from the spread of the realizations), and the
points' angles and unit vectors per incidence.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np

from microsim.core.orders import ORDERS
from microsim.core.table_layout import Attribute, Dataset
from microsim.tracer.estimators import Estimator


class PointsTally(NamedTuple):
    """Sums of w e V over the events (rows: the order the interaction makes, 1, 2, 3, 4+;
    columns: the sensor's points), not yet divided by N mu_o."""

    weight: np.ndarray


class Points(Estimator):
    """Next-event estimation at the sensor's points (module doc): datasets brdf_points*."""

    name = "points"
    Record = PointsTally
    HOOKS = "microsim.tracer.estimators.points_hooks"
    DATASETS = tuple(
        dataset
        for name, axes, doc in (
            ("brdf_points", ("incidences", "points"), "f at each point (next-event estimation), all orders, "
             "without the delta lobes named by the points_delta_lobes attribute"),
            ("brdf_points_order", ("incidences", "orders", "points"), "brdf_points by scattering order 1, 2, 3, "
             "4+ (they sum to brdf_points)"),
        )
        for dataset in (
            Dataset(name, axes, "1/sr", doc, when="sensor.directions_deg or sensor.retro_points_deg"),
            Dataset(f"{name}_stderr", axes, "1/sr", f"standard error of {name}, from the spread of the realizations",
                    when="sensor.directions_deg or sensor.retro_points_deg"),
        )
    ) + (
        Dataset("brdf_points_covariance", ("incidences", "points", "other_points"), "1/sr^2", "covariance of the errors "
                "of brdf_points between the points of each incidence (they share their paths), from the spread "
                "of the realizations; its diagonal is brdf_points_stderr squared",
                when="sensor.directions_deg or sensor.retro_points_deg"),
        Dataset("brdf_points_order_covariance", ("incidences", "orders", "points", "other_points"), "1/sr^2",
                "brdf_points_covariance of each order", when="sensor.directions_deg or sensor.retro_points_deg"),
    ) + tuple(
        Dataset(f"sensor/points_{name}", axes, unit, doc, when="sensor.directions_deg or sensor.retro_points_deg")
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
                  when="sensor.directions_deg or sensor.retro_points_deg"),
    )

    COVARIANT = ("brdf_points",)

    @classmethod
    def wanted(cls, config) -> bool:
        """Every run: its hooks are compiled into every tracer, so that a run with points takes
        the kernel a run without them compiled (numba specializes the kernels on the estimators'
        records, and a second kernel cost as long a compile as the first). Without points they
        loop over none, draw no random number, estimate nothing and write nothing."""
        return True

    def shapes(self):
        return ((ORDERS, self.sensor.n_points),)

    def reduce(self, fields, paths, incidence):
        if not self.sensor.n_points:
            return {}
        per_path = fields.weight / paths
        rows = np.vstack([per_path, per_path.sum(axis=0)])
        return {"brdf_points": rows / self.directions[incidence][:, 2]}

    def estimate_values(self):
        # the reducer keeps three numbers a value (memory_estimate); the covariance's products
        # add n_points more, counted here in thirds
        values = (ORDERS + 1) * self.sensor.n_points
        return math.ceil(values * (3 + self.sensor.n_points) / 3)

    @functools.cached_property
    def directions(self) -> list[np.ndarray]:
        """Per incidence of the run, the points' unit vectors about it."""
        plan = self.plan
        return [self.sensor.point_directions(plan.incidence_direction(i), plan.phi_i[i])
                for i in range(plan.n_incidences)]

    def write(self, put, estimates):
        if not self.sensor.n_points:
            return
        plan = self.plan
        angles = [self.sensor.point_angles(plan.incidence_direction(i), plan.phi_i[i])
                  for i in range(plan.n_incidences)]
        for k, name in enumerate(("theta", "phi", "gamma")):
            put(f"sensor/points_{name}", np.stack([a[k] for a in angles]))
        put("sensor/points_direction", np.stack(self.directions))
        put("sensor/points_kind", self.sensor.point_spec[:, 0].astype(np.int8))
        for suffix, row in (("", ORDERS), ("_order", slice(0, ORDERS))):
            put(f"brdf_points{suffix}", np.stack([e.mean[row] for e in estimates["brdf_points"]]))
            put(f"brdf_points{suffix}_stderr", np.stack([e.stderr[row] for e in estimates["brdf_points"]]))
            put(f"brdf_points{suffix}_covariance", np.stack([e.covariance[row] for e in estimates["brdf_points"]]))

    def attributes(self) -> dict:
        if not self.sensor.n_points:
            return {}
        config = self.plan.config
        parts = [f"{name} ({m.kind}): {m.delta_lobes}" for name, m in (("material", config.material),
                                                                       ("base", config.base))
                 if m is not None and m.delta_lobes]
        return {"points_delta_lobes": "; ".join(parts)}
