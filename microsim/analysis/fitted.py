"""What a fit fits (:func:`microsim.analysis.fit.fit`): the table's values, their errors and the
model's values there (:class:`Fitted`), and the parameters' standard errors each weighing gives.
A judge (:mod:`microsim.analysis.judges`) makes its own ``Fitted``; the cells' is here
(:func:`fitted_cells`; how the cells are chosen and weighed: the fit's module doc).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from microsim.analysis.averages import QUADRATURE_TOLERANCE, CellRule, refined_cell_averages
from microsim.analysis.selection import selection, with_signal
from microsim.core import table_noise


@dataclass
class Fitted:
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


def fitted_cells(table, first, order: str, n_free: int) -> Fitted:
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
    return Fitted(sim[fitted], stderr[fitted], incidence,
                   lambda model: np.concatenate([rule.averages(model)[fitted[i]] for i, rule in enumerate(rules)]),
                   (dispersion[:, None] / table.projected_solid_angle)[fitted], floor[incidence], scale)


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
