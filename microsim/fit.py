"""Model parameters fitted to a table (CONVENTIONS 7, ``microsim fit``): weighted least squares
on cell averages.

The residual of cell C of incidence i is (model_C - table_C) / stderr_C over the cells with
signal (table > ``compare.SIGNAL_TO_NOISE`` standard errors), the model averaged over each cell
as ``compare`` does. The quadrature each cell needs is found once, at the starting parameters
(``compare.refined_cell_averages``), and held fixed while the parameters move
(``compare.CellRule``), so the residuals are smooth in them. Its tolerance is compare's
(``QUADRATURE_TOLERANCE`` standard errors a cell) divided by the square root of the N cells with
signal: quadrature errors can share their sign over many cells, and N cells each off by t
standard errors in the same direction would move a fitted scale by about t sqrt(N) of its
standard errors. scipy's trust-region reflective
least squares keeps the parameters inside their declared ranges (open ends by 1e-9 of the
range). Standard errors are the square roots of the diagonal of (J^T J)^-1 at the optimum (J the
Jacobian of the residuals): what the table's errors allow if the model is right. The chi-square
per degree of freedom (cells with signal minus free parameters) says whether it is: near 1 for a
model that describes the table, far above 1 for one that does not, and the fit reports it
whatever it is. The best model is then compared with the table exactly as ``compare`` does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from . import compare, models

#: open ends of a parameter's range are kept this fraction of the range (or absolutely) inside
OPEN_END = 1e-9


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
    _, sim, stderr, _, _ = compare.selection(table, order)  # checks the order and the table's values
    signal = compare.with_signal(sim, stderr)
    if signal.sum() <= len(free):
        raise ValueError(f"table {table.path}: {int(signal.sum())} cells with signal, too few to fit "
                         f"{len(free)} parameters")
    tolerance = compare.QUADRATURE_TOLERANCE / math.sqrt(signal.sum())
    rules = [compare.CellRule(table.sensor, wi,
                              compare.refined_cell_averages(first, table.sensor, wi, stderr[i], tolerance)[2])
             for i, wi in enumerate(table.wi)]

    def residuals(x):
        model = model_at(x)
        out = []
        for i, rule in enumerate(rules):
            averages = rule.averages(model)
            ok = signal[i]
            out.append((averages[ok] - sim[i, ok]) / stderr[i, ok])
        return np.concatenate(out)

    solution = least_squares(residuals, start, bounds=bounds, method="trf", x_scale="jac")
    jac = solution.jac
    dof = int(signal.sum()) - len(free)
    chi2 = float(np.sum(solution.fun**2))
    try:
        covariance = np.linalg.inv(jac.T @ jac)
        errors = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    except np.linalg.LinAlgError:
        errors = np.full(len(free), math.inf)  # a parameter the table does not constrain
    best = model_at(solution.x)
    return Fit({name: (float(v), float(e)) for name, v, e in zip(free, solution.x, errors)}, chi2 / dof, dof,
               int(solution.nfev), compare.compare(table, best, order))


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
