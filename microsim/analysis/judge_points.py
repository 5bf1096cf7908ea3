"""The judge of the points (``compare --points``, ``fit --points``; :mod:`microsim.tracer.estimators.points`).

Compared (:func:`compare_points`): next-event estimation's f at the exact directions
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

A table of format 1.0 without the covariance (written before it existed) keeps the bounds of chi-square of
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

Fitted (:func:`fitted_points`): next-event estimation's f at the table's points (nothing predicts a point's
variance; an exact point, without spread, is weighed by ``EXACT_POINT`` of its value; a
point where the table holds 0 without spread is left out): the weights are fixed, and one solve
ends the fit. The points of an incidence share their paths. Where the table holds the covariance
C of their mean (``brdf_points_covariance``, from R realizations), the fit is generalized least
squares: each incidence's points with spread are projected on the k eigen-directions of C that
``compare`` keeps for Hotelling's test (above its rounding, :func:`table_noise.eigenbasis`) and
weighed by c / eigenvalue (weights c C^+), and the parameters' covariance is Gauss-Newton's,
(J^T W J)^-1. C is estimated: for normal realizations the fit's true covariance is (m - 1) /
(m - 1 - k + p) times that of a known C (m = R - 1, p parameters) while (J^T C^+ J)^-1 is (m - k
+ p) / m of it in expectation (both checked on a normal simulation to 1 %), so with c = 1 the
errors would run low. c = (m - k + p)(m - 1 - k + p) / (m (m - 1)) (:func:`estimated_weights`)
gives errors as calibrated as a normal simulation's (figures: docs/validation/statistics.md,
'Fits at points'). Chi-square is the sum of the incidences' T^2 at the best fit, over
sum k less the free parameters; each T^2 has mean k (R - 1) / (R - k - 2) for an exact model,
so chi-square per degree of freedom near (R - 1) / (R - k - 2) is a good fit (1.9 at R = 16, k =
6). An incidence with as many points with spread as realizations or more (C of rank R - 1 at
most), or too many for c > 0, and a table of format 1.0 without the covariance (written before it existed),
take the bounding fit instead: each point weighed by its own standard error, and a parameter's
standard error the bound that holds whatever the points' correlation, sum_j |a_j| s_j for the
parameter's row a of the least-squares solution and the points' errors s (for independent points
sqrt(sum_j a_j^2 s_j^2), up to sqrt(n) times smaller), with degrees of freedom the points less
the free parameters and chi-square per degree of freedom counting z^2, each of mean (R - 1) /
(R - 3) for an exact model. The key ``fit_points_weights`` says which ("covariance" or
"bounding", with ``fit_points_weights_note``); the covariance's errors are far smaller than the
bound's (docs/validation/statistics.md, 'Fits at points'). The best model is compared as
``compare`` compares on the same.
"""

from __future__ import annotations

import numpy as np

from microsim.analysis.fitted import Fitted
from microsim.analysis.judges import Judge
from microsim.analysis.point_comparison import EXACT_POINT, PointComparison, judged_values
from microsim.analysis.selection import ORDER_ROWS, extra_selection, predates, require_finite
from microsim.core import table_noise
from microsim.core.table_noise import CHI2_OUTSIDE, chi2_1dof_p, hotelling, normal_squares, realizations


class PointsComparison(PointComparison):
    """Model and simulation at a table's points (module doc)."""

    unit, counted = "point", "points_compared"

    @property
    def statistic(self) -> str | None:
        """What judges the points: "hotelling" (the table holds their covariance), "chi2_1dof", or
        "exact" (no point has spread: each must equal the model to EXACT_POINT)."""
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

    def more_metrics(self, i, exact, judged_any, agree) -> dict:
        out = {"points_without_spread": int(exact.sum()), "points_statistic": self.statistic}
        if self.hotelling is not None and judged_any:
            out.update(self._hotelling_metrics(i, agree))
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

    def rules(self) -> dict:
        if self.hotelling is not None:
            return {
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
        return {
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

    def summary(self) -> str:
        level = f"{100 * (1 - CHI2_OUTSIDE):g} % two-sided"
        if self.hotelling is not None:
            return ("points: the model at each exact direction (next-event estimation); per incidence Hotelling's F "
                    f"of the points with the covariance of their errors, {level} bounds (an incidence with too few "
                    "realizations: chi^2 per point, bounds of 1 degree of freedom); overall: every incidence at the "
                    "Bonferroni level")
        return ("points: the model at each exact direction (next-event estimation), every point but where both are "
                f"0; exact points (no spread) must match to {EXACT_POINT:g}; chi^2 per point: 1 "
                "expected for the model of the table, bounds of 1 degree of freedom (the table holds no covariance "
                f"of the points' errors), {level}")


def compare_points(table, model, order: str = "all", **params) -> PointComparison:
    """``model`` at the table's points against next-event estimation's f there (module doc),
    arguments as :func:`compare`'s; ValueError (one line) for a table without points, an order
    they do not hold, or no point to compare."""
    model, sim, stderr = judged_values(table, model, order, POINTS, params)
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
    return PointsComparison(model.name, dict(model.values), order, "points", table.theta_i, table.phi_i, modelled,
                           sim, stderr, judged, exact, z, terms, np.zeros_like(sim), np.ones_like(sim), 0.0,
                           {"points_delta_lobes": str(table.attrs.get("points_delta_lobes", ""))}, tests,
                           count)


def points_covariance(table, order: str) -> np.ndarray | None:
    """(n_i, n_d, n_d) the covariance of the mean of the table's points of ``order`` (checked
    by :func:`microsim.analysis.selection.extra_selection`), brdf_points_covariance or a row of
    brdf_points_order_covariance; None for a table of a format before it existed. ValueError
    (one line) if not finite, or missing from a table of a format that holds it."""
    row = ORDER_ROWS[order]
    name = "brdf_points_covariance" if row is None else "brdf_points_order_covariance"
    if name not in table.arrays:
        if predates(table, name):
            return None
        raise ValueError(f"--points: table {table.path} has no {name}, which a table of format "
                         f"{table.format_version} holds with its points: it is damaged")
    covariance = table.arrays[name] if row is None else table.arrays[name][:, row]
    require_finite(covariance, f"table {table.path}: {name} (order {order})", "entries")
    return covariance


def repeated_points(directions: np.ndarray) -> np.ndarray:
    """(n_i, n_d) True where a point's direction (n_i, n_d, 3) is an earlier point's of its
    incidence (normal incidence: the retro point at gamma = 0 is the direction [0, 0]): the same
    estimate, compared once."""
    gap = np.linalg.norm(directions[:, :, None] - directions[:, None, :], axis=-1)
    earlier = np.tril(np.ones(gap.shape[1:], bool), -1)
    return np.any((gap < 1e-12) & earlier, axis=2)


def fitted_points(table, first, order: str, n_free: int) -> Fitted:
    """The points to fit (module doc); ``first`` is not needed (no quadrature)."""
    sim, stderr = extra_selection(table, order, POINTS)
    directions = table.arrays["sensor/points_direction"]
    error = np.maximum(stderr, EXACT_POINT * np.abs(sim))
    fitted = (error > 0) & ~repeated_points(directions)
    if fitted.sum() <= n_free:
        raise ValueError(f"--points: table {table.path}: {int(fitted.sum())} points with a value, too few to fit "
                         f"{n_free} parameters")
    incidence = np.nonzero(fitted)[0]
    wi, wo = table.wi[incidence], directions[fitted]
    whiten, counted, notes = _whitening(table, order, sim, stderr, fitted, n_free)
    return Fitted(sim[fitted], error[fitted], incidence, lambda model: model(wi, wo), whiten=whiten,
                   counted=counted, notes=notes)


def _whitening(table, order, sim, stderr, fitted, n_free):
    """(whiten, counted, notes) of the points ``fitted`` (module doc): with the table's covariance
    of its points, each incidence's points with spread projected on the kept eigen-directions of
    their covariance and scaled by sqrt(c / eigenvalue) (weights c C^+, generalized least squares;
    c :func:`estimated_weights`), each exact point by 1 / (EXACT_POINT of its value);
    ``counted``: c on the incidences' rows, 0 on the exact points'. (None, None, notes) without the
    covariance, or where an incidence has as many points with spread as realizations or more, or
    too many for the estimated weights (c <= 0)."""
    covariance = points_covariance(table, order)
    realizations = table_noise.realizations(table)
    bounding = ("each point weighed by its own standard error; parameter errors that hold whatever the "
                "correlation")
    if covariance is None:
        return None, None, {"fit_points_weights": "bounding", "fit_points_weights_note": "the table holds no "
                            f"brdf_points_covariance: {bounding}"}
    noisy = fitted & (stderr > EXACT_POINT * np.abs(sim))
    column = np.full(sim.shape, -1)
    column[fitted] = np.arange(int(fitted.sum()))
    rows, counted = [], []
    for i in range(len(sim)):
        if noisy[i].sum() >= realizations:
            return None, None, {"fit_points_weights": "bounding", "fit_points_weights_note": f"incidence {i} has "
                                f"{int(noisy[i].sum())} points with spread, as many as the {realizations} "
                                f"realizations or more (a covariance of rank R - 1 at most): {bounding}"}
        if noisy[i].any():
            spread, axes, kept = table_noise.eigenbasis(covariance[i][np.ix_(noisy[i], noisy[i])],
                                                        table_noise.covariance_rounding(sim[i, noisy[i]], realizations))
            k = int(kept.sum())
            c = estimated_weights(k, min(n_free, k), realizations)
            if c <= 0:
                return None, None, {"fit_points_weights": "bounding", "fit_points_weights_note": f"incidence {i}: "
                                    f"{k} directions with spread and {realizations} realizations, too few for "
                                    f"weights from their covariance (R - 3 - k + parameters <= 0): {bounding}"}
            block = np.zeros((k, int(fitted.sum())))
            block[:, column[i, noisy[i]]] = (axes[:, kept] * np.sqrt(c / spread[kept])).T
            rows.append(block)
            counted += [c] * k
        for j in np.flatnonzero(fitted[i] & ~noisy[i]):
            row = np.zeros((1, int(fitted.sum())))
            row[0, column[i, j]] = 1.0 / (EXACT_POINT * abs(sim[i, j]))
            rows.append(row)
            counted.append(0.0)
    return np.concatenate(rows), np.array(counted), {"fit_points_weights": "covariance"}


def estimated_weights(k: int, p: int, realizations: int) -> float:
    """c, the factor on the weights C^+ of an incidence's k directions (module doc) for p
    parameters, C estimated from R realizations (m = R - 1 degrees of freedom): (m - k + p)
    (m - 1 - k + p) / (m (m - 1)). For normal realizations (C then a Wishart matrix over m,
    independent of the mean), (J^T C^+ J)^-1 has expectation (m - k + p) / m of the parameters'
    covariance that C would give if known, and the estimated weights make the fit's own
    covariance (m - 1) / (m - 1 - k + p) times that (as in the growth-curve model): c makes the
    Gauss-Newton covariance of one incidence right in expectation, and weighs incidences by how
    well their covariance is known. 0 or less: too few realizations."""
    m = realizations - 1
    return (m - k + p) * (m - 1 - k + p) / (m * (m - 1)) if m > 1 else 0.0



POINTS = Judge(
    on="points", unit="point", dataset="brdf_points", counted="points_compared",
    keys="[sensor] directions_deg or retro_points_deg", geometry=("sensor/points_direction",),
    help="instead of the cells, the table's points (sensor.directions_deg, sensor.retro_points_deg): the model at "
         "each exact direction against brdf_points (next-event estimation), nothing averaged; no albedo",
    compare=compare_points, fitted=fitted_points)
