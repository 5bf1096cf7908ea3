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

Retro rings (optional, ``[sensor] retro_rings``): a second, finer tally of the exits near the
retro direction wi, for the opposition peak. Ring b holds the directions whose chord to wi,
|wo - wi| = 2 sin(gamma / 2) (gamma the phase angle), lies in [b, b + 1) times a fixed step, out
to ``retro_max_deg``: rings of nearly equal width in gamma, found with one square root. Their
f is the cos(theta_o)-weighted mean of the BRDF over the part of the ring above the horizon,
like a cell's.

Points (optional, ``[sensor] directions_deg`` and ``retro_points_deg``): exact directions at
which next-event estimation (:mod:`microsim.tracer.estimators.points`) reads f, not cells. A direction
is (theta_o, phi_o) with phi_o the relative azimuth (conventions §1): phi_i + phi_o in the
scene's frame. A retro point at phase angle gamma is the retro direction wi turned by gamma
towards the normal, in the plane of incidence: theta_o = theta_i - gamma on the side of the
light, and past the normal (on the specular side) where gamma > theta_i. The sensor holds them
as given (``point_spec``) and, once turned :meth:`toward` an incidence, as unit vectors
(``points``) that the kernels read.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from microsim.core.frames import direction

#: most points (directions and retro points together) a run reads f at: each costs a shadow ray
#: per scattering event
MAX_POINTS = 256
#: kinds of point (``Sensor.point_spec``): a direction (theta_o, relative phi_o), a retro point (gamma)
DIRECTION_POINT, RETRO_POINT = 0.0, 1.0


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
    #: retro rings: (wi_x, wi_y, wi_z, chord step, ring count); no rings by default (see the module doc)
    retro: np.ndarray = np.array([0.0, 0.0, 1.0, 1.0, 0.0])
    #: points (see the module doc), one row each: (DIRECTION_POINT, theta_o, phi_o) or
    #: (RETRO_POINT, gamma, 0), radians; none by default
    point_spec: np.ndarray = np.zeros((0, 3))
    #: the points' unit vectors about the incidence of :meth:`toward` (before it: about the zenith)
    points: np.ndarray = np.zeros((0, 3))

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

    def with_retro_rings(self, rings: int, max_deg: float) -> "Sensor":
        """This sensor with ``rings`` retro rings out to a phase angle of ``max_deg`` (0: none)."""
        step = 2.0 * math.sin(math.radians(max_deg) / 2.0) / max(rings, 1)
        return self._replace(retro=np.array([0.0, 0.0, 1.0, step, float(rings)]))

    def with_points(self, directions_deg=(), retro_points_deg=()) -> "Sensor":
        """This sensor with the points (module doc) ``directions_deg`` ([theta_o, phi_o] pairs) and
        ``retro_points_deg`` (phase angles gamma), in that order, degrees."""
        spec = [(DIRECTION_POINT, math.radians(t), math.radians(p)) for t, p in directions_deg]
        spec += [(RETRO_POINT, math.radians(g), 0.0) for g in retro_points_deg]
        spec = np.array(spec, np.float64).reshape(-1, 3)
        return self._replace(point_spec=spec, points=self.point_directions(np.array([0.0, 0.0, 1.0]), 0.0, spec))

    def toward(self, wi: np.ndarray, phi_i: float | None = None) -> "Sensor":
        """This sensor with its retro rings centred on the incidence direction wi and its points
        turned about it; ``phi_i``, the incidence's azimuth, defines the plane of incidence where
        wi is the normal (else it is wi's own)."""
        return self._replace(retro=np.array([wi[0], wi[1], wi[2], self.retro[3], self.retro[4]]),
                             points=self.point_directions(wi, phi_i))

    @property
    def n_points(self) -> int:
        return len(self.point_spec)

    def point_directions(self, wi: np.ndarray, phi_i: float | None = None, spec=None) -> np.ndarray:
        """Unit vectors (n_points, 3) of the points about the incidence wi (module doc); ``phi_i``
        as :meth:`toward` takes it."""
        spec = self.point_spec if spec is None else spec
        wi = np.asarray(wi, np.float64)
        theta_i, phi_i = math.acos(min(max(float(wi[2]), -1.0), 1.0)), _azimuth(wi, phi_i)
        theta, phi = spec[:, 1].copy(), phi_i + spec[:, 2]
        retro = spec[:, 0] == RETRO_POINT
        turned = theta_i - spec[retro, 1]  # negative: past the normal, on the specular side
        theta[retro], phi[retro] = np.abs(turned), np.where(turned >= 0.0, phi_i, phi_i + math.pi)
        return direction(theta, phi).reshape(-1, 3)

    def point_angles(self, wi: np.ndarray, phi_i: float | None = None):
        """(theta_o, relative phi_o in [0, 2 pi), phase angle gamma from wi) of every point about
        the incidence wi, radians."""
        w = self.point_directions(wi, phi_i)
        wi = np.asarray(wi, np.float64)
        relative = np.remainder(np.arctan2(w[:, 1], w[:, 0]) - _azimuth(wi, phi_i), 2.0 * math.pi)
        relative[relative > 2.0 * math.pi - 1e-12] = 0.0  # -0 by rounding
        relative[(w[:, 0] == 0.0) & (w[:, 1] == 0.0)] = 0.0
        gamma = 2.0 * np.arcsin(np.clip(np.linalg.norm(w - wi, axis=1) / 2.0, 0.0, 1.0))
        return np.arccos(np.clip(w[:, 2], -1.0, 1.0)), relative, gamma

    @property
    def retro_rings(self) -> int:
        return int(self.retro[4])

    @property
    def tally_width(self) -> int:
        """Bins of an exit tally: the cells, then the retro rings."""
        return self.n_cells + self.retro_rings

    def retro_phase_bounds(self):
        """(gamma_lo, gamma_hi) of every retro ring, radians."""
        chord = self.retro[3] * np.arange(self.retro_rings + 1)
        gamma = 2.0 * np.arcsin(np.clip(chord / 2.0, 0.0, 1.0))
        return gamma[:-1], gamma[1:]

    def _retro_arcs(self, wi: np.ndarray, nodes: int):
        """Gauss-Legendre nodes in cos(gamma) over every retro ring about wi, and the visible arc
        at each: cos(theta_o) = mu_i cos(gamma) + s sin(gamma) cos(psi) (s = sin theta_i, psi the
        azimuth about wi from its plane of incidence) is positive for |psi| < arc. Returns
        (cos_gamma, sin_gamma, node weights in cos(gamma), arc), each (n_r, nodes)."""
        lo, hi = self.retro_phase_bounds()
        x, w = np.polynomial.legendre.leggauss(nodes)
        c_lo, c_hi = np.cos(lo)[:, None], np.cos(hi)[:, None]
        cos_g = c_hi + (c_lo - c_hi) * 0.5 * (x + 1.0)
        sin_g = np.sqrt(np.clip(1.0 - cos_g**2, 0.0, 1.0))
        mu_i = float(wi[2])
        a, b = mu_i * cos_g, math.sqrt(max(1.0 - mu_i * mu_i, 0.0)) * sin_g
        ratio = np.divide(-a, b, out=np.where(a >= 0, -np.inf, np.inf), where=b > 0)
        return cos_g, sin_g, 0.5 * (c_lo - c_hi) * w, np.arccos(np.clip(ratio, -1.0, 1.0))

    def retro_ring_quadrature(self, wi: np.ndarray, n_gamma: int = 8, n_psi: int = 32):
        """Nodes and weights averaging a function over every retro ring about wi with the
        cos(theta_o) weight, as :meth:`cell_quadrature` does over cells: ``(w (n_r, M, 3),
        weight (n_r, M))``. Gauss-Legendre in cos(gamma) and, at each, in psi over the arc
        above the horizon (all of it for a ring that the horizon does not cut)."""
        wi = np.asarray(wi, np.float64)
        cos_g, sin_g, w_g, arc = self._retro_arcs(wi, n_gamma)
        xp, wp = np.polynomial.legendre.leggauss(n_psi)
        psi = arc[:, :, None] * xp  # (n_r, n_gamma, n_psi)
        mu_i = wi[2]
        tangent = math.sqrt(max(1.0 - mu_i * mu_i, 0.0))
        # u: unit vector normal to wi in its plane of incidence, pointing up; v = wi x u
        u = np.array([-wi[0] * mu_i, -wi[1] * mu_i, tangent * tangent]) / tangent if tangent > 0 else np.array([1.0, 0, 0])
        v = np.cross(wi, u)
        cg, sg = cos_g[:, :, None, None], sin_g[:, :, None, None]
        w = cg * wi + sg * (np.cos(psi)[..., None] * u + np.sin(psi)[..., None] * v)
        weight = (w_g[:, :, None] * arc[:, :, None] * wp) * np.clip(w[..., 2], 0.0, None)
        weight /= np.maximum(weight.sum(axis=(1, 2), keepdims=True), 1e-300)
        return w.reshape(len(w), -1, 3), weight.reshape(len(w), -1)

    def retro_projected_solid_angle(self, wi: np.ndarray, nodes: int = 64) -> np.ndarray:
        """Integral of max(cos theta_o, 0) d(omega) over every retro ring about wi: exact in psi
        (2 (mu_i cos(gamma) arc + s sin(gamma) sin(arc))), Gauss-Legendre in cos(gamma); pi mu_i
        (cos^2 lo - cos^2 hi) for a ring the horizon does not cut."""
        cos_g, sin_g, w_g, arc = self._retro_arcs(np.asarray(wi, np.float64), nodes)
        mu_i = float(wi[2])
        s = math.sqrt(max(1.0 - mu_i * mu_i, 0.0))
        return np.sum(2.0 * (mu_i * cos_g * arc + s * sin_g * np.sin(arc)) * w_g, axis=1)

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


def _azimuth(wi: np.ndarray, phi_i: float | None) -> float:
    """The incidence's azimuth: ``phi_i`` if given, else wi's own (0 where wi is the normal)."""
    if phi_i is not None:
        return float(phi_i)
    return math.atan2(wi[1], wi[0]) if wi[0] or wi[1] else 0.0
