"""A table cell holds the cos(theta_o)-weighted average of the BRDF over the cell, so the model
is averaged the same way, by Gauss quadrature over each cell (:meth:`microsim.tracer.sensor.Sensor.cell_quadrature`).
The rule is refined cell by cell (4 x 4, 8 x 8, ... up to 128 x 128 nodes) until two
successive rules differ by less than ``QUADRATURE_TOLERANCE`` of the cell's standard error, so
the averaging error stays far below the table's noise; a cell without a standard error (no
path reached it) is refined until its change, times its projected solid angle, is below
``ALBEDO_TOLERANCE`` / cells of the model's albedo, so that the albedo, which sums every cell,
is converged too (a narrow specular lobe at grazing incidence on flat grains leaves it 0.5 %
short if such cells stop at 8 x 8). The largest remaining change is reported, in standard
errors (for cells without one, in their albedo share over QUADRATURE_TOLERANCE).

The retro rings are averaged the same way (:meth:`microsim.tracer.estimators.retro_rings.RetroRings.quadrature`,
n x 4 n nodes a ring). :class:`CellRule` and :class:`RingRule` hold a settled rule fixed, so
that a model's averages at other parameters cost one evaluation (``microsim fit``).
"""

from __future__ import annotations

import numpy as np

QUADRATURE_TOLERANCE = 0.05
ALBEDO_TOLERANCE = 1e-4
QUADRATURE_RULES = (4, 8, 16, 32, 64, 128)
#: the retro rings' rules: n x 4 n nodes a ring (RetroRings.quadrature), refined as the cells' are
RING_RULES = (8, 16, 32, 64)


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


def ring_averages(model, rings, wi: np.ndarray, stderr: np.ndarray, tolerance: float = QUADRATURE_TOLERANCE):
    """``model`` averaged over every retro ring of ``rings`` (a RetroRings) about wi, cos-weighted (n x 4 n
    nodes a ring, n of RING_RULES), refined until no ring moves by more than ``tolerance`` of
    its standard error (a ring without one: ALBEDO_TOLERANCE of its value). Returns the
    averages, the largest last change in standard errors and the n settled on (which
    :class:`RingRule` can hold fixed)."""
    previous, change = None, np.zeros(len(stderr))
    for n in RING_RULES:
        averages = RingRule(rings, wi, n).averages(model)
        if previous is not None:
            floor = np.where(stderr > 0, stderr, ALBEDO_TOLERANCE * np.abs(averages) / tolerance)
            change = np.divide(np.abs(averages - previous), floor, out=np.zeros_like(floor), where=floor > 0)
            if change.max(initial=0.0) <= tolerance:
                break
        previous = averages
    return averages, float(change.max(initial=0.0)), n


class RingRule:
    """A fixed quadrature of every retro ring about wi, n x 4 n nodes a ring, as
    :class:`CellRule` is of the cells."""

    def __init__(self, rings, wi: np.ndarray, n: int):
        self.nodes, self.weights = rings.quadrature(wi, n, 4 * n)
        self.wi = np.broadcast_to(wi, self.nodes.shape)

    def averages(self, model) -> np.ndarray:
        return np.sum(model(self.wi, self.nodes) * self.weights, axis=1)
