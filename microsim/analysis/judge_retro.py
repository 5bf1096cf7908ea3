"""The judge of the retro rings (``compare --retro``, ``fit --retro``;
:mod:`microsim.tracer.estimators.retro_rings`).

Compared (:func:`compare_retro`): the model averaged over each ring about the
retro direction with the cos(theta_o) weight (:meth:`RetroRings.quadrature`, refined as
the cells' rule is) against ``brdf_retro``. A ring is a bin that the paths exit into, as a cell
is: its variance if the model were right comes from the cells' dispersion and realizations'
scale (the same paths), and it is judged as a cell is, over the rings with signal (rings the
horizon cuts entirely have none). Neither points nor rings have an albedo.

Fitted (:func:`fitted_rings`) as the cells are (the fit's module doc): a ring is a bin that the
paths exit into, weighed by the variance the model predicts from the cells' dispersion (the same
paths), every ring above the horizon of the incidences whose cells have signal, each averaged by
a rule found at the starting parameters and held fixed (``averages.RingRule``).
"""

from __future__ import annotations

import math

import numpy as np

from microsim.analysis.averages import QUADRATURE_TOLERANCE, RingRule, ring_averages
from microsim.analysis.fitted import Fitted
from microsim.analysis.judges import Judge
from microsim.analysis.point_comparison import PointComparison, judged_values
from microsim.analysis.selection import SIGNAL_TO_NOISE, extra_selection, require_finite, selection, with_signal
from microsim.core import table_noise
from microsim.core.table_noise import CHI2_OUTSIDE, predicted_variance, realization_scale, realizations
from microsim.tracer.estimators.retro_rings import RetroRings


class RingsComparison(PointComparison):
    """Model and simulation on a table's retro rings (module doc)."""

    unit, counted = "ring", "rings_with_signal"

    def rules(self) -> dict:
        return {
            "signal_rule": f"table value > {SIGNAL_TO_NOISE:g} standard errors, on rings above the horizon",
            "chi2_rule": "mean over the rings with signal of (model - table)^2 / v, v the ring's variance if "
                         "the model were right (from the cells' dispersion: the same paths); bounds: "
                         f"{100 * (1 - CHI2_OUTSIDE):g} % two-sided; consistent: within them",
            "quadrature_max_change_in_stderr": self.quadrature_change,
        }

    def summary(self) -> str:
        return (f"retro rings with signal: table > {SIGNAL_TO_NOISE:g} standard errors; chi^2 per "
                f"ring: 1 expected for the model of the table, {100 * (1 - CHI2_OUTSIDE):g} % two-sided")


def compare_retro(table, model, order: str = "all", **params) -> PointComparison:
    """``model`` averaged over the table's retro rings against ``brdf_retro`` (module doc),
    arguments as :func:`compare`'s; ValueError (one line) for a table without rings, an order
    they do not hold, or no ring with signal."""
    model, sim, stderr = judged_values(table, model, order, RETRO, params)
    rings = rings_of(table)
    projected = table.arrays["sensor/retro_projected_solid_angle"]
    modelled = np.zeros_like(sim)
    worst = 0.0
    for i, wi in enumerate(table.wi):
        modelled[i], change, _ = ring_averages(model, rings, wi, stderr[i])
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
    return RingsComparison(model.name, dict(model.values), order, "retro", table.theta_i, table.phi_i, modelled,
                           sim, stderr, judged, np.zeros_like(judged), z, terms, kurtosis, common, worst, {})


def rings_of(table) -> RetroRings:
    """The table's retro rings, rebuilt from their bounds (uniform in the chord 2 sin(gamma / 2)
    out to the last ring's gamma_hi) and checked against them (ValueError)."""
    lo, hi = table.arrays["sensor/retro_gamma_lo"], table.arrays["sensor/retro_gamma_hi"]
    rings = RetroRings.reaching(len(lo), math.degrees(hi[-1]))
    if not all(np.allclose(mine, stored, rtol=0.0, atol=1e-9)
               for mine, stored in zip(rings.phase_bounds(), (lo, hi))):
        raise ValueError(f"--retro: table {table.path}: its rings (sensor/retro_gamma_lo, sensor/retro_gamma_hi) are "
                         "not uniform in the chord 2 sin(gamma / 2), as microsim writes them")
    return rings


def fitted_rings(table, first, order: str, n_free: int) -> Fitted:
    """The retro rings to fit (module doc), their quadrature found for the model ``first``."""
    sim, stderr = extra_selection(table, order, RETRO)
    rings = rings_of(table)
    projected = table.arrays["sensor/retro_projected_solid_angle"]
    _, cells, cells_stderr, albedo, albedo_stderr = selection(table, order)
    cells_signal = with_signal(cells, cells_stderr)
    signal = with_signal(sim, stderr) & (projected > 0)
    if signal.sum() <= n_free:
        raise ValueError(f"--retro: table {table.path}: {int(signal.sum())} retro rings with signal, too few to fit "
                         f"{n_free} parameters")
    fitted = (projected > 0) & cells_signal.any(axis=1)[:, None]
    tolerance = QUADRATURE_TOLERANCE / math.sqrt(fitted.sum())
    rules = [RingRule(rings, wi, ring_averages(first, rings, wi, stderr[i], tolerance)[2])
             for i, wi in enumerate(table.wi)]
    incidence = np.nonzero(fitted)[0]
    dispersion, floor = table_noise.variance_model(cells, cells_stderr, cells_signal, table.projected_solid_angle)
    scale = table_noise.realization_scale(cells, cells_stderr, albedo, albedo_stderr, table.projected_solid_angle,
                                          table.paths, table_noise.realizations(table))
    return Fitted(sim[fitted], stderr[fitted], incidence,
                   lambda model: np.concatenate([rule.averages(model)[fitted[i]] for i, rule in enumerate(rules)]),
                   dispersion[incidence] / projected[fitted], floor[incidence], scale)


RETRO = Judge(
    on="retro", unit="ring", dataset="brdf_retro", counted="rings_with_signal", keys="[sensor] retro_rings",
    geometry=("sensor/retro_gamma_lo", "sensor/retro_gamma_hi", "sensor/retro_projected_solid_angle"),
    help="instead of the cells, the table's retro rings (sensor.retro_rings): the model averaged over each ring, "
         "cos-weighted, against brdf_retro, each ring judged as a cell; no albedo",
    compare=compare_retro, fitted=fitted_rings)
