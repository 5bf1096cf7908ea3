"""Model parameters fitted to a table (docs/conventions.md §7, ``microsim fit``): least squares on
cell averages, weighted by variances predicted from the model (quasi-likelihood, iterated).

Weighting each cell by its own estimated standard error (Neyman's chi-square) biases a fit:
a cell's error is estimated from the same paths as its value, and a cell that fluctuated low
also gets a small error and a large weight (a bias that grows as the paths per cell fall).
Instead, the variance of cell C is taken from the model, v_C = k m_C / P_C, with m_C the
model's cell average, P_C the cell's projected solid angle and k the incidence's dispersion of
its paths (:func:`table_noise.variance_model`). Weights are held fixed while the parameters move,
then recomputed from the best model, until no parameter moves by more than ``CONVERGED`` of its
standard error: the fitted parameters solve sum_C (m_C - f_C) dm_C/dx / v_C = 0, whose
expectation at the true parameters is zero whatever the noise (where the weights of a cell's
paths vary from cell to cell, v_C is only near the truth: the fit stays unbiased, a little less
efficient).

The standard errors are those of the sandwich (J^T W J)^-1 J^T W Cov W J (J^T W J)^-1, W the
weights, with the cells' covariance Cov that the table implies: the cells of an incidence share
its paths (a path exits into one cell, so they are anticorrelated) and, in a random scene, its
realizations (:func:`table_noise.path_covariance`, :func:`table_noise.realization_scale`). Taking
the cells as independent overstates the error of what sums many cells: the albedo of a Lambertian
plane is fixed by the energy its paths carry out, each exactly 0.5, and its fit is exact, where
independent cells would give it an error.

Every cell is fitted, the model averaged over each cell as ``compare`` does: with variances from
the model, a cell's residual needs no error of its own, and choosing the cells by their own
value biases the fit, as weighing them by their own error does: fitting only the cells with
signal (table > ``selection.SIGNAL_TO_NOISE`` standard errors, as compare reports them) biases the
fit high, since near the threshold the cells kept are those that fluctuated up. The cells with
signal only pool the paths' dispersion k (a ratio of sums), and an incidence without any is left
out. The quadrature each cell needs is found once, at the starting
parameters (``averages.refined_cell_averages``), and held fixed while the parameters move
(``averages.CellRule``), so the residuals are smooth in them. Its tolerance is compare's
(``QUADRATURE_TOLERANCE`` standard errors a cell) divided by the square root of the N cells
fitted: quadrature errors can share their sign over many cells, and N cells each off by t
standard errors in the same direction would move a fitted scale by about t sqrt(N) of its
standard errors. scipy's trust-region reflective least squares keeps the parameters inside their
declared ranges (open ends by 1e-9 of the range). The chi-square per degree of freedom says
whether the model describes the table: near 1 if it does, far above 1 if not, and the fit
reports it whatever it is. Its degrees of freedom are the cells' expected shares of chi-square,
less the free parameters: a cell whose model value m_C lies under the variance floor adds m_C /
floor in expectation, not 1 (sum_C min(1, m_C / floor) - parameters; a dark cell counted whole
would sink an exact model's chi-square per degree of freedom far below 1). The best model is
then compared with the table exactly as ``compare`` does.

(measurements of the weights, covariance and choice of cells tried: docs/developer/performance.md,
section 'Fits and chi-square: weights, covariance and cells')

``on="retro"`` (``--retro``) fits the retro rings instead, as the cells: a ring is a bin that the
paths exit into, weighed by the variance the model predicts from the cells' dispersion (the same
paths), every ring above the horizon of the incidences whose cells have signal, each averaged by
a rule found at the starting parameters and held fixed (``averages.RingRule``). ``on="points"``
(``--points``) fits next-event estimation's f at the table's points (nothing predicts a point's
variance; an exact point, without spread, is weighed by ``compare_points.EXACT_POINT`` of its value; a
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
most), or too many for c > 0, and a table without the covariance (written before it existed),
take the bounding fit instead: each point weighed by its own standard error, and a parameter's
standard error the bound that holds whatever the points' correlation, sum_j |a_j| s_j for the
parameter's row a of the least-squares solution and the points' errors s (for independent points
sqrt(sum_j a_j^2 s_j^2), up to sqrt(n) times smaller), with degrees of freedom the points less
the free parameters and chi-square per degree of freedom counting z^2, each of mean (R - 1) /
(R - 3) for an exact model. The key ``fit_points_weights`` says which ("covariance" or
"bounding", with ``fit_points_weights_note``); the covariance's errors are far smaller than the
bound's (docs/validation/statistics.md, 'Fits at points'). The best model is compared as
``compare`` compares on the same."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from microsim import models
from microsim.analysis import compare
from microsim.analysis.averages import QUADRATURE_TOLERANCE, CellRule, RingRule, refined_cell_averages, ring_averages
from microsim.analysis.compare_points import EXACT_POINT, PointComparison, retro_sensor
from microsim.analysis.selection import extra_selection, points_covariance, repeated_points, selection, with_signal
from microsim.core import table_noise

#: open ends of a parameter's range are kept this fraction of the range (or absolutely) inside
OPEN_END = 1e-9
#: the weights are recomputed until no parameter moves by more than this many standard errors
CONVERGED = 1e-3
#: and at most this many times
REWEIGHTS = 20


@dataclass
class Fit:
    """Best parameters and their standard errors, chi-square per degree of freedom, and the
    comparison of the best model with the table."""

    free: dict  # name -> (value, standard error)
    chi2_per_dof: float | None  # None without degrees of freedom
    dof: float  # the cells' (rings') expected share of chi-square or the points, less the free parameters (>= 0)
    evaluations: int
    comparison: compare.Comparison | PointComparison
    notes: dict = field(default_factory=dict)  # keys added to as_dict (how the points were weighed)

    def as_dict(self) -> dict:
        """The ``compare`` JSON with the key ``fit`` added."""
        out = self.comparison.as_dict()
        out["fit"] = {name: {"value": v, "stderr": e} for name, (v, e) in self.free.items()}
        out["fit_chi2_per_dof"] = self.chi2_per_dof
        out["fit_dof"] = self.dof
        out.update(self.notes)
        return out


def fit(table, model, free: list[str], fixed: dict | None = None, order: str = "all", progress=None,
        on: str = "cells") -> Fit:
    """Fit the ``free`` parameters of ``model`` to ``table``; ``fixed`` holds the other
    parameters, and starting values for free ones. ``model``: a registered model's name, a
    :class:`~microsim.models.BRDFModel` subclass or a plain function ``f(wi, wo, **params)``
    (:mod:`microsim.models.user_models`). ``progress(evaluations, values)``, if given, is called
    after every evaluation of the model over the table's cells (``values``: the free parameters
    evaluated). ``on``: what is fitted, "cells", "retro" (the retro rings) or "points" (module
    doc). Raises ValueError (one line) for a bad name, value or table."""
    if isinstance(model, models.BRDFModel):
        raise ValueError(f"{model!r}: fit takes a model's name, class or function, whose parameters it varies, "
                         "not a model made already (give its parameters as fixed ones)")
    cls = models.model_class(model)
    model_name, fixed = cls.name, dict(fixed or {})
    params = {p.name: p for p in cls.params}
    if not free:
        raise ValueError("--free: give at least one parameter to fit")
    for name in free:
        if name not in params:
            raise ValueError(f"--free {name}: model {model_name!r} has no such parameter; its parameters: "
                             f"{', '.join(params)}")
        if params[name].choices is not None or params[name].text:
            raise ValueError(f"--free {name}: takes {params[name].describe()}, not a number, so it cannot be fitted; "
                             "give it with --param")
    if len(set(free)) != len(free):
        raise ValueError("--free: a parameter is named twice")
    start = np.array([_start(params[name], fixed.get(name)) for name in free])
    others = {k: v for k, v in fixed.items() if k not in free}
    bounds = np.array([_bounds(params[name]) for name in free]).T
    start = np.clip(start, bounds[0], bounds[1])

    def model_at(x):
        return cls(**others, **dict(zip(free, (float(v) for v in x))))

    first = model_at(start)  # a bad fixed parameter fails here, in one line
    if on not in FITTED_ON:
        raise ValueError(f"on = {on!r}: accepted: {', '.join(map(repr, FITTED_ON))}")
    data = FITTED_ON[on](table, first, order, len(free))
    evaluated = [0]

    def values(x):
        out = data.evaluate(model_at(x))
        evaluated[0] += 1
        if progress is not None:
            progress(evaluated[0], dict(zip(free, (float(v) for v in x))))
        return out

    x, evaluations = start, 0
    for _ in range(REWEIGHTS):
        sigma = data.sigma(values(x))
        solution = least_squares(lambda x: data.residuals(values(x), sigma), x, bounds=bounds, method="trf",
                                 x_scale="jac")
        evaluations += solution.nfev
        errors = data.errors(solution.jac, sigma, table.paths)
        moved, x = np.abs(solution.x - x), solution.x
        if data.per_path is None or np.all(moved <= CONVERGED * errors):
            break
    # no degrees of freedom left (every point fitted exact, or no more values than parameters):
    # no chi-square per degree of freedom, and 0 of them, not fewer
    dof = max(data.dof(values(solution.x)) - len(free), 0.0)
    chi2 = data.chi2(solution.fun)
    best = model_at(solution.x)
    return Fit({name: (float(v), float(e)) for name, v, e in zip(free, solution.x, errors)},
               chi2 / dof if dof > 0 else None, dof, int(evaluations),
               compare.compare(table, best, order, on=on), data.notes)


@dataclass
class _Fitted:
    """What a fit fits (module doc): the table's values ``f`` at its fitted cells, retro rings or
    points, their standard errors ``observed`` and ``incidence``, and ``evaluate(model)``, the
    model's values there. Cells and rings are weighed by the variance the model predicts, ``per_path``
    max(m, ``floor``), with the realizations' ``scale`` in their errors; points (``per_path``
    None) by ``observed``, or, with the points' covariance, by ``whiten`` (generalized least
    squares: residuals whiten @ (m - f), of which the rows ``counted`` are the incidences'
    Hotelling directions and the others the exact points)."""

    f: np.ndarray
    observed: np.ndarray
    incidence: np.ndarray
    evaluate: Callable
    per_path: np.ndarray | None = None
    floor: np.ndarray | None = None
    scale: np.ndarray | None = None
    whiten: np.ndarray | None = None
    counted: np.ndarray | None = None
    notes: dict = field(default_factory=dict)

    def sigma(self, values) -> np.ndarray:
        """The standard error each fitted value is weighed by, the model's being ``values``."""
        return self.observed if self.per_path is None else np.sqrt(self.per_path * np.maximum(values, self.floor))

    def residuals(self, values, sigma) -> np.ndarray:
        """The residuals least squares minimizes, the model's values being ``values``."""
        return (values - self.f) / sigma if self.whiten is None else self.whiten @ (values - self.f)

    def errors(self, jac, sigma, paths) -> np.ndarray:
        """The parameters' standard errors (module doc)."""
        if self.whiten is not None:
            return _gauss_newton_errors(jac)
        if self.per_path is None:
            return _bounding_errors(jac)
        return _sandwich_errors(jac, sigma, self.f, self.observed, self.incidence, paths, self.scale)

    def chi2(self, residuals) -> float:
        """Chi-square of the best fit's ``residuals`` (with the points' covariance: the sum of the
        incidences' Hotelling T^2, the exact points left out)."""
        if self.counted is None:
            return float(np.sum(residuals**2))
        weighed = self.counted > 0
        return float(np.sum(residuals[weighed] ** 2 / self.counted[weighed]))

    def dof(self, values) -> float:
        """Chi-square's expected value at the model's ``values``, before the free parameters."""
        if self.counted is not None:
            return float(np.count_nonzero(self.counted))
        return float(self.f.size) if self.per_path is None else float(np.sum(np.minimum(1.0, values / self.floor)))


def _cells(table, first, order: str, n_free: int) -> _Fitted:
    """The cells to fit (module doc), their quadrature found for the model ``first``."""
    _, sim, stderr, albedo, albedo_stderr = selection(table, order)  # checks the order and the values
    signal = with_signal(sim, stderr)
    if signal.sum() <= n_free:
        raise ValueError(f"table {table.path}: {int(signal.sum())} cells with signal, too few to fit "
                         f"{n_free} parameters")
    # every cell, none chosen by its own value (module doc), of the incidences whose cells with
    # signal tell the paths' dispersion
    fitted = np.broadcast_to(signal.any(axis=1)[:, None], signal.shape)
    tolerance = QUADRATURE_TOLERANCE / math.sqrt(fitted.sum())
    rules = [CellRule(table.sensor, wi,
                              refined_cell_averages(first, table.sensor, wi, stderr[i], tolerance)[2])
             for i, wi in enumerate(table.wi)]
    incidence = np.nonzero(fitted)[0]  # the incidence of each fitted cell
    dispersion, floor = table_noise.variance_model(sim, stderr, signal, table.projected_solid_angle)
    scale = table_noise.realization_scale(sim, stderr, albedo, albedo_stderr, table.projected_solid_angle,
                                          table.paths, table_noise.realizations(table))
    return _Fitted(sim[fitted], stderr[fitted], incidence,
                   lambda model: np.concatenate([rule.averages(model)[fitted[i]] for i, rule in enumerate(rules)]),
                   (dispersion[:, None] / table.projected_solid_angle)[fitted], floor[incidence], scale)


def _rings(table, first, order: str, n_free: int) -> _Fitted:
    """The retro rings to fit (module doc), their quadrature found for the model ``first``."""
    sim, stderr = extra_selection(table, order, "retro")
    sensor = retro_sensor(table)
    projected = table.arrays["sensor/retro_projected_solid_angle"]
    _, cells, cells_stderr, albedo, albedo_stderr = selection(table, order)
    cells_signal = with_signal(cells, cells_stderr)
    signal = with_signal(sim, stderr) & (projected > 0)
    if signal.sum() <= n_free:
        raise ValueError(f"--retro: table {table.path}: {int(signal.sum())} retro rings with signal, too few to fit "
                         f"{n_free} parameters")
    fitted = (projected > 0) & cells_signal.any(axis=1)[:, None]
    tolerance = QUADRATURE_TOLERANCE / math.sqrt(fitted.sum())
    rules = [RingRule(sensor, wi, ring_averages(first, sensor, wi, stderr[i], tolerance)[2])
             for i, wi in enumerate(table.wi)]
    incidence = np.nonzero(fitted)[0]
    dispersion, floor = table_noise.variance_model(cells, cells_stderr, cells_signal, table.projected_solid_angle)
    scale = table_noise.realization_scale(cells, cells_stderr, albedo, albedo_stderr, table.projected_solid_angle,
                                          table.paths, table_noise.realizations(table))
    return _Fitted(sim[fitted], stderr[fitted], incidence,
                   lambda model: np.concatenate([rule.averages(model)[fitted[i]] for i, rule in enumerate(rules)]),
                   dispersion[incidence] / projected[fitted], floor[incidence], scale)


def _points(table, first, order: str, n_free: int) -> _Fitted:
    """The points to fit (module doc); ``first`` is not needed (no quadrature)."""
    sim, stderr = extra_selection(table, order, "points")
    directions = table.arrays["sensor/points_direction"]
    error = np.maximum(stderr, EXACT_POINT * np.abs(sim))
    fitted = (error > 0) & ~repeated_points(directions)
    if fitted.sum() <= n_free:
        raise ValueError(f"--points: table {table.path}: {int(fitted.sum())} points with a value, too few to fit "
                         f"{n_free} parameters")
    incidence = np.nonzero(fitted)[0]
    wi, wo = table.wi[incidence], directions[fitted]
    whiten, counted, notes = _whitening(table, order, sim, stderr, fitted, n_free)
    return _Fitted(sim[fitted], error[fitted], incidence, lambda model: model(wi, wo), whiten=whiten,
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


#: what a fit fits, by ``on``
FITTED_ON = {"cells": _cells, "retro": _rings, "points": _points}


def _bounding_errors(jac) -> np.ndarray:
    """Standard errors of parameters fitted with residuals of unit variance and unknown
    correlation, Jacobian ``jac``: sum_j |a_j| for each parameter's row a of (J^T J)^-1 J^T, the
    largest whatever the correlation; infinite for a parameter the table does not constrain."""
    try:
        solve = np.linalg.inv(jac.T @ jac) @ jac.T
    except np.linalg.LinAlgError:
        return np.full(jac.shape[1], math.inf)
    return np.sum(np.abs(solve), axis=1)


def _gauss_newton_errors(jac) -> np.ndarray:
    """Standard errors of parameters fitted with whitened residuals (unit covariance) of
    Jacobian ``jac``: the square roots of the diagonal of (J^T J)^-1; infinite for a parameter
    the table does not constrain."""
    try:
        return np.sqrt(np.clip(np.diag(np.linalg.inv(jac.T @ jac)), 0.0, None))
    except np.linalg.LinAlgError:
        return np.full(jac.shape[1], math.inf)


def _sandwich_errors(jac, sigma, f, stderr, incidence, paths, scale) -> np.ndarray:
    """Standard errors of parameters fitted with residuals (m - f) / sigma of Jacobian ``jac``:
    the square roots of the diagonal of (J^T J)^-1 M (J^T J)^-1, M the covariance of J^T (f /
    sigma), from the paths of each incidence (:func:`table_noise.path_covariance`) and its
    realizations' common scale (:func:`table_noise.realization_scale`); infinite for a parameter
    the table does not constrain."""
    try:
        bread = np.linalg.inv(jac.T @ jac)
    except np.linalg.LinAlgError:
        return np.full(jac.shape[1], math.inf)
    meat = np.zeros_like(bread)
    for i in np.unique(incidence):
        cells = incidence == i
        coefficients = jac[cells] / sigma[cells, None]
        along = coefficients.T @ f[cells]
        meat += (table_noise.path_covariance(coefficients, f[cells], stderr[cells], paths[i])
                 + scale[i] * np.outer(along, along))
    return np.sqrt(np.clip(np.diag(bread @ meat @ bread), 0.0, None))


def _bounds(param) -> tuple[float, float]:
    lo, hi = param.lo, param.hi
    span = hi - lo if math.isfinite(hi - lo) else 1.0
    if param.lo_open:
        lo += OPEN_END * span
    if param.hi_open:
        hi -= OPEN_END * span
    return lo, hi


#: a positive range at least this wide (hi / lo) that holds 1 starts at 1
DECADES_RATIO = 100.0


def _start(param, given) -> float:
    """The starting value: the one given, else the default, else 1 for a positive range of
    decades that holds it (a ratio or a slope: the middle of beta in [0.001, 1000], 500, starts a
    fit of micrograins so far from its answer that it does not end in minutes), else the middle
    of a finite range."""
    if given is not None:
        return param.check(given)
    if isinstance(param.default, (int, float)) and not isinstance(param.default, bool):
        return float(param.default)
    lo, hi = _bounds(param)
    if 0 < lo <= 1.0 <= hi and hi / lo >= DECADES_RATIO:
        return 1.0
    if math.isfinite(lo) and math.isfinite(hi):
        return 0.5 * (lo + hi)
    return lo + 1.0 if math.isfinite(lo) else (hi - 1.0 if math.isfinite(hi) else 1.0)
