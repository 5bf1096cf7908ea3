"""Model versus table, cell by cell (docs/conventions.md §2 and §7).

A table cell holds the cos(theta_o)-weighted average of the BRDF over the cell, so the model
is averaged the same way, by Gauss quadrature over each cell (:meth:`Sensor.cell_quadrature`).
The rule is refined cell by cell (4 x 4, 8 x 8, ... up to 128 x 128 nodes) until two
successive rules differ by less than ``QUADRATURE_TOLERANCE`` of the cell's standard error, so
the averaging error stays far below the table's noise; a cell without a standard error (no
path reached it) is refined until its change, times its projected solid angle, is below
``ALBEDO_TOLERANCE`` / cells of the model's albedo, so that the albedo, which sums every cell,
is converged too (a narrow specular lobe at grazing incidence on flat grains left it 0.5 %
short when such cells stopped at 8 x 8). The largest remaining change is reported, in standard
errors (for cells without one, in their albedo share over QUADRATURE_TOLERANCE).

Metrics are taken over the cells with signal, where the table value exceeds
``SIGNAL_TO_NOISE`` standard errors (a relative error means nothing on a cell the simulation
did not resolve). NaN or infinity, in the table or in the model, is an error, never a cell
silently left out.

Chi-square per cell, and whether the model is consistent with the table: each cell's squared
difference over the variance it would have if the model were the table's BRDF (the paths' and
the realizations' share, :mod:`microsim.core.table_noise`), not over its own estimated error, which
runs high at few paths a cell. 1 is expected, within two-sided CHI2_OUTSIDE bounds. The model
is "consistent" with the table when chi-square lies within them and the albedo's z^2 (over the
incidences) under its upper bound; above, it is not the table's BRDF; below, the table's errors
are too large.

Points (``--points``, :func:`compare_points`): next-event estimation's f at the exact directions
of ``[sensor] directions_deg`` and ``retro_points_deg`` (``brdf_points``), against the model at
those directions, nothing averaged. Nothing predicts a point's variance from the model (a point
is no bin that paths exit into), so z = (table - model) / the point's own standard error; that
error is estimated from R realizations, so z is Student's t of R - 1 degrees of freedom for the
table's own BRDF, and chi-square per point is the mean of the squares of the standard normal
numbers of the same tail probabilities (:func:`table_noise.normal_squares`), 1 in expectation
whatever the points' correlation. That correlation is large: the points of an incidence share
its paths (in a half space of albedo 0.9, 0.7 to 0.99 between points 0 to 80 degrees apart), so
the 99 % bounds of chi-square of as many degrees of freedom as points, over their number,
rejected the exact model at 30 of 80 incidences (40 tables of a medium traced to order 1, 6
points an incidence, 8 realizations).

Tables hold the covariance of the mean of their points (``brdf_points_covariance``,
``brdf_points_order_covariance``, from the R realizations), and there each incidence is judged
by Hotelling's test of its points with spread (:func:`table_noise.hotelling`): F = (R - k) /
(k (R - 1)) T^2, T^2 = d^T C^+ d over the k eigen-directions of C above its rounding, against
F(k, R - k), two-sided CHI2_OUTSIDE bounds, and along the other directions (relations between
the points) the deviation within a few of their largest standard error. The incidences share
the realizations (and the geometry's), so no statistic joins them: overall, the model is
consistent when every incidence is at the Bonferroni level CHI2_OUTSIDE / (incidences tested),
the smallest p-value reported. Chi-square per point stays, as a description. An incidence with
as many points with spread as realizations or more has no test (C has rank R - 1 at most) and
takes the bounds below instead, at the same level. On the half space at order 1, 16
realizations of 1 000 paths, 7 and 8 points: an albedo 0.5 % off gave F = 20 and 531 against
an upper bound of 6.5, its chi-square per point 0.5 and 1.5 against 7.9.

A table without the covariance (written before it existed) keeps the bounds of chi-square of
one degree of freedom, every point's error one common error (``chi2_bounds`` with realizations'
share 1): for normal errors, whatever their correlation, the mean of the squares exceeds the
upper one with probability at most CHI2_OUTSIDE / 2 (Szekely and Bakirov 2003). A model off by
more than its errors at many points still exceeds it many times over; the lower bound, near 0,
tells nothing of errors too large. The JSON's ``points_statistic`` says which rule judged
("hotelling" or "chi2_1dof"; per incidence, also "exact" where no point has spread). Every point
is compared but those where model and table are both 0 and those that repeat another point of
their incidence (normal incidence: the retro point at gamma = 0 is the direction [0, 0]). A
point without spread (standard error under ``EXACT_POINT`` of its value: every path adds the
same, as on a Lambertian plane) is exact: it stays out of chi-square and Hotelling's test, and
the model must equal it to EXACT_POINT. Delta lobes (a mirror's, a smooth interface's) are not
in the points (the table's attribute ``points_delta_lobes`` names them). The orders 1 and 2
together and the base's part of order 1 are refused: the table holds neither at its points, and
the error of the sum of two order rows needs their covariance.

Retro rings (``--retro``, :func:`compare_retro`): the model averaged over each ring about the
retro direction with the cos(theta_o) weight (:meth:`Sensor.retro_ring_quadrature`, refined as
the cells' rule is) against ``brdf_retro``. A ring is a bin that the paths exit into, as a cell
is: its variance if the model were right comes from the cells' dispersion and realizations'
scale (the same paths), and it is judged as a cell is, over the rings with signal (rings the
horizon cuts entirely have none). Neither points nor rings have an albedo.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from microsim.core import table_noise
from microsim.core.table_noise import (
    CHI2_OUTSIDE,
    chi2_1dof_p,
    chi2_bounds,
    hotelling,
    normal_squares,
    predicted_variance,
    realization_scale,
    realizations,
)

QUADRATURE_TOLERANCE = 0.05
ALBEDO_TOLERANCE = 1e-4
QUADRATURE_RULES = (4, 8, 16, 32, 64, 128)
SIGNAL_TO_NOISE = 3.0
#: incidences of two tables within this (radians) are the same: their cells are compared one by one
SAME_INCIDENCE = 1e-9
#: the Gauss rule (nodes a side) averaging a tabulated BRDF over a cell of another table
TABULATED_RULE = 16
#: --order choice -> row of the table's brdf_order (None: all orders, the table's brdf; BASE: the
#: part of order 1 scattered by the base, brdf_order1_base, in tables of scenes with a base)
BASE = "base"
#: orders 1 and 2 together, brdf_orders12 (the f2 of Meneveaux et al. 2015, Sec. 3.3)
ORDERS12 = "orders12"
ORDER_ROWS = {"all": None, "1": 0, "2": 1, "3": 2, "4+": 3, "1+2": ORDERS12, "1-base": BASE}
#: a point whose standard error is under this fraction of its value has no spread (every path adds
#: the same, as on a Lambertian plane): the model must equal it to this fraction
EXACT_POINT = 1e-9
#: the retro rings' rules: n x 4 n nodes a ring (Sensor.retro_ring_quadrature), refined as the cells' are
RING_RULES = (8, 16, 32, 64)
#: what --points and --retro compare on (PointComparison.on): the word for one, the datasets, the
#: count of those judged, and the config that makes them
ON = {
    "points": ("point", "brdf_points", "points_compared", "[sensor] directions_deg or retro_points_deg"),
    "retro": ("ring", "brdf_retro", "rings_with_signal", "[sensor] retro_rings"),
}


@dataclass
class Comparison:
    """Model and simulation on the cells of a table, with the metrics of conventions §7."""

    model_name: str
    params: dict
    order: str
    theta_i: np.ndarray
    phi_i: np.ndarray
    model: np.ndarray  # (n_i, n_c) cell averages of the model
    sim: np.ndarray  # (n_i, n_c)
    stderr: np.ndarray  # (n_i, n_c)
    signal: np.ndarray  # (n_i, n_c) bool
    albedo_model: np.ndarray  # (n_i,) sum over cells of model * projected solid angle
    albedo_sim: np.ndarray
    albedo_sim_stderr: np.ndarray
    quadrature_change: float  # largest last-refinement change, in standard errors
    #: (n_i, n_c) each cell's variance if the model were right, the excess kurtosis of its paths'
    #: part, and the realizations' share of it (table_noise.predicted_variance)
    variance: np.ndarray
    kurtosis: np.ndarray
    common: np.ndarray
    #: (n_i, m): the standard deviation, in each incidence's albedo difference, of m independent
    #: scales common to every incidence (the realizations' of each table: the incidences of a
    #: table share their geometry); None: none, the incidences independent
    albedo_common: np.ndarray | None = None
    #: (n_i,) the sum over pairs of distinct cells with signal of each incidence of their errors'
    #: squared correlation (a tabulated model's cells share its table's values); None: 0
    correlated: np.ndarray | None = None
    #: whose errors ``stderr`` and ``variance`` hold beyond the table's (a tabulated model's:
    #: :func:`compare_tables`, :func:`compare_tabulated`); None for an analytic model, exact
    model_errors: str | None = None
    #: why the bounds, made for independent estimates, do not hold (:func:`not_independent`); None: they do
    warning: str | None = None

    def _exact_agree(self, i: int | None = None) -> bool:
        """Whether every exact point (of incidence ``i``, or of all) equals the model to EXACT_POINT."""
        rows = slice(None) if i is None else slice(i, i + 1)
        return not np.any(np.abs(self.z[rows][self.exact[rows]]) > 1.0)

    def metrics(self, i: int | None = None) -> dict:
        """The metrics of one incidence, or over all incidences (``i=None``)."""
        rows = slice(None) if i is None else slice(i, i + 1)
        m, s, e, ok = self.model[rows], self.sim[rows], self.stderr[rows], self.signal[rows]
        rel = (m[ok] - s[ok]) / s[ok]
        z = (m[ok] - s[ok]) / e[ok]
        v = self.variance[rows][ok]
        chi2 = float(np.mean((m[ok] - s[ok]) ** 2 / v)) if z.size else float("nan")
        correlated = 0.0 if self.correlated is None else float(np.sum(self.correlated[rows]))
        low, high = chi2_bounds(self.kurtosis[rows][ok], self.common[rows][ok], correlated)
        albedo_z = self.albedo_z()[rows]
        albedo_limit = albedo_bound(self.albedo_correlation()[rows, rows])
        out = {
            "cells_with_signal": int(ok.sum()),
            "median_abs_rel_err": float(np.median(np.abs(rel))) if rel.size else float("nan"),
            "rel_rmse": float(np.sqrt(np.mean(rel**2))) if rel.size else float("nan"),
            "max_abs_z": float(np.max(np.abs(z))) if z.size else float("nan"),
            "chi2_per_cell": chi2,
            "chi2_expected": 1.0,
            "chi2_bounds": [low, high],
            "albedo_z2": float(np.mean(albedo_z**2)),
            "albedo_z2_bound": albedo_limit,
            # None where no cell has signal: nothing to judge
            "consistent": bool(low <= chi2 <= high and np.mean(albedo_z**2) <= albedo_limit) if z.size else None,
        }
        if i is None:
            out["albedo_model"] = float(np.mean(self.albedo_model))
            out["albedo_sim"] = float(np.mean(self.albedo_sim))
        else:
            out = {"theta_i_deg": _degrees(self.theta_i[i]), "phi_i_deg": _degrees(self.phi_i[i]),
                   **out, "albedo_model": float(self.albedo_model[i]), "albedo_sim": float(self.albedo_sim[i]),
                   "albedo_sim_stderr": float(self.albedo_sim_stderr[i])}
        return out

    def albedo_z(self) -> np.ndarray:
        """(n_i,) (model's albedo - table's) / its standard error (:meth:`albedo_error`)."""
        error = self.albedo_error()
        return (self.albedo_model - self.albedo_sim) / np.where(error > 0, error, np.inf)

    def albedo_error(self) -> np.ndarray:
        """(n_i,) the standard error of each albedo difference: the table's, and the albedo
        quadrature's own tolerance (ALBEDO_TOLERANCE of it) in quadrature (a plane's albedo has
        no error)."""
        return np.hypot(self.albedo_sim_stderr, ALBEDO_TOLERANCE * np.abs(self.albedo_model))

    def albedo_correlation(self) -> np.ndarray:
        """(n_i, n_i) the correlation of the incidences' albedo z: their common scales'
        (``albedo_common``) covariance over their errors, 1 on the diagonal."""
        n = len(self.albedo_model)
        if self.albedo_common is None:
            return np.eye(n)
        error = self.albedo_error()
        scaled = np.divide(self.albedo_common, error[:, None], out=np.zeros_like(self.albedo_common),
                           where=error[:, None] > 0)
        correlation = np.clip(scaled @ scaled.T, -1.0, 1.0)
        np.fill_diagonal(correlation, 1.0)
        return correlation

    def as_dict(self) -> dict:
        return {
            "model": self.model_name,
            "params": self.params,
            "order": self.order,
            "per_incidence": [self.metrics(i) for i in range(len(self.theta_i))],
            "overall": self.metrics(),
            "signal_rule": f"table value > {SIGNAL_TO_NOISE:g} standard errors",
            "chi2_rule": "mean over the cells with signal of (model - table)^2 / v, v the cell's variance if the "
                         f"model were right; bounds: {100 * (1 - CHI2_OUTSIDE):g} % two-sided; consistent: within "
                         f"them, and the mean albedo z^2 below its {100 * (1 - CHI2_OUTSIDE / 2):g} % point",
            "quadrature_max_change_in_stderr": self.quadrature_change,
            **({"model_errors": self.model_errors} if self.model_errors else {}),
            **({"warning": self.warning} if self.warning else {}),
        }


@dataclass
class PointComparison:
    """Model and simulation at a table's points (``on`` = "points") or on its retro rings
    ("retro"), with the metrics of conventions §7 but the albedo's (module doc)."""

    model_name: str
    params: dict
    order: str
    on: str
    theta_i: np.ndarray
    phi_i: np.ndarray
    model: np.ndarray  # (n_i, n) the model at each point, or averaged over each ring
    sim: np.ndarray  # (n_i, n)
    stderr: np.ndarray  # (n_i, n)
    judged: np.ndarray  # (n_i, n) bool: the points compared, the rings with signal
    exact: np.ndarray  # (n_i, n) bool: the judged points without spread (EXACT_POINT)
    z: np.ndarray  # (n_i, n) (table - model) / standard error (of an exact point: EXACT_POINT of its value)
    #: (n_i, n) each judged point's or ring's share of chi-square (1 expected), and the excess
    #: kurtosis and realizations' share of it that its bounds take (table_noise.chi2_bounds)
    terms: np.ndarray
    kurtosis: np.ndarray
    common: np.ndarray
    quadrature_change: float  # rings: the largest last-refinement change, in standard errors
    notes: dict  # keys added to as_dict
    #: points of a table with their covariance: each incidence's Hotelling test (None where it has
    #: none: no point with spread, or as many as realizations or more); None: a table without it
    hotelling: list | None = None
    realizations: int = 0  # the realizations the points' errors come from

    @property
    def statistic(self) -> str | None:
        """What judges the points: "hotelling" (the table holds their covariance), "chi2_1dof", or
        "exact" (no point has spread: each must equal the model to EXACT_POINT)."""
        if self.on != "points":
            return None
        if not (self.judged & ~self.exact).any():
            return "exact"
        return "chi2_1dof" if self.hotelling is None else "hotelling"

    def incidence_test(self, i: int) -> tuple[str, float, bool]:
        """(statistic, two-sided p-value, relations held) of incidence i of a table with the
        points' covariance: Hotelling's test, the bounds of one degree of freedom where it has
        none, or "exact" where no point has spread (p 1 where each equals the model to
        EXACT_POINT, else 0)."""
        h = self.hotelling[i]
        if h is not None:
            return "hotelling", h.p, h.relations_hold
        noisy = self.judged[i] & ~self.exact[i]
        if not noisy.any():
            return "exact", float(self._exact_agree(i)), True
        return "chi2_1dof", chi2_1dof_p(float(np.mean(self.terms[i][noisy]))), True

    def _exact_agree(self, i: int | None = None) -> bool:
        """Whether every exact point (of incidence ``i``, or of all) equals the model to EXACT_POINT."""
        rows = slice(None) if i is None else slice(i, i + 1)
        return not np.any(np.abs(self.z[rows][self.exact[rows]]) > 1.0)

    def metrics(self, i: int | None = None) -> dict:
        """The metrics of one incidence, or over all incidences (``i=None``)."""
        rows = slice(None) if i is None else slice(i, i + 1)
        m, s, ok, exact = self.model[rows], self.sim[rows], self.judged[rows], self.exact[rows]
        seen = ok & (s > 0)  # a relative error where the table has light
        rel = (m[seen] - s[seen]) / s[seen]
        z = self.z[rows][ok]
        noisy = ok & ~exact
        # without a point with spread there is no chi-square (None, as its bounds): the exact
        # points' agreement is the whole verdict
        chi2 = float(np.mean(self.terms[rows][noisy])) if noisy.any() else None
        bounds = list(chi2_bounds(self.kurtosis[rows][noisy], self.common[rows][noisy])) if noisy.any() else None
        agree = self._exact_agree(i)
        unit, _, count, _ = ON[self.on]
        out = {
            count: int(ok.sum()),
            "median_abs_rel_err": float(np.median(np.abs(rel))) if rel.size else float("nan"),
            "rel_rmse": float(np.sqrt(np.mean(rel**2))) if rel.size else float("nan"),
            "max_abs_z": float(np.max(np.abs(z))) if z.size else float("nan"),
            f"chi2_per_{unit}": chi2,
            "chi2_expected": 1.0,
            "chi2_bounds": bounds,
            # None where nothing is judged
            "consistent": bool(agree and (not noisy.any() or bounds[0] <= chi2 <= bounds[1])) if ok.any() else None,
        }
        if self.on == "points":
            out["points_without_spread"] = int(exact.sum())
            out["points_statistic"] = self.statistic
            if self.hotelling is not None and ok.any():
                out.update(self._hotelling_metrics(i, agree))
        if i is not None:
            out = {"theta_i_deg": _degrees(self.theta_i[i]), "phi_i_deg": _degrees(self.phi_i[i]), **out}
        return out

    def _hotelling_metrics(self, i: int | None, agree: bool) -> dict:
        """The keys of a table with the points' covariance (module doc): an incidence's test, or
        over all, the smallest p-value against the Bonferroni level; ``consistent`` from them and
        ``agree`` (every exact point equal)."""
        tested = [n for n in range(len(self.theta_i)) if self.judged[n].any()]
        if i is None:
            tests = [self.incidence_test(n) for n in tested]
            # exact incidences (p 0 or 1) are no tests of chance: the level divides among the others
            level = CHI2_OUTSIDE / max(sum(t[0] != "exact" for t in tests), 1)
            p = min((t[1] for t in tests), default=1.0)
            return {"p_value_min": p, "bonferroni_level": level,
                    "incidences_chi2_1dof": sum(t[0] == "chi2_1dof" for t in tests),
                    "consistent": bool(agree and all(t[2] for t in tests) and p >= level)}
        statistic, p, held = self.incidence_test(i)
        out = {"points_statistic": statistic, "p_value": p}
        if statistic == "hotelling":
            h = self.hotelling[i]
            out.update({"hotelling_f": h.f, "hotelling_dof": list(h.dof), "hotelling_bounds": list(h.bounds()),
                        "points_dropped": h.dropped, "dropped_max_ratio": h.dropped_ratio})
        elif statistic == "chi2_1dof":
            spread = int((self.judged[i] & ~self.exact[i]).sum())
            why = ("as many as the realizations or more: no Hotelling test (the covariance of R realizations has "
                   "rank R - 1 at most)" if spread >= self.realizations else
                   "no direction of their covariance above its rounding: no Hotelling test")
            out["points_statistic_note"] = f"{spread} points with spread, {why}; the bounds of 1 degree of freedom"
        out["consistent"] = bool(agree and held and p >= CHI2_OUTSIDE)
        return out

    def as_dict(self) -> dict:
        if self.on == "points" and self.hotelling is not None:
            rules = {
                "points_rule": "every point but those where model and table are both 0 and those that repeat "
                               f"another of their incidence; a point without spread (standard error under "
                               f"{EXACT_POINT:g} of its value) is exact: out of the statistics, the model must "
                               f"equal it to {EXACT_POINT:g}",
                "points_statistic": "hotelling",
                "hotelling_rule": "per incidence, Hotelling's T^2 = d^T C^+ d of the deviations d = table - model "
                                  "at the points with spread, C the covariance of their mean (brdf_points_covariance), "
                                  f"over the k eigen-directions of C above {table_noise.KEPT_ROUNDING:g} times its "
                                  "rounding eps |f|^2 / R; F = (R - k) / (k (R - 1)) T^2 ~ F(k, R - k) for the "
                                  f"table's own BRDF, R realizations; bounds: {100 * (1 - CHI2_OUTSIDE):g} % "
                                  "two-sided; along a dropped direction the deviation must lie within "
                                  f"{table_noise.DROPPED_LIMIT:g} standard errors of the largest variance it can "
                                  f"have ({table_noise.KEPT_ROUNDING:g} times the rounding) + {EXACT_POINT:g} of "
                                  "the points' size; an incidence with as many points with spread as realizations or "
                                  "more takes the bounds of chi2_per_point of 1 degree of freedom instead; "
                                  "consistent: within them, the dropped directions held, and every exact point "
                                  "equal. Overall (the incidences share the realizations: no joint statistic): "
                                  f"every incidence consistent at the Bonferroni level {CHI2_OUTSIDE:g} / the "
                                  "incidences tested, i.e. p_value_min >= bonferroni_level",
                "chi2_rule": "descriptive: mean over the points with spread of u^2, u the standard normal number of "
                             "the tail probability of z = (table - model) / stderr under Student's t of realizations "
                             f"- 1 degrees of freedom; chi2_bounds: {100 * (1 - CHI2_OUTSIDE):g} % two-sided, of "
                             "chi-square of 1 degree of freedom (valid whatever the correlation, weak); the verdict "
                             "is Hotelling's",
            }
        elif self.on == "points":
            rules = {
                "points_rule": "every point but those where model and table are both 0 and those that repeat "
                               f"another of their incidence; a point without spread (standard error under "
                               f"{EXACT_POINT:g} of its value) is exact: out of chi-square, the model must equal it "
                               f"to {EXACT_POINT:g}",
                "chi2_rule": "mean over the points with spread of u^2, u the standard normal number of the tail "
                             "probability of z = (table - model) / stderr under Student's t of realizations - 1 "
                             f"degrees of freedom; bounds: {100 * (1 - CHI2_OUTSIDE):g} % two-sided, of chi-square "
                             "of 1 degree of freedom whatever the number of points (they share their paths, and "
                             "the table holds no correlation between them); consistent: within them, and every "
                             "exact point equal",
                "points_statistic": "chi2_1dof",
                "points_statistic_note": "the table holds no brdf_points_covariance (written before it existed): "
                                         "the conservative bounds of 1 degree of freedom",
            }
        else:
            rules = {
                "signal_rule": f"table value > {SIGNAL_TO_NOISE:g} standard errors, on rings above the horizon",
                "chi2_rule": "mean over the rings with signal of (model - table)^2 / v, v the ring's variance if "
                             "the model were right (from the cells' dispersion: the same paths); bounds: "
                             f"{100 * (1 - CHI2_OUTSIDE):g} % two-sided; consistent: within them",
                "quadrature_max_change_in_stderr": self.quadrature_change,
            }
        return {
            "model": self.model_name,
            "params": self.params,
            "order": self.order,
            "on": self.on,
            "per_incidence": [self.metrics(i) for i in range(len(self.theta_i))],
            "overall": self.metrics(),
            **rules,
            **self.notes,
        }


def cell_averages(model, sensor, wi: np.ndarray, stderr: np.ndarray):
    """Model averaged over every cell, refined until stable within the cell's standard error
    (cells without one: within their share of ALBEDO_TOLERANCE of the albedo). Returns the
    averages and the largest last change, in standard errors."""
    averages, change, _ = refined_cell_averages(model, sensor, wi, stderr)
    return averages, change


def refined_cell_averages(model, sensor, wi: np.ndarray, stderr: np.ndarray, tolerance: float = QUADRATURE_TOLERANCE):
    """:func:`cell_averages` refined to ``tolerance`` standard errors, and the rule each cell
    settled on (an n of QUADRATURE_RULES: n x n nodes), which :class:`CellRule` can hold fixed
    (``microsim fit``)."""
    projected = sensor.projected_solid_angle()
    pending = np.arange(sensor.n_cells)
    previous = None
    result = np.zeros(sensor.n_cells)
    change = np.zeros(sensor.n_cells)
    level = np.full(sensor.n_cells, QUADRATURE_RULES[-1])
    for n in QUADRATURE_RULES:
        w, weight = sensor.cell_quadrature(n, n, pending)
        values = model(np.broadcast_to(wi, w.shape), w)
        current = np.sum(values * weight, axis=1)
        result[pending] = current
        if previous is None:
            share = ALBEDO_TOLERANCE * max(float(result @ projected), 1e-300) / sensor.n_cells / projected
            floor = np.where(stderr > 0, stderr, share / tolerance)
            previous = current
            continue
        change[pending] = np.abs(current - previous) / floor[pending]
        still = change[pending] > tolerance
        level[pending[~still]] = n
        previous = current[still]
        pending = pending[still]
        if pending.size == 0:
            break
    return result, float(change.max(initial=0.0)), level


class CellRule:
    """A fixed quadrature of every cell: cell c with the n x n rule ``level[c]`` (from
    :func:`refined_cell_averages`), so that a model's cell averages at other parameters cost one
    evaluation and move smoothly with them (what a least-squares fit needs)."""

    def __init__(self, sensor, wi: np.ndarray, level: np.ndarray):
        nodes, weights, cells = [], [], []
        for n in np.unique(level):
            chosen = np.flatnonzero(level == n)
            w, weight = sensor.cell_quadrature(int(n), int(n), chosen)
            nodes.append(w.reshape(-1, 3))
            weights.append(weight.reshape(-1))
            cells.append(np.repeat(chosen, w.shape[1]))
        self.nodes, self.weights, self.cells = np.concatenate(nodes), np.concatenate(weights), np.concatenate(cells)
        self.wi, self.n_cells = np.broadcast_to(wi, self.nodes.shape), sensor.n_cells

    def averages(self, model) -> np.ndarray:
        return np.bincount(self.cells, weights=model(self.wi, self.nodes) * self.weights, minlength=self.n_cells)


def compare(table, model, order: str = "all", on: str = "cells", **params) -> Comparison | PointComparison:
    """Compare ``model`` with ``table`` (a :class:`microsim.tables.Table`) on what ``on`` names, as
    :func:`microsim.analysis.fit.fit` takes it: "cells" (:func:`compare_cells`), "points"
    (:func:`compare_points`) or "retro" (:func:`compare_retro`, the retro rings); ValueError (one
    line) for another ``on``. ``model``: a model (``models.create(...)``), a registered model's
    name, a :class:`~microsim.models.BRDFModel` subclass or a plain function ``f(wi, wo, **params)``
    (:mod:`microsim.models.user_models`), made with ``params``."""
    if on not in COMPARE_ON:
        raise ValueError(f"on = {on!r}: accepted: {', '.join(map(repr, COMPARE_ON))}")
    return COMPARE_ON[on](table, model, order, **params)


def compare_cells(table, model, order: str = "all", **params) -> Comparison:
    """Average ``model`` over the cells of ``table`` and compare (module doc); ValueError (one
    line) if no cell has signal. ``model`` and ``params`` as :func:`compare` takes them."""
    from microsim.models import as_model

    model = as_model(model, **params)
    if getattr(model, "name", None) == "table":
        return compare_tables(table, model, order) if same_layout(table, model.table) else \
            compare_tabulated(table, model, order)
    names, sim, stderr, albedo_sim, albedo_se = selection(table, order)
    signal = signal_or_refusal(table, sim, stderr, order)
    modelled = np.zeros_like(sim)
    worst = 0.0
    for i, wi in enumerate(table.wi):
        modelled[i], change = cell_averages(model, table.sensor, wi, stderr[i])
        worst = max(worst, change)
    _require_finite(modelled, f"model {model!r}")
    p = table.projected_solid_angle
    scale = realization_scale(sim, stderr, albedo_sim, albedo_se, p, table.paths, realizations(table))
    return Comparison(model.name, dict(model.values), order, table.theta_i, table.phi_i, modelled, sim, stderr,
                      signal, modelled @ p, albedo_sim, albedo_se, worst,
                      *predicted_variance(modelled, sim, stderr, signal, p, scale),
                      albedo_common=(np.sqrt(scale) * albedo_sim)[:, None])


def same_layout(table, other) -> bool:
    """Whether two tables have the same sensor cells and the same incidences (to SAME_INCIDENCE)."""
    return (np.array_equal(table.sensor.ring_counts, other.sensor.ring_counts)
            and table.theta_i.shape == other.theta_i.shape
            and np.allclose(table.theta_i, other.theta_i, rtol=0, atol=SAME_INCIDENCE)
            and np.all(np.abs(np.mod(table.phi_i - other.phi_i + np.pi, 2 * np.pi) - np.pi) < SAME_INCIDENCE))


def compare_tables(table, tabulated, order: str = "all") -> Comparison:
    """Table against table, cell by cell (the tabulated model's table ``tabulated.table`` has
    ``table``'s cells and incidences): each cell's difference over the variance both tables would
    have if their BRDF were the mean of the two (:func:`table_noise.predicted_variance` of each,
    summed: chi-square per cell 1 expected, 0 for a table against itself), the errors of both in
    ``stderr`` and in the albedos'. The signal is ``table``'s; the orders compared, ``order`` of both."""
    other = tabulated.table
    _, sim, stderr, albedo_sim, albedo_se = selection(table, order)
    _, values, values_se, albedo_values, albedo_values_se = selection(other, order)
    signal = signal_or_refusal(table, sim, stderr, order)
    p = table.projected_solid_angle
    mean = 0.5 * (sim + values)
    both = ((table, sim, stderr, albedo_sim, albedo_se), (other, values, values_se, albedo_values, albedo_values_se))
    scales = [realization_scale(f, se, albedo, error, p, t.paths, realizations(t)) for t, f, se, albedo, error in both]
    variance, kurtosis, common = table_noise.independent_sum(
        *(predicted_variance(mean, f, se, with_signal(f, se), p, scale) for (_, f, se, _, _), scale in zip(both, scales)))
    return Comparison("table", dict(tabulated.values), order, table.theta_i, table.phi_i, values, sim,
                      np.hypot(stderr, values_se), signal, albedo_values, albedo_sim, np.hypot(albedo_se, albedo_values_se),
                      0.0, variance, kurtosis, common,
                      albedo_common=np.stack([np.sqrt(scale) * albedo for scale, (_, _, _, albedo, _) in zip(scales, both)],
                                             axis=1),
                      model_errors=f"both tables', cell by cell ({other.path} has {table.path}'s cells and incidences)",
                      warning=not_independent(table, other, np.array_equal(sim, values)))


def compare_tabulated(table, tabulated, order: str = "all") -> Comparison:
    """Table against a tabulated BRDF of other cells or incidences: the tabulated BRDF averaged
    over ``table``'s cells (a fixed rule, :data:`TABULATED_RULE` nodes a side: the interpolant is
    piecewise linear), its error propagated from its table's (microsim.models.tabulated) and added to
    ``table``'s. Only all orders: the tabulated BRDF is its table's brdf."""
    if order != "all":
        raise ValueError(f"--order {order} with --model table: the tabulated BRDF is its table's brdf, all orders; "
                         "cell by cell (the same sensor and incidences in both tables) compares any order")
    _, sim, stderr, albedo_sim, albedo_se = selection(table, order)
    signal = signal_or_refusal(table, sim, stderr, order)
    p = table.projected_solid_angle
    noise = [tabulated.cell_average_noise(CellRule(table.sensor, wi, np.full(table.sensor.n_cells, TABULATED_RULE)), p)
             for wi in table.wi]
    averaged, model_variance, common_b = (np.array([getattr(n, k) for n in noise]) for k in
                                          ("averages", "variance", "common"))
    scale = realization_scale(sim, stderr, albedo_sim, albedo_se, p, table.paths, realizations(table))
    modelled = (model_variance, np.zeros_like(sim), np.divide(common_b, model_variance, out=np.zeros_like(sim),
                                                              where=model_variance > 0))
    variance, kurtosis, common = table_noise.independent_sum(
        predicted_variance(averaged, sim, stderr, signal, p, scale), modelled)
    correlated = np.array([table_noise.correlated_pairs(n.covariance, variance[i], signal[i])
                           for i, n in enumerate(noise)])
    return Comparison("table", dict(tabulated.values), order, table.theta_i, table.phi_i, averaged, sim,
                      np.sqrt(stderr**2 + model_variance), signal, averaged @ p, albedo_sim,
                      np.sqrt(albedo_se**2 + np.array([n.albedo_variance for n in noise])), 0.0, variance,
                      kurtosis, common, correlated=correlated,
                      albedo_common=np.stack([np.sqrt(scale) * albedo_sim, [n.albedo_common for n in noise]], axis=1),
                      model_errors=f"both: {tabulated.table.path} interpolated to {table.path}'s cells and incidences, "
                                   "its errors propagated (microsim.models.tabulated)",
                      warning=not_independent(table, tabulated.table))


def not_independent(table, other, same_values: bool = False) -> str | None:
    """Why two tables' errors are not independent, as compare's bounds assume, or None: the same
    values (a table against itself), or the same seed (the same realizations of the geometry, and
    the same random numbers at incidences of the same index)."""
    if same_values:
        return (f"{other.path} holds {table.path}'s values: chi^2 and albedo z^2 are 0 by construction, "
                "and the bounds, made for independent tables, do not apply")
    seed = table.attrs.get("seed")
    if seed is not None and seed == other.attrs.get("seed"):
        return (f"both tables were traced with seed {seed}: they share realizations of the geometry and random "
                "numbers, so their errors are correlated and the bounds, made for independent tables, do not "
                "hold; trace one with another --seed")
    return None


def compare_points(table, model, order: str = "all", **params) -> PointComparison:
    """``model`` at the table's points against next-event estimation's f there (module doc),
    arguments as :func:`compare`'s; ValueError (one line) for a table without points, an order
    they do not hold, or no point to compare."""
    from microsim.models import as_model

    model = as_model(model, **params)
    _refuse_tabulated(model, "--points")
    sim, stderr = extra_selection(table, order, "points")
    directions = table.arrays["sensor/points_direction"]
    modelled = np.stack([model(np.broadcast_to(wi, d.shape), d) for wi, d in zip(table.wi, directions)])
    _require_finite(modelled, f"model {model!r}", "points")
    size = np.maximum(np.abs(sim), np.abs(modelled))
    judged = (size > 0) & ~repeated_points(directions)
    if not judged.any():
        raise ValueError(f"--points: table {table.path}: the model and the table are 0 at every point of order "
                         f"{order}: nothing to compare")
    exact = judged & (stderr <= EXACT_POINT * size)
    error = np.where(exact, EXACT_POINT * size, stderr)
    z = np.divide(sim - modelled, error, out=np.zeros_like(sim), where=judged)
    count = realizations(table)
    noisy = judged & ~exact
    terms = np.where(noisy, normal_squares(z, count), 0.0)
    covariance = points_covariance(table, order)
    # with the covariance, Hotelling's test of each incidence; without, the bounds of one error
    # common to every point (module doc)
    tests = None if covariance is None else [
        hotelling((sim - modelled)[i, n], covariance[i][np.ix_(n, n)], count, sim[i, n],
                  EXACT_POINT * float(np.linalg.norm(size[i, n]))) if n.any() else None
        for i, n in enumerate(noisy)]
    return PointComparison(model.name, dict(model.values), order, "points", table.theta_i, table.phi_i, modelled,
                           sim, stderr, judged, exact, z, terms, np.zeros_like(sim), np.ones_like(sim), 0.0,
                           {"points_delta_lobes": str(table.attrs.get("points_delta_lobes", ""))}, tests,
                           count)


def compare_retro(table, model, order: str = "all", **params) -> PointComparison:
    """``model`` averaged over the table's retro rings against ``brdf_retro`` (module doc),
    arguments as :func:`compare`'s; ValueError (one line) for a table without rings, an order
    they do not hold, or no ring with signal."""
    from microsim.models import as_model

    model = as_model(model, **params)
    _refuse_tabulated(model, "--retro")
    sim, stderr = extra_selection(table, order, "retro")
    sensor = retro_sensor(table)
    projected = table.arrays["sensor/retro_projected_solid_angle"]
    modelled = np.zeros_like(sim)
    worst = 0.0
    for i, wi in enumerate(table.wi):
        modelled[i], change, _ = ring_averages(model, sensor, wi, stderr[i])
        worst = max(worst, change)
    _require_finite(modelled, f"model {model!r}", "retro rings")
    _, cells, cells_stderr, albedo, albedo_stderr = selection(table, order)
    p = table.projected_solid_angle
    scale = realization_scale(cells, cells_stderr, albedo, albedo_stderr, p, table.paths, realizations(table))
    variance, kurtosis, common = predicted_variance(modelled, cells, cells_stderr, with_signal(cells, cells_stderr),
                                                    p, scale, at=projected)
    # a ring the horizon cuts entirely has no value and no variance; nor has one of an incidence
    # without a cell of signal, whose paths' dispersion is unknown
    judged = with_signal(sim, stderr) & (variance > 0)
    if not judged.any():
        raise ValueError(f"--retro: table {table.path}: no retro ring of order {order} has signal (a value above "
                         f"{SIGNAL_TO_NOISE:g} standard errors): nothing to compare; trace more paths or use fewer "
                         "rings")
    zeros = np.zeros_like(sim)
    z = np.divide(sim - modelled, stderr, out=zeros.copy(), where=judged)
    terms = np.divide((modelled - sim) ** 2, variance, out=zeros.copy(), where=judged)
    return PointComparison(model.name, dict(model.values), order, "retro", table.theta_i, table.phi_i, modelled,
                           sim, stderr, judged, np.zeros_like(judged), z, terms, kurtosis, common, worst, {})


#: what compares a model with a table, by what it compares on
COMPARE_ON = {"cells": compare_cells, "points": compare_points, "retro": compare_retro}


def ring_averages(model, sensor, wi: np.ndarray, stderr: np.ndarray, tolerance: float = QUADRATURE_TOLERANCE):
    """``model`` averaged over every retro ring of ``sensor`` about wi, cos-weighted (n x 4 n
    nodes a ring, n of RING_RULES), refined until no ring moves by more than ``tolerance`` of
    its standard error (a ring without one: ALBEDO_TOLERANCE of its value). Returns the
    averages, the largest last change in standard errors and the n settled on (which
    :class:`RingRule` can hold fixed)."""
    previous, change = None, np.zeros(len(stderr))
    for n in RING_RULES:
        averages = RingRule(sensor, wi, n).averages(model)
        if previous is not None:
            floor = np.where(stderr > 0, stderr, ALBEDO_TOLERANCE * np.abs(averages) / tolerance)
            change = np.divide(np.abs(averages - previous), floor, out=np.zeros_like(floor), where=floor > 0)
            if change.max(initial=0.0) <= tolerance:
                break
        previous = averages
    return averages, float(change.max(initial=0.0)), n


class RingRule:
    """A fixed quadrature of every retro ring about wi, n x 4 n nodes a ring, as
    :class:`CellRule` is of the cells."""

    def __init__(self, sensor, wi: np.ndarray, n: int):
        self.nodes, self.weights = sensor.retro_ring_quadrature(wi, n, 4 * n)
        self.wi = np.broadcast_to(wi, self.nodes.shape)

    def averages(self, model) -> np.ndarray:
        return np.sum(model(self.wi, self.nodes) * self.weights, axis=1)


def retro_sensor(table):
    """The table's sensor with its retro rings, rebuilt from their bounds (uniform in the chord
    2 sin(gamma / 2) out to the last ring's gamma_hi) and checked against them (ValueError)."""
    lo, hi = table.arrays["sensor/retro_gamma_lo"], table.arrays["sensor/retro_gamma_hi"]
    sensor = table.sensor.with_retro_rings(len(lo), math.degrees(hi[-1]))
    if not all(np.allclose(mine, stored, rtol=0.0, atol=1e-9)
               for mine, stored in zip(sensor.retro_phase_bounds(), (lo, hi))):
        raise ValueError(f"--retro: table {table.path}: its rings (sensor/retro_gamma_lo, sensor/retro_gamma_hi) are "
                         "not uniform in the chord 2 sin(gamma / 2), as microsim writes them")
    return sensor


def albedo_bound(correlation: np.ndarray) -> float:
    """Upper CHI2_OUTSIDE / 2 bound of the mean albedo z^2 over incidences whose z have this
    ``correlation`` (n x n) for an exact model: a sum of chi-squares of one degree of freedom
    weighted by its eigenvalues, taken as the gamma distribution of mean 1 and variance
    2 sum(rho^2) / n^2 (exact for independent incidences: chi-square of n degrees of freedom over n)."""
    from scipy.stats import gamma

    n = correlation.shape[0]
    variance = 2.0 * float(np.sum(correlation**2)) / n**2
    return float(gamma.ppf(1 - CHI2_OUTSIDE / 2, 1.0 / variance, scale=variance))


def _refuse_tabulated(model, flag: str) -> None:
    """ValueError (one line) for a tabulated model where its errors are not propagated."""
    if getattr(model, "name", None) == "table":
        raise ValueError(f"{flag} with --model table: the tabulated BRDF's errors are propagated to cells only "
                         "(compare the cells, or the two tables' points as tables of their own)")


def signal_or_refusal(table, sim, stderr, order: str) -> np.ndarray:
    """:func:`with_signal` of the table's ``order``; ValueError (one line) if no cell has signal."""
    signal = with_signal(sim, stderr)
    if not signal.any():
        raise ValueError(f"table {table.path}: no cell of order {order} has signal (a value above "
                         f"{SIGNAL_TO_NOISE:g} standard errors): nothing to compare; trace more paths or use fewer cells")
    return signal


def with_signal(sim, stderr) -> np.ndarray:
    """The cells where the table has signal: value above SIGNAL_TO_NOISE standard errors."""
    return (stderr > 0) & (sim > SIGNAL_TO_NOISE * stderr)


def selection(table, order: str):
    """(dataset names, f_C, its standard error, albedo, its standard error) of the table's
    ``order`` (a key of ORDER_ROWS), checked present and finite (ValueError, one line)."""
    if order not in ORDER_ROWS:
        raise ValueError(f"order {order!r}; accepted: {', '.join(ORDER_ROWS)}")
    row = ORDER_ROWS[order]
    if row == BASE and not {"brdf_order1_base", "albedo_order1_base"} <= table.arrays.keys():
        raise ValueError(f"--order 1-base: table {table.path} has no brdf_order1_base and albedo_order1_base "
                         "(its scene has no base, or it was written before they existed)")
    if row == ORDERS12 and not {"brdf_orders12", "albedo_orders12"} <= table.arrays.keys():
        raise ValueError(f"--order 1+2: table {table.path} has no brdf_orders12 and albedo_orders12 "
                         "(it was written before they existed)")
    selected = _selected(table, row)
    for name, values in zip(selected[0], selected[1:3]):
        _require_finite(values, f"table {table.path}: {name} (order {order})")
    return selected


def extra_selection(table, order: str, on: str):
    """(f, its standard error) of the table's points (``on`` = "points") or retro rings
    ("retro") of ``order``, each (n_i, n), checked present and finite (ValueError, one line)."""
    if order not in ORDER_ROWS:
        raise ValueError(f"order {order!r}; accepted: {', '.join(ORDER_ROWS)}")
    _, name, _, config = ON[on]
    row = ORDER_ROWS[order]
    if row == ORDERS12:
        raise ValueError(f"--order 1+2 with --{on}: the table holds its {name} by order but not the covariance of "
                         "orders 1 and 2, which the error of their sum needs; compare --order 1 and --order 2 apart")
    if row == BASE:
        raise ValueError(f"--order 1-base with --{on}: the table holds no base part of order 1 in {name}")
    dataset = name if row is None else f"{name}_order"
    geometry = ("sensor/points_direction",) if on == "points" else \
        ("sensor/retro_gamma_lo", "sensor/retro_gamma_hi", "sensor/retro_projected_solid_angle")
    missing = [k for k in (dataset, f"{dataset}_stderr", *geometry) if k not in table.arrays]
    if missing:
        raise ValueError(f"--{on}: table {table.path} has no {', '.join(missing)} (its config has no {config}, or it "
                         "was written before they existed)")
    names = (dataset, f"{dataset}_stderr")
    values, stderr = (table.arrays[k] if row is None else table.arrays[k][:, row] for k in names)
    for k, v in zip(names, (values, stderr)):
        _require_finite(v, f"table {table.path}: {k} (order {order})", ON[on][0] + "s")
    return values, stderr


def points_covariance(table, order: str) -> np.ndarray | None:
    """(n_i, n_d, n_d) the covariance of the mean of the table's points of ``order`` (checked
    by :func:`extra_selection`), brdf_points_covariance or a row of brdf_points_order_covariance;
    None for a table without it (written before it existed). ValueError (one line) if not finite."""
    row = ORDER_ROWS[order]
    name = "brdf_points_covariance" if row is None else "brdf_points_order_covariance"
    if name not in table.arrays:
        return None
    covariance = table.arrays[name] if row is None else table.arrays[name][:, row]
    _require_finite(covariance, f"table {table.path}: {name} (order {order})", "entries")
    return covariance


def repeated_points(directions: np.ndarray) -> np.ndarray:
    """(n_i, n_d) True where a point's direction (n_i, n_d, 3) is an earlier point's of its
    incidence (normal incidence: the retro point at gamma = 0 is the direction [0, 0]): the same
    estimate, compared once."""
    gap = np.linalg.norm(directions[:, :, None] - directions[:, None, :], axis=-1)
    earlier = np.tril(np.ones(gap.shape[1:], bool), -1)
    return np.any((gap < 1e-12) & earlier, axis=2)


def _selected(table, row):
    """(dataset names, f_C, its standard error, albedo, its standard error) of an ORDER_ROWS row."""
    a = table.arrays
    if row is None:
        return ("brdf", "brdf_stderr"), table.brdf, table.brdf_stderr, table.albedo, table.albedo_stderr
    if row in (BASE, ORDERS12):
        name = "order1_base" if row == BASE else "orders12"
        return ((f"brdf_{name}", f"brdf_{name}_stderr"), a[f"brdf_{name}"], a[f"brdf_{name}_stderr"],
                a[f"albedo_{name}"], a[f"albedo_{name}_stderr"])
    return (("brdf_order", "brdf_order_stderr"), table.brdf_order[:, row, :], a["brdf_order_stderr"][:, row, :],
            a["albedo_order"][:, row], a["albedo_order_stderr"][:, row])


def _degrees(radians: float) -> float:
    """Degrees as a config gives them: 30.0, not the 29.999999999999996 of a round trip."""
    return round(float(np.degrees(radians)), 9)


def _require_finite(values: np.ndarray, what: str, unit: str = "cells") -> None:
    """Raise ValueError naming ``what`` if any cell (or other ``unit``) is NaN or infinite."""
    if bad := np.count_nonzero(~np.isfinite(values)):
        raise ValueError(f"{what} is NaN or infinite in {bad} of {values.size} {unit}")
