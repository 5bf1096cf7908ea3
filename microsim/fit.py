"""Model parameters fitted to a table (CONVENTIONS 7, ``microsim fit``): least squares on cell
averages, weighted by variances predicted from the model (quasi-likelihood, iterated).

Weighting each cell by its own estimated standard error (Neyman's chi-square) biases a fit:
a cell's error is estimated from the same paths as its value, and a cell that fluctuated low
also gets a small error and a large weight. A plane of albedo 0.5 came out 5 standard errors
low at 125 paths a cell (800 cells), and the bias fell as 1 / (paths per cell) (issue 24).
Instead, the variance of cell C is taken from the model: an estimate f_C = (sum of the weights of the paths
that exit into C) / (N paths x projected solid angle P_C) has variance f_C E[w^2] / E[w] /
(N P_C), so v_C = k m_C / P_C, with m_C the model's cell average and k an incidence's
dispersion pooled over its cells with signal, k = sum(stderr_C^2 P_C) / sum(f_C) (a ratio of
sums, nearly free of any one cell's noise). Weights are held fixed while the parameters move,
then recomputed from the best model, until no parameter moves by more than ``CONVERGED`` of its
standard error: the fitted parameters solve sum_C (m_C - f_C) dm_C/dx / v_C = 0, whose
expectation at the true parameters is zero whatever the noise (where the weights of a cell's
paths vary from cell to cell, v_C is only near the truth: the fit stays unbiased, a little less
efficient).

The standard errors are those of the sandwich (J^T W J)^-1 J^T W Cov W J (J^T W J)^-1, W the
weights, with the cells' covariance Cov that the table implies: the cells of an incidence share
its paths (a path exits into one cell, so they are anticorrelated) and, in a random scene, its
realizations (:func:`_path_covariance`, :func:`_realization_scale`). Taking the cells as
independent overstates the error of what sums many cells: the albedo of a Lambertian plane is
fixed by the energy its paths carry out, each exactly 0.5, and its fit is exact but for the
cells without signal: at 125 paths a cell (100 cells, 30 seeds) the fits fell within 1.7e-4 of
0.5, where the error of independent cells read 2.6e-3 (``tests/test_fit.py``).

The cells fitted are those with signal (table > ``compare.SIGNAL_TO_NOISE`` standard errors),
the model averaged over each cell as ``compare`` does. The quadrature each cell needs is found
once, at the starting parameters (``compare.refined_cell_averages``), and held fixed while the
parameters move (``compare.CellRule``), so the residuals are smooth in them. Its tolerance is
compare's (``QUADRATURE_TOLERANCE`` standard errors a cell) divided by the square root of the N
cells with signal: quadrature errors can share their sign over many cells, and N cells each off
by t standard errors in the same direction would move a fitted scale by about t sqrt(N) of its
standard errors. scipy's trust-region reflective least squares keeps the parameters inside
their declared ranges (open ends by 1e-9 of the range). The chi-square per degree of freedom
(cells with signal minus free parameters, with the model's variances) says whether the model
describes the table: near 1 if it does, far above 1 if not, and the fit reports it whatever it
is. The best model is then compared with the table exactly as ``compare`` does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from . import compare, models

#: open ends of a parameter's range are kept this fraction of the range (or absolutely) inside
OPEN_END = 1e-9
#: the weights are recomputed until no parameter moves by more than this many standard errors
CONVERGED = 1e-3
#: and at most this many times
REWEIGHTS = 20
#: a cell's predicted variance is at least that of a cell this fraction of the incidence's mean
#: value (a model of zero in a cell with signal would otherwise weigh without limit)
VARIANCE_FLOOR = 1e-3


@dataclass
class Fit:
    """Best parameters and their standard errors, chi-square per degree of freedom, and the
    comparison of the best model with the table."""

    free: dict  # name -> (value, standard error)
    chi2_per_dof: float
    dof: int
    evaluations: int
    comparison: compare.Comparison

    def as_dict(self) -> dict:
        """The ``compare`` JSON with the key ``fit`` added."""
        out = self.comparison.as_dict()
        out["fit"] = {name: {"value": v, "stderr": e} for name, (v, e) in self.free.items()}
        out["fit_chi2_per_dof"] = self.chi2_per_dof
        out["fit_dof"] = self.dof
        return out


def fit(table, model_name: str, free: list[str], fixed: dict, order: str = "all") -> Fit:
    """Fit the ``free`` parameters of model ``model_name`` to ``table``; ``fixed`` holds the other
    parameters, and starting values for free ones. Raises ValueError (one line) for a bad name,
    value or table."""
    cls = models.get(model_name)
    params = {p.name: p for p in cls.params}
    if not free:
        raise ValueError("--free: give at least one parameter to fit")
    for name in free:
        if name not in params:
            raise ValueError(f"--free {name}: model {model_name!r} has no such parameter; its parameters: "
                             f"{', '.join(params)}")
        if params[name].choices is not None:
            raise ValueError(f"--free {name}: a choice ({params[name].describe()}) cannot be fitted; give it with --param")
    if len(set(free)) != len(free):
        raise ValueError("--free: a parameter is named twice")
    start = np.array([_start(params[name], fixed.get(name)) for name in free])
    others = {k: v for k, v in fixed.items() if k not in free}
    bounds = np.array([_bounds(params[name]) for name in free]).T
    start = np.clip(start, bounds[0], bounds[1])

    def model_at(x):
        return models.create(model_name, **others, **dict(zip(free, (float(v) for v in x))))

    first = model_at(start)  # a bad fixed parameter fails here, in one line
    _, sim, stderr, albedo, albedo_stderr = compare.selection(table, order)  # checks the order and the values
    signal = compare.with_signal(sim, stderr)
    if signal.sum() <= len(free):
        raise ValueError(f"table {table.path}: {int(signal.sum())} cells with signal, too few to fit "
                         f"{len(free)} parameters")
    tolerance = compare.QUADRATURE_TOLERANCE / math.sqrt(signal.sum())
    rules = [compare.CellRule(table.sensor, wi,
                              compare.refined_cell_averages(first, table.sensor, wi, stderr[i], tolerance)[2])
             for i, wi in enumerate(table.wi)]

    incidence = np.nonzero(signal)[0]  # the incidence of each fitted cell
    f, observed = sim[signal], stderr[signal]
    projected = np.broadcast_to(table.projected_solid_angle, sim.shape)[signal]
    total, count = np.bincount(incidence, f, len(sim)), np.bincount(incidence, minlength=len(sim))
    dispersion = (np.bincount(incidence, observed**2 * projected, len(sim)) / np.where(total > 0, total, 1.0))[incidence]
    floor = VARIANCE_FLOOR * (total / np.maximum(count, 1))[incidence]
    scale = _realization_scale(sim, stderr, albedo, albedo_stderr, table.projected_solid_angle, table.paths,
                               int(table.attrs["realizations"]))

    def cell_averages(x):
        model = model_at(x)
        return np.concatenate([rule.averages(model)[signal[i]] for i, rule in enumerate(rules)])

    def predicted_stderr(x):
        return np.sqrt(dispersion * np.maximum(cell_averages(x), floor) / projected)

    x, evaluations = start, 0
    for _ in range(REWEIGHTS):
        sigma = predicted_stderr(x)
        solution = least_squares(lambda x: (cell_averages(x) - f) / sigma, x, bounds=bounds, method="trf",
                                 x_scale="jac")
        evaluations += solution.nfev
        errors = _sandwich_errors(solution.jac, sigma, f, observed, incidence, table.paths, scale)
        moved, x = np.abs(solution.x - x), solution.x
        if np.all(moved <= CONVERGED * errors):
            break
    dof = int(signal.sum()) - len(free)
    chi2 = float(np.sum(solution.fun**2))
    best = model_at(solution.x)
    return Fit({name: (float(v), float(e)) for name, v, e in zip(free, solution.x, errors)}, chi2 / dof, dof,
               int(evaluations), compare.compare(table, best, order))


def _realization_scale(sim, stderr, albedo, albedo_stderr, projected, paths, realizations) -> np.ndarray:
    """Per incidence, the variance g of a common relative scale of every cell: what the table's
    albedo error (from its ``realizations``) holds beyond the paths' own share
    (:func:`_path_covariance` of the albedo, sum f_C P_C). A random scene's realizations differ,
    and a denser one brightens every cell; a fixed scene has g = 0, and its albedo variance
    estimated from R realizations scatters about the paths' share as chi^2(R - 1) / (R - 1): g
    counts only where the ratio exceeds that distribution's 99th percentile (clipped at 0 alone,
    the scatter made a fixed scene's errors 5-19 % too large in half its tables)."""
    from scipy.stats import chi2

    significant = chi2.ppf(0.99, realizations - 1) / (realizations - 1)
    out = np.zeros(len(albedo))
    for i, n in enumerate(paths):
        lit = sim[i] > 0
        if not lit.any() or albedo[i] <= 0:
            continue
        own = _path_covariance(projected[lit, None], sim[i, lit], stderr[i, lit], n)[0, 0]
        if albedo_stderr[i] ** 2 > significant * own:
            out[i] = (albedo_stderr[i] ** 2 - own) / albedo[i] ** 2
    return out


def _path_covariance(coefficients, f, stderr, n) -> np.ndarray:
    """Covariance of the sums ``coefficients^T f`` over cells f_C of one incidence's n paths.

    A path exits into one cell C with weight w, or not at all; f_C = p_C E[w | C] / P_C, and the
    sum is the mean over the paths of Y = c_C w / P_C: its covariance is (sum_C c_C c_C^T n D_C
    - E[Y] E[Y]^T) / n, exactly, with D_C = stderr_C^2 + f_C^2 / n = p_C E[w^2 | C] / (n P_C^2)
    from the table. It is computed in the two-pass form sum_C q_C (y_C - E[Y])(y_C - E[Y])^T +
    q_0 E[Y] E[Y]^T, with q_C = f_C^2 / (n D_C) (p_C E[w]^2 / E[w^2], at most p_C),
    y_C = c_C n D_C / f_C and q_0 = 1 - sum q_C, which is the same whatever the weights, but
    never negative: a plane's albedo sums every path, and there the one-pass form subtracts two
    near-equal noisy terms. Where noise makes sum q_C > 1, q_0 is taken as 0, which errs high."""
    d = stderr**2 + f**2 / n
    p = f**2 / (n * d)
    y = coefficients * (n * d / f)[:, None]
    mean = coefficients.T @ f
    spread = (y - mean).T @ ((y - mean) * p[:, None])
    return (spread + max(1.0 - p.sum(), 0.0) * np.outer(mean, mean)) / n


def _sandwich_errors(jac, sigma, f, stderr, incidence, paths, scale) -> np.ndarray:
    """Standard errors of parameters fitted with residuals (m - f) / sigma of Jacobian ``jac``:
    the square roots of the diagonal of (J^T J)^-1 M (J^T J)^-1, M the covariance of J^T (f /
    sigma), from the paths of each incidence (:func:`_path_covariance`) and its realizations'
    common scale (:func:`_realization_scale`); infinite for a parameter the table does not
    constrain."""
    try:
        bread = np.linalg.inv(jac.T @ jac)
    except np.linalg.LinAlgError:
        return np.full(jac.shape[1], math.inf)
    meat = np.zeros_like(bread)
    for i in np.unique(incidence):
        cells = incidence == i
        coefficients = jac[cells] / sigma[cells, None]
        along = coefficients.T @ f[cells]
        meat += _path_covariance(coefficients, f[cells], stderr[cells], paths[i]) + scale[i] * np.outer(along, along)
    return np.sqrt(np.clip(np.diag(bread @ meat @ bread), 0.0, None))


def _bounds(param) -> tuple[float, float]:
    lo, hi = param.lo, param.hi
    span = hi - lo if math.isfinite(hi - lo) else 1.0
    if param.lo_open:
        lo += OPEN_END * span
    if param.hi_open:
        hi -= OPEN_END * span
    return lo, hi


def _start(param, given) -> float:
    """The starting value: the one given, else the default, else the middle of a finite range."""
    if given is not None:
        return param.check(given)
    if isinstance(param.default, (int, float)) and not isinstance(param.default, bool):
        return float(param.default)
    lo, hi = _bounds(param)
    if math.isfinite(lo) and math.isfinite(hi):
        return 0.5 * (lo + hi)
    return lo + 1.0 if math.isfinite(lo) else (hi - 1.0 if math.isfinite(hi) else 1.0)
