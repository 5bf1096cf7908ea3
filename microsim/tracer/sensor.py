"""The hemispherical sensor of docs/conventions.md §3: equal-solid-angle cells, exact cover, O(1) lookup.

The hemisphere is cut into rings in theta; ring k holds ``n_k`` cells of equal width in phi.
Ring boundaries are placed so that every cell has solid angle exactly 2 pi / N:
``1 - cos(theta_k) = C_k / N`` with ``C_k`` the number of cells in rings 0..k. The cap is one
cell; ring counts are chosen from a nominal theta spacing equal to the cell side so that cells
are close to square. Cells of ring k are centred on phi = 2 pi j / n_k (j = 0 sits on the
backscatter half plane of an incidence at phi_i = 0).

Lookup: u = (1 - z) N lies in [C_{k-1}, C_k) for the ring k of direction (x, y, z), so
``ring_of[floor(u)]`` gives the ring in O(1). Within the ring, a polynomial azimuth (error
below 2.04e-4 rad, at most a tenth of a cell's width even at 10^6 cells) guesses the cell. Where
the guess lies farther from both of the cell's edges than twice that error, it is the cell;
otherwise the side of the cell's two phi edges that (x, y) lies on (the sign of a cross product
with the edge's unit vector) settles it exactly, one step at most. No atan2, no search loop: it
bins as floor(atan2(y, x) n_k / 2 pi + 1/2) did, except within rounding (~1e-16 rad) of an
edge, at a third of the cost of a search loop (measurements: docs/developer/performance.md,
section 'Sensor lookup per exit').

The sensor is the cells alone: the retro rings and the points are estimators' own
(:mod:`microsim.tracer.estimators.retro_rings`, :mod:`microsim.tracer.estimators.points`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from microsim.core.frames import direction


class Sensor(NamedTuple):
    """Cell layout of the hemispherical sensor (all angles in radians).

    A namedtuple of its lookup arrays, so that numba kernels take the sensor itself
    (:func:`cell_index`). Made from the cells per ring alone (:meth:`from_ring_counts`).
    """

    ring_counts: np.ndarray  # (n_rings,) cells per ring
    ring_start: np.ndarray  # (n_rings + 1,) index of the first cell of each ring; last = N
    ring_of: np.ndarray  # (N,) ring of each solid-angle slot floor((1 - z) N)
    edge_x: np.ndarray  # (N,) cos of each cell's lower phi edge, (j - 1/2) 2 pi / n_k
    edge_y: np.ndarray  # (N,) its sin

    @classmethod
    def from_ring_counts(cls, ring_counts) -> "Sensor":
        ring_counts = np.asarray(ring_counts, dtype=np.int64)
        ring_start = np.concatenate([[0], np.cumsum(ring_counts)]).astype(np.int64)
        ring_of = np.repeat(np.arange(len(ring_counts), dtype=np.int32), ring_counts)
        j = np.arange(ring_start[-1]) - ring_start[ring_of]
        edge = (j - 0.5) * (2.0 * np.pi / ring_counts[ring_of])
        return cls(ring_counts, ring_start, ring_of, np.cos(edge), np.sin(edge))

    @classmethod
    def build(cls, cells: int) -> "Sensor":
        """A sensor of about ``cells`` cells (the actual count is ``n_cells``)."""
        if cells < 1:
            raise ValueError("sensor.cells must be >= 1")
        omega = 2.0 * math.pi / cells
        side = math.sqrt(omega)
        theta_cap = math.acos(1.0 - 1.0 / cells)
        n_rings_rest = max(0, round((math.pi / 2 - theta_cap) / side))
        counts = [1]
        if n_rings_rest:
            edges = np.linspace(theta_cap, math.pi / 2, n_rings_rest + 1)
            for lo, hi in zip(edges[:-1], edges[1:]):
                band = 2.0 * math.pi * (math.cos(lo) - math.cos(hi))
                counts.append(max(1, round(band / omega)))
        return cls.from_ring_counts(counts)

    @property
    def n_cells(self) -> int:
        return int(self.ring_start[-1])

    @property
    def n_rings(self) -> int:
        return len(self.ring_counts)

    @property
    def cos_edges(self) -> np.ndarray:
        """cos(theta) at the ring boundaries, from 1 (pole) down to 0 (horizon), exact."""
        return 1.0 - self.ring_start / self.n_cells

    def ring_theta_bounds(self):
        """(theta_lo, theta_hi) of each ring."""
        c = np.clip(self.cos_edges, 0.0, 1.0)
        c[-1] = 0.0
        t = np.arccos(c)
        return t[:-1], t[1:]

    def ring_centres(self) -> np.ndarray:
        """Polar angle at the middle of each ring (the cap's centre is the pole)."""
        lo, hi = self.ring_theta_bounds()
        centre = 0.5 * (lo + hi)
        centre[0] = 0.0
        return centre

    def cell_bounds(self):
        """theta_lo, theta_hi, phi_lo, phi_hi of every cell, radians."""
        t_lo, t_hi = self.ring_theta_bounds()
        ring = self.ring_of_cell()
        j = np.arange(self.n_cells) - self.ring_start[ring]
        width = 2.0 * np.pi / self.ring_counts[ring]
        return t_lo[ring], t_hi[ring], (j - 0.5) * width, (j + 0.5) * width

    def ring_of_cell(self) -> np.ndarray:
        return np.repeat(np.arange(self.n_rings), self.ring_counts)

    def cell_centres(self) -> tuple[np.ndarray, np.ndarray]:
        """theta and phi of every cell's centre, radians: mid theta of the ring (0 for the polar
        cap), mid phi of the cell."""
        t_lo, t_hi, p_lo, p_hi = self.cell_bounds()
        theta = 0.5 * (t_lo + t_hi)
        theta[self.ring_of_cell() == 0] = 0.0
        return theta, 0.5 * (p_lo + p_hi)

    def directions(self) -> np.ndarray:
        """Cell centre directions (N, 3) (:meth:`cell_centres`)."""
        return direction(*self.cell_centres())

    def solid_angle(self) -> np.ndarray:
        """Solid angle of every cell: exactly 2 pi / N."""
        return np.full(self.n_cells, 2.0 * np.pi / self.n_cells)

    def projected_solid_angle(self) -> np.ndarray:
        """Integral of cos(theta) d(omega) over every cell: dphi (cos^2 lo - cos^2 hi) / 2."""
        c = self.cos_edges
        ring = self.ring_of_cell()
        dphi = 2.0 * np.pi / self.ring_counts[ring]
        return dphi * 0.5 * (c[ring] ** 2 - c[ring + 1] ** 2)

    def lookup(self, w: np.ndarray) -> np.ndarray:
        """Cell index of each direction of ``w`` (M, 3) with w.z > 0."""
        from microsim.tracer.sensor_kernels import cell_indices

        w = np.ascontiguousarray(w, dtype=np.float64).reshape(-1, 3)
        return cell_indices(w, self)

    def cell_quadrature(self, n_theta: int = 4, n_phi: int = 4, cells=None):
        """Nodes and weights averaging a function over each cell (or over ``cells``, an index
        array) with the cos(theta) weight.

        Returns ``(w (N, n_theta * n_phi, 3), weight (N, n_theta * n_phi))`` such that
        ``sum(weight * g(w), axis=1)`` is the cos-weighted mean of g over each cell, i.e.
        (1 / P_C) * integral over C of g cos(theta) d(omega) (conventions §2). Gauss-Legendre
        in mu = cos(theta) with the weight mu folded in (exact for g polynomial in mu of degree
        2 n_theta - 2), and Gauss-Legendre in phi.
        """
        c = self.cos_edges
        cells = np.arange(self.n_cells) if cells is None else np.asarray(cells)
        ring = self.ring_of_cell()[cells]
        mu_lo, mu_hi = c[ring + 1], c[ring]
        _, _, p_lo, p_hi = (bounds[cells] for bounds in self.cell_bounds())
        xt, wt = np.polynomial.legendre.leggauss(n_theta)
        xp, wp = np.polynomial.legendre.leggauss(n_phi)
        half = 0.5 * (mu_hi - mu_lo)[:, None]
        mu = mu_lo[:, None] + half * (xt[None, :] + 1.0)
        w_mu = half * wt[None, :] * mu
        w_mu /= w_mu.sum(axis=1, keepdims=True)
        phi = p_lo[:, None] + (p_hi - p_lo)[:, None] * 0.5 * (xp[None, :] + 1.0)
        sin_t = np.sqrt(np.clip(1.0 - mu * mu, 0.0, 1.0))[:, :, None]
        mu3 = mu[:, :, None]
        phi = phi[:, None, :]
        w = np.stack(np.broadcast_arrays(sin_t * np.cos(phi), sin_t * np.sin(phi), mu3), axis=-1)
        weight = w_mu[:, :, None] * (0.5 * wp)[None, None, :]
        return w.reshape(len(cells), -1, 3), weight.reshape(len(cells), -1)

    def cell_average(self, func, n_theta: int = 4, n_phi: int = 4) -> np.ndarray:
        """cos(theta)-weighted average over each cell of ``func(w (M, 3)) -> (M,)``."""
        w, weight = self.cell_quadrature(n_theta, n_phi)
        values = func(w.reshape(-1, 3)).reshape(weight.shape)
        return np.sum(values * weight, axis=1)

