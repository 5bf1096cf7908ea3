"""A toy estimator, the example of ``microsim.tracer.estimators``: the BRDF averaged over a cone
about the normal, by order, with a config key, a dataset and a comparison of its own.

A path leaving along d, theta_o below ``[sensor] cone_deg``, with weight w adds w / (N P) to
``brdf_cone``, P = pi sin^2(cone) the cone's projected solid angle: the cos-weighted mean of f over
the cone, as a cell's (docs/conventions.md §2). With the whole hemisphere (cone_deg = 90, the
default) its orders are the albedo's, over pi. ``compare --cone`` and ``fit --cone`` judge it
against the model averaged over the cone (its judge, :data:`CONE`). tests/test_estimators.py
registers it (one line in ``microsim.tracer.estimators.ESTIMATORS``): what a new estimator with
keys and a comparison costs is this module and that line.
"""

import math
from typing import NamedTuple

import numba
import numpy as np
from pydantic import Field

from microsim.analysis.fitted import Fitted
from microsim.analysis.judges import Judge
from microsim.analysis.point_comparison import PointComparison, judged_values
from microsim.analysis.selection import extra_selection
from microsim.core.orders import ORDERS
from microsim.core.schema import Section
from microsim.core.table_layout import Attribute, Dataset
from microsim.core.table_noise import CHI2_OUTSIDE, normal_squares, realizations
from microsim.tracer.estimators import Estimator
from microsim.tracer.estimators.hooks import ON_EXIT

#: Gauss-Legendre nodes of the model's average over the cone, in cos(theta_o) and in phi
NODES_MU, NODES_PHI = 16, 32


class ConeKeys(Section):
    cone_deg: float = Field(90.0, gt=0.0, le=90.0, description="half angle of the cone about the normal whose "
                            "cos-weighted mean BRDF the toy estimator tallies (brdf_cone), deg")


class ConeTally(NamedTuple):
    weight: np.ndarray  # exit weight inside the cone, by order


class Cone(Estimator):
    name = "cone"
    Record = ConeTally
    KEYS = ConeKeys
    JUDGE = "toy_estimator:CONE"
    DATASETS = tuple(Dataset(name, axes, "1/sr", doc, required=False)
                     for name, axes, doc in (("brdf_cone", ("incidences",), "f averaged over the cone, all orders"),
                                             ("brdf_cone_stderr", ("incidences",), "its standard error"),
                                             ("brdf_cone_order", ("incidences", "orders"), "brdf_cone by order"),
                                             ("brdf_cone_order_stderr", ("incidences", "orders"), "its standard error")))
    ATTRIBUTES = (Attribute("cone_deg", "the cone of brdf_cone, deg"),)

    def projected_solid_angle(self) -> float:
        return math.pi * math.sin(math.radians(self.keys.cone_deg)) ** 2

    def setup(self, wi, phi_i):
        return np.array([math.cos(math.radians(self.keys.cone_deg))])

    def shapes(self):
        return ((ORDERS,),)

    def estimate_values(self):
        return ORDERS + 1

    def reduce(self, fields, paths, incidence):
        per_path = fields.weight / paths
        return {"brdf_cone": np.append(per_path, per_path.sum()) / self.projected_solid_angle()}

    def write(self, put, estimates):
        for suffix, row in (("", ORDERS), ("_order", slice(0, ORDERS))):
            put(f"brdf_cone{suffix}", np.stack([e.mean[row] for e in estimates["brdf_cone"]]))
            put(f"brdf_cone{suffix}_stderr", np.stack([e.stderr[row] for e in estimates["brdf_cone"]]))

    def attributes(self) -> dict:
        return {"cone_deg": self.keys.cone_deg}


@ON_EXIT.register(ConeTally)
def on_exit(record, setup, tally, paths, i, d):
    if d[2] >= setup[0]:
        order = paths.order[i]
        add_weight(record.weight[tally.row], tally.albedo_scale, min(order, ORDERS) - 1, paths.weight[i], order)


@numba.njit(cache=True, error_model="numpy", _nrt=False)
def add_weight(weight, scale, row, w, order):
    """weight[row] += w, for each albedo of a run of several w scale^order (the branch on ndim is
    resolved when numba compiles, for an argument)."""
    if weight.ndim == 1:
        weight[row] += w
    else:
        for j in range(weight.shape[0]):
            weight[j, row] += w * scale[j] ** order


def cone_average(model, wi: np.ndarray, cone_deg: float) -> float:
    """The model's cos-weighted mean over the cone about the normal, at the incidence wi."""
    x, w = np.polynomial.legendre.leggauss(NODES_MU)
    lo = math.cos(math.radians(cone_deg))
    mu = lo + (1.0 - lo) * 0.5 * (x + 1.0)
    phi = (np.arange(NODES_PHI) + 0.5) * 2.0 * math.pi / NODES_PHI
    sin = np.sqrt(1.0 - mu**2)[:, None]
    wo = np.stack(np.broadcast_arrays(sin * np.cos(phi), sin * np.sin(phi), mu[:, None]), axis=-1).reshape(-1, 3)
    weight = np.repeat(w * mu, NODES_PHI)
    return float(np.sum(model(np.broadcast_to(wi, wo.shape), wo) * weight) / np.sum(weight))


class ConeComparison(PointComparison):
    unit, counted = "cone", "cones_compared"

    def rules(self) -> dict:
        return {"chi2_rule": "mean over the incidences of u^2, u the standard normal number of z = (table - "
                             "model) / stderr under Student's t of realizations - 1 degrees of freedom; bounds: "
                             f"{100 * (1 - CHI2_OUTSIDE):g} % two-sided"}

    def summary(self) -> str:
        return "the cone about the normal (a toy): the model's cos-weighted mean over it against brdf_cone"


def compare_cone(table, model, order: str = "all", **params) -> ConeComparison:
    """``model`` averaged over the table's cone against ``brdf_cone`` of ``order``."""
    model, sim, stderr = judged_values(table, model, order, CONE, params)
    sim, stderr = sim[:, None], stderr[:, None]
    modelled = np.array([[cone_average(model, wi, float(table.attrs["cone_deg"]))] for wi in table.wi])
    judged = stderr > 0
    z = np.divide(sim - modelled, stderr, out=np.zeros_like(sim), where=judged)
    terms = np.where(judged, normal_squares(z, realizations(table)), 0.0)
    return ConeComparison(model.name, dict(model.values), order, "cone", table.theta_i, table.phi_i, modelled, sim,
                          stderr, judged, np.zeros_like(judged), z, terms, np.zeros_like(sim), np.ones_like(sim), 0.0,
                          {"cone_deg": float(table.attrs["cone_deg"])})


def fitted_cone(table, first, order: str, n_free: int) -> Fitted:
    """The incidences' cone values, each weighed by its own standard error."""
    sim, stderr = extra_selection(table, order, CONE)
    cone = float(table.attrs["cone_deg"])
    fitted = np.flatnonzero(stderr > 0)
    if fitted.size <= n_free:
        raise ValueError(f"--cone: table {table.path}: {fitted.size} incidences with a value, too few to fit "
                         f"{n_free} parameters")
    return Fitted(sim[fitted], stderr[fitted], fitted,
                  lambda model: np.array([cone_average(model, table.wi[i], cone) for i in fitted]))


CONE = Judge(on="cone", unit="cone", dataset="brdf_cone", counted="cones_compared", keys="[sensor] cone_deg",
             geometry=(), help="instead of the cells, the table's cone about the normal (a toy estimator)",
             compare=compare_cone, fitted=fitted_cone)
