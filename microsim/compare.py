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
the realizations' share, :mod:`microsim.table_noise`), not over its own estimated error, which
runs high at few paths a cell. 1 is expected, within two-sided CHI2_OUTSIDE bounds. The model
is "consistent" with the table when chi-square lies within them and the albedo's z^2 (over the
incidences) under its upper bound; above, it is not the table's BRDF; below, the table's errors
are too large.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .table_noise import CHI2_OUTSIDE, chi2_bounds, predicted_variance, realization_scale

QUADRATURE_TOLERANCE = 0.05
ALBEDO_TOLERANCE = 1e-4
QUADRATURE_RULES = (4, 8, 16, 32, 64, 128)
SIGNAL_TO_NOISE = 3.0
#: --order choice -> row of the table's brdf_order (None: all orders, the table's brdf; BASE: the
#: part of order 1 scattered by the base, brdf_order1_base, in tables of scenes with a base)
BASE = "base"
#: orders 1 and 2 together, brdf_orders12 (the f2 of Meneveaux et al. 2015, Sec. 3.3)
ORDERS12 = "orders12"
ORDER_ROWS = {"all": None, "1": 0, "2": 1, "3": 2, "4+": 3, "1+2": ORDERS12, "1-base": BASE}


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

    def metrics(self, i: int | None = None) -> dict:
        """The metrics of one incidence, or over all incidences (``i=None``)."""
        rows = slice(None) if i is None else slice(i, i + 1)
        m, s, e, ok = self.model[rows], self.sim[rows], self.stderr[rows], self.signal[rows]
        rel = (m[ok] - s[ok]) / s[ok]
        z = (m[ok] - s[ok]) / e[ok]
        v = self.variance[rows][ok]
        chi2 = float(np.mean((m[ok] - s[ok]) ** 2 / v)) if z.size else float("nan")
        low, high = chi2_bounds(self.kurtosis[rows][ok], self.common[rows][ok])
        albedo_z = self.albedo_z()[rows]
        albedo_limit = albedo_bound(albedo_z.size)
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
        """(n_i,) (model's albedo - table's) / its standard error, the albedo quadrature's own
        tolerance (ALBEDO_TOLERANCE of it) added in quadrature: a plane's albedo has no error."""
        error = np.hypot(self.albedo_sim_stderr, ALBEDO_TOLERANCE * np.abs(self.albedo_model))
        return (self.albedo_model - self.albedo_sim) / np.where(error > 0, error, np.inf)

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


def compare(table, model, order: str = "all", **params) -> Comparison:
    """Average ``model`` over the cells of ``table`` (a :class:`microsim.tables.Table`) and compare;
    ValueError (one line) if no cell has signal. ``model``: a model (``models.create(...)``), a
    registered model's name, a :class:`~microsim.models.BRDFModel` subclass or a plain function
    ``f(wi, wo, **params)`` (:mod:`microsim.models.user_models`), made with ``params``."""
    from .models import as_model

    model = as_model(model, **params)
    names, sim, stderr, albedo_sim, albedo_se = selection(table, order)
    if not with_signal(sim, stderr).any():
        raise ValueError(f"table {table.path}: no cell of order {order} has signal (a value above "
                         f"{SIGNAL_TO_NOISE:g} standard errors): nothing to compare; trace more paths or use fewer cells")
    modelled = np.zeros_like(sim)
    worst = 0.0
    for i, wi in enumerate(table.wi):
        modelled[i], change = cell_averages(model, table.sensor, wi, stderr[i])
        worst = max(worst, change)
    _require_finite(modelled, f"model {model!r}")
    p = table.projected_solid_angle
    signal = with_signal(sim, stderr)
    return Comparison(model.name, dict(model.values), order, table.theta_i, table.phi_i, modelled, sim, stderr,
                      signal, modelled @ p, albedo_sim, albedo_se, worst,
                      *predicted_variance(modelled, sim, stderr, signal, p,
                                          realization_scale(sim, stderr, albedo_sim, albedo_se, p, table.paths,
                                                            int(table.attrs.get("realizations", 2)))))


def albedo_bound(incidences: int) -> float:
    """Upper CHI2_OUTSIDE / 2 bound of the mean albedo z^2 over ``incidences`` (chi-square of that
    many degrees of freedom, over their number) for an exact model."""
    from scipy.stats import chi2

    return float(chi2.ppf(1 - CHI2_OUTSIDE / 2, incidences) / incidences)


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


def _require_finite(values: np.ndarray, what: str) -> None:
    """Raise ValueError naming ``what`` if any cell is NaN or infinite."""
    if bad := np.count_nonzero(~np.isfinite(values)):
        raise ValueError(f"{what} is NaN or infinite in {bad} of {values.size} cells")
