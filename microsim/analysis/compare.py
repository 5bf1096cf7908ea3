"""Model versus table, cell by cell (docs/conventions.md §2 and §7).

Chi-square per cell, and whether the model is consistent with the table: each cell's squared
difference over the variance it would have if the model were the table's BRDF (the paths' and
the realizations' share, :mod:`microsim.core.table_noise`), not over its own estimated error, which
runs high at few paths a cell. 1 is expected, within two-sided CHI2_OUTSIDE bounds. The model
is "consistent" with the table when chi-square lies within them and the albedo's z^2 (over the
incidences) under its upper bound; above, it is not the table's BRDF; below, the table's errors
are too large.

The model is averaged over each cell as the table is (:mod:`microsim.analysis.averages`), over
the cells with signal (:mod:`microsim.analysis.selection`). :func:`compare` dispatches on what
a comparison is on to the estimators' judges (:mod:`microsim.analysis.judges`): the cells'
(:data:`CELLS`) here, the points' and the retro rings' in :mod:`microsim.analysis.judge_points` and
:mod:`microsim.analysis.judge_retro`; a table against another table, or against a tabulated BRDF
of other cells, is compared cell by cell too.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from microsim.analysis import judges
from microsim.analysis.averages import ALBEDO_TOLERANCE, CellRule, cell_averages
from microsim.analysis.fitted import fitted_cells
from microsim.analysis.judges import DEFAULT_ON, Judge
from microsim.analysis.selection import (
    SIGNAL_TO_NOISE,
    config_degrees,
    require_finite,
    selection,
    signal_or_refusal,
    with_signal,
)
from microsim.core import table_noise
from microsim.core.table_noise import CHI2_OUTSIDE, chi2_bounds, predicted_variance, realization_scale, realizations

#: incidences of two tables within this (radians) are the same: their cells are compared one by one
SAME_INCIDENCE = 1e-9
#: the Gauss rule (nodes a side) averaging a tabulated BRDF over a cell of another table
TABULATED_RULE = 16


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
            out = {"theta_i_deg": config_degrees(self.theta_i[i]), "phi_i_deg": config_degrees(self.phi_i[i]),
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


def compare(table, model, order: str = "all", on: str = DEFAULT_ON, **params):
    """Compare ``model`` with ``table`` (a :class:`microsim.tables.Table`) on what ``on`` names, as
    :func:`microsim.analysis.fit.fit` takes it: "cells" (:func:`compare_cells`) or the word of
    another estimator's judge (:mod:`microsim.analysis.judges`: "points", "retro"); ValueError (one
    line) for another ``on``. ``model``: a model (``models.create(...)``), a registered model's
    name, a :class:`~microsim.models.BRDFModel` subclass or a plain function ``f(wi, wo, **params)``
    (:mod:`microsim.models.user_models`), made with ``params``."""
    return judges.judge(on).compare(table, model, order, **params)


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
    require_finite(modelled, f"model {model!r}")
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


#: the judge of the cells (microsim.analysis.judges), the exit binning's
CELLS = Judge(on=DEFAULT_ON, unit="cell", dataset="brdf", counted="cells_with_signal", keys="[sensor] cells",
              geometry=(), help="", compare=compare_cells, fitted=fitted_cells)


def albedo_bound(correlation: np.ndarray) -> float:
    """Upper CHI2_OUTSIDE / 2 bound of the mean albedo z^2 over incidences whose z have this
    ``correlation`` (n x n) for an exact model: a sum of chi-squares of one degree of freedom
    weighted by its eigenvalues, taken as the gamma distribution of mean 1 and variance
    2 sum(rho^2) / n^2 (exact for independent incidences: chi-square of n degrees of freedom over n)."""
    from scipy.stats import gamma

    n = correlation.shape[0]
    variance = 2.0 * float(np.sum(correlation**2)) / n**2
    return float(gamma.ppf(1 - CHI2_OUTSIDE / 2, 1.0 / variance, scale=variance))
