"""Model versus table at exact directions and on the retro rings (``compare --points``, ``--retro``;
docs/conventions.md §7).

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
reject an exact model far more often than 1 % of the time (docs/validation/statistics.md,
'Points').

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
takes the bounds below instead, at the same level. Hotelling's test sees a model off by less
than chi-square per point can (its power: docs/validation/statistics.md, 'Points').

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

from microsim.analysis.averages import ring_averages
from microsim.analysis.selection import (
    ON,
    SIGNAL_TO_NOISE,
    config_degrees,
    extra_selection,
    points_covariance,
    repeated_points,
    require_finite,
    selection,
    with_signal,
)
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

#: a point whose standard error is under this fraction of its value has no spread (every path adds
#: the same, as on a Lambertian plane): the model must equal it to this fraction
EXACT_POINT = 1e-9


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
            out = {"theta_i_deg": config_degrees(self.theta_i[i]), "phi_i_deg": config_degrees(self.phi_i[i]), **out}
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
    require_finite(modelled, f"model {model!r}", "points")
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
    require_finite(modelled, f"model {model!r}", "retro rings")
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


def _refuse_tabulated(model, flag: str) -> None:
    """ValueError (one line) for a tabulated model where its errors are not propagated."""
    if getattr(model, "name", None) == "table":
        raise ValueError(f"{flag} with --model table: the tabulated BRDF's errors are propagated to cells only "
                         "(compare the cells, or the two tables' points as tables of their own)")
