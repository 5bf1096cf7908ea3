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

``on`` fits another estimator's values instead of the cells: the retro rings (``--retro``) or
the points (``--points``), each as its judge makes them a :class:`~microsim.analysis.fitted.Fitted`
(:mod:`microsim.analysis.judge_retro`, :mod:`microsim.analysis.judge_points`). The best model is
compared as ``compare`` compares on the same."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from microsim import models
from microsim.analysis import compare, judges
from microsim.analysis.judges import DEFAULT_ON
from microsim.analysis.point_comparison import PointComparison

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
        on: str = DEFAULT_ON) -> Fit:
    """Fit the ``free`` parameters of ``model`` to ``table``; ``fixed`` holds the other
    parameters, and starting values for free ones. ``model``: a registered model's name, a
    :class:`~microsim.models.BRDFModel` subclass or a plain function ``f(wi, wo, **params)``
    (:mod:`microsim.models.user_models`). ``progress(evaluations, values)``, if given, is called
    after every evaluation of the model over the table's cells (``values``: the free parameters
    evaluated). ``on``: what is fitted, "cells" or another judge's word (module doc). Raises ValueError (one line) for a bad name, value or table."""
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
    data = judges.judge(on).fitted(table, first, order, len(free))
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
