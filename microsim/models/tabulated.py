"""A table as a BRDF: f(wi, wo) at any pair of directions, and directions sampled from it.

A table holds, for each of its incidences, the cell averages f_C of the BRDF (conventions §2).
:class:`TabulatedBRDF` makes of them a function of any pair (wi, wo), the model ``table``:

- **Between incidences**: linear in cos(theta_i) between the two incidences whose polar angles
  bracket theta_i, held at the first and last beyond them; in an anisotropic table (incidences
  at several azimuths phi_i, evenly spaced, on a grid), linear in phi_i too, periodically. Each
  incidence is read at the same theta_o and relative azimuth phi_o - phi_i: a table's cells lie
  in the scene's frame, so an incidence at azimuth phi_k is read at phi_o - phi_i + phi_k. The
  normal incidence is read at phi_o itself, as traced, so that f is continuous at the pole.
- **Across cells**: the cell averages taken as the values at the cells' centres, linear in
  phi_o between the centres of a ring (periodically), then linear in theta_o between the two
  rings whose centres bracket theta_o (the polar cap's centre is the pole; beyond the last
  ring's centre, that ring). A convex combination of cell averages: continuous, and positive
  wherever they are.
- **Reciprocal**: f(wi, wo) = (F(wi, wo) + F(wo, wi)) / 2 of that interpolant F, exactly
  symmetric. A table of incidences at the sensor's ring centres (``illumination.incidences``)
  pairs each cell with its reciprocal one, read at a table incidence.

What it costs in accuracy (measured, docs/guide/tabulated.md): taking averages for the values
at centres errs by the BRDF's curvature over a cell (second order in the cell's width), and so
does the linear step between incidences, in their spacing; the symmetrizing averages the two.

Sampling (:meth:`TabulatedBRDF.sample`): one of the incidences that weigh on wi, drawn by its
weight; one of its cells, by its share of the incidence's albedo f_C P_C; a direction in the
cell with density proportional to cos(theta_o). :meth:`TabulatedBRDF.pdf` is that mixture's
density, per steradian.

To be evaluated, the table must cover the hemisphere (:meth:`TabulatedBRDF.require_full_brdf`):
polar angles whose cosines leave no gap wider than MAX_COS_GAP from 1 to 0, the ends included.
A table that does not is still one to compare with cell by cell (:func:`microsim.analysis.compare.compare_tables`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
from scipy import sparse

from microsim.core.files import not_a_file
from microsim.core.frames import direction
from microsim.core.table_noise import realization_scale, realizations
from microsim.models.base import BRDFModel, Param, register

#: pairs of directions evaluated at once (their coefficients take 0.5 kB a pair)
CHUNK = 65536
#: incidences whose polar angles (or azimuths) differ by less than this are one (radians)
SAME_ANGLE = 1e-9


class IncidenceGrid:
    """The incidences of a table as nodes of the interpolation: polar angles (their cosines,
    ``mu``, decreasing) times azimuths (``phi``, increasing in [0, 2 pi)); the normal incidence,
    if any, a node of every azimuth. ``index[k, j]`` is the table's incidence at polar node k
    and azimuth node j."""

    def __init__(self, theta_i: np.ndarray, phi_i: np.ndarray):
        theta = _distinct(theta_i)
        tilted = theta_i > SAME_ANGLE
        phi = _distinct(np.mod(phi_i[tilted], 2 * np.pi)) if tilted.any() else np.zeros(1)
        self.mu, self.phi = np.cos(theta), phi
        steps = np.diff(np.concatenate([phi, [phi[0] + 2 * np.pi]]))
        if phi.size > 1 and not np.allclose(steps, 2 * np.pi / phi.size, rtol=0, atol=1e-6):
            raise ValueError(f"incidences: azimuths {np.round(np.degrees(phi), 6).tolist()} deg are not evenly spaced; "
                             "a full BRDF's are 360 j / M (illumination.azimuths)")
        self.index = np.full((theta.size, phi.size), -1)
        for n, (t, p) in enumerate(zip(theta_i, np.mod(phi_i, 2 * np.pi))):
            k = int(np.argmin(np.abs(theta - t)))
            columns = range(phi.size) if t <= SAME_ANGLE else [int(np.argmin(_circular(phi - p)))]
            for j in columns:
                if self.index[k, j] < 0:
                    self.index[k, j] = n
        #: the table's normal incidence (theta_i = 0), a node of every azimuth, or None
        self.normal = int(self.index[0, 0]) if theta[0] <= SAME_ANGLE else None
        if np.any(self.index < 0):
            k, j = np.argwhere(self.index < 0)[0]
            raise ValueError(f"incidences: theta_i {np.degrees(theta[k]):g} deg has no incidence at phi_i "
                             f"{np.degrees(phi[j]):g} deg; a full BRDF needs every polar angle at every azimuth")

    @property
    def anisotropic(self) -> bool:
        return self.phi.size > 1

    def weights(self, mu: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(incidence, weight, azimuth), each (n, 4): the table incidences that weigh on each
        direction of cosine ``mu`` and azimuth ``phi``, their weights (summing to 1), and the
        azimuth each is read as lying at: its column's, so that it is read at the same relative
        azimuth; the normal incidence, ``phi`` itself, so that it is read in the scene's frame,
        as it was traced (the same from whatever azimuth wi nears the normal)."""
        m = self.mu[::-1]  # increasing
        upper = np.clip(np.searchsorted(m, mu), 1, max(m.size - 1, 1)) if m.size > 1 else np.zeros(mu.size, int)
        lower = np.maximum(upper - 1, 0)
        span = m[upper] - m[lower]
        t = np.clip(np.divide(mu - m[lower], span, out=np.zeros_like(mu), where=span > 0), 0.0, 1.0)
        k0, k1 = self.mu.size - 1 - lower, self.mu.size - 1 - upper
        n = self.phi.size
        if n == 1:
            j0 = j1 = np.zeros(mu.size, int)
            s = np.zeros_like(mu)
        else:
            step = 2 * np.pi / n
            u = np.mod(phi - self.phi[0], 2 * np.pi) / step
            j0 = np.floor(u).astype(int) % n
            j1, s = (j0 + 1) % n, u - np.floor(u)
        incidence = np.stack([self.index[k0, j0], self.index[k0, j1], self.index[k1, j0], self.index[k1, j1]], 1)
        weight = np.stack([(1 - t) * (1 - s), (1 - t) * s, t * (1 - s), t * s], 1)
        azimuth = self.phi[np.stack([j0, j1, j0, j1], 1)]
        if self.normal is not None:
            azimuth = np.where(incidence == self.normal, phi[:, None], azimuth)
        return incidence, weight, azimuth

    def gaps(self) -> tuple[float, float]:
        """(the widest gap in cos(theta_i), the cosine it starts from), the ends 1 and 0 included."""
        from microsim.config.full_brdf import widest_gap

        return widest_gap(self.mu)


def _distinct(values: np.ndarray) -> np.ndarray:
    """The distinct values, increasing (those within SAME_ANGLE of another taken as one)."""
    ordered = np.sort(values)
    return ordered[np.concatenate([[True], np.diff(ordered) > SAME_ANGLE])]


def _circular(delta: np.ndarray) -> np.ndarray:
    """|delta| as an angle: its distance from the nearest multiple of 2 pi."""
    return np.abs(np.mod(delta + np.pi, 2 * np.pi) - np.pi)


class CellInterpolant:
    """The cell averages of a sensor's cells as a continuous function of the direction (module
    doc: linear between the centres in phi_o within a ring, then in theta_o between rings)."""

    def __init__(self, sensor):
        self.centre = sensor.ring_centres()
        self.start, self.counts = sensor.ring_start[:-1].astype(int), np.asarray(sensor.ring_counts, int)

    def corners(self, theta: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(cell, weight), each (n, 4): the cells whose averages make the value at each direction."""
        rings = self.centre.size
        r0 = np.clip(np.searchsorted(self.centre, theta, side="right") - 1, 0, rings - 1)
        r1 = np.minimum(r0 + 1, rings - 1)
        span = self.centre[r1] - self.centre[r0]
        t = np.clip(np.divide(theta - self.centre[r0], span, out=np.zeros_like(theta), where=span > 0), 0.0, 1.0)
        cells, weights = [], []
        for ring, w_ring in ((r0, 1 - t), (r1, t)):
            n = self.counts[ring]
            u = np.mod(phi, 2 * np.pi) * n / (2 * np.pi)
            j0 = np.floor(u).astype(int) % n
            s = u - np.floor(u)
            cells += [self.start[ring] + j0, self.start[ring] + (j0 + 1) % n]
            weights += [w_ring * (1 - s), w_ring * s]
        return np.stack(cells, 1), np.stack(weights, 1)


class CellNoise(NamedTuple):
    """A tabulated BRDF averaged over another sensor's cells, one incidence
    (:meth:`TabulatedBRDF.cell_average_noise`), and its table's errors propagated to them."""

    averages: np.ndarray  #: (cells,)
    variance: np.ndarray  #: (cells,) of each average
    common: np.ndarray  #: (cells,) the part of it from the realizations' common scale
    covariance: object  #: sparse (cells, cells): the covariance of the averages' other part
    albedo_variance: float  #: of sum(averages * projected)
    albedo_common: float  #: the albedo's deviation for one standard deviation of the common scale


@dataclass(frozen=True)
class CellValues:
    """Cell averages made otherwise than by a run (a model's, for measuring the interpolation
    alone), to tabulate as a table's: ``brdf`` (incidences, cells) on ``sensor``'s cells, at the
    incidences ``theta_i``, ``phi_i`` (radians); ``path`` a label."""

    sensor: object
    theta_i: np.ndarray
    phi_i: np.ndarray
    brdf: np.ndarray
    path: str = "<cell values>"


@register
class TabulatedBRDF(BRDFModel):
    """The BRDF a microsim table holds (all orders), at any pair of directions: interpolated
    between its incidences in cos(theta_i) (and phi_i), across its cells linearly between their
    centres, and made reciprocal, f(wi, wo) = (F(wi, wo) + F(wo, wi)) / 2 (microsim.models.tabulated).
    The table needs incidences over the whole hemisphere: run it with illumination.incidences."""

    name = "table"
    params = (Param("path", "a microsim table (.h5) of a full BRDF", text=True),)
    reference = "microsim.models.tabulated: the table's cell averages, interpolated (docs/guide/tabulated.md)"

    def __init__(self, table=None, **values):
        """``table``: a loaded :class:`microsim.tables.Table` or :class:`CellValues`, or the path
        of a table (the parameter ``path``)."""
        self.table = None if table is None or isinstance(table, (str, Path)) else table
        if table is not None:
            values["path"] = str(table.path if self.table is not None else table)
        super().__init__(**values)

    def setup(self) -> None:
        if self.table is None:
            if why := not_a_file(self.path):
                raise ValueError(f"path = {self.path!r}: {why}")
            try:
                from microsim.tables import load

                self.table = load(self.path)
            except OSError as err:
                raise ValueError(f"path = {self.path!r}: not a microsim table ({err})") from None
        table = self.table
        self.sensor = table.sensor
        self.grid = IncidenceGrid(table.theta_i, table.phi_i)
        self.cells = CellInterpolant(self.sensor)
        self._noise_of_values = None
        self.f = np.maximum(table.brdf, 0.0)
        shares = self.f * self.sensor.projected_solid_angle()
        self.albedo = shares.sum(axis=1)
        self.cdf = np.cumsum(shares, axis=1) / np.where(self.albedo > 0, self.albedo, 1.0)[:, None]
        self.cdf[:, -1] = 1.0
        self.share = shares / np.where(self.albedo > 0, self.albedo, 1.0)[:, None]
        bounds = self.sensor.cell_bounds()
        self.cos2_lo, self.cos2_hi = np.cos(bounds[0]) ** 2, np.cos(bounds[1]) ** 2
        self.phi_lo, self.phi_hi = bounds[2], bounds[3]

    def require_full_brdf(self) -> None:
        """ValueError (one line) unless the table's incidences cover the hemisphere (MAX_COS_GAP):
        what every evaluation needs (a table may be compared cell by cell without it)."""
        from microsim.config.full_brdf import MAX_COS_GAP

        gap, start = self.grid.gaps()
        if gap > MAX_COS_GAP:
            raise ValueError(f"{self.path}: not a full BRDF: its incidences leave a gap of {gap:.3g} in "
                             f"cos theta_i from {start:.3g} (at most {MAX_COS_GAP:g}); trace it with "
                             "illumination.incidences")

    def _eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        self.require_full_brdf()
        out = np.empty(len(wi))
        for start in range(0, len(wi), CHUNK):  # 32 coefficients a pair: bounded memory
            entry, weight = self.coefficients(wi[start:start + CHUNK], wo[start:start + CHUNK])
            out[start:start + CHUNK] = np.sum(weight * self.f.reshape(-1)[entry], axis=1)
        return out

    def coefficients(self, wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """f(wi, wo) as a linear form of the table's values: (entry, weight), each (n, 32), f =
        sum(weight * brdf.flat[entry]) (entry = incidence x cells + cell). Directions above the
        horizon, (n, 3)."""
        forward, backward = self._linear_form(wi, wo), self._linear_form(wo, wi)
        return (np.concatenate([forward[0], backward[0]], axis=1),
                0.5 * np.concatenate([forward[1], backward[1]], axis=1))

    def interpolated(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """F(wi, wo), the interpolant before it is made reciprocal (module doc): at a table
        incidence and a cell's centre, that cell's value. Directions above the horizon, (n, 3)."""
        self.require_full_brdf()
        entry, weight = self._linear_form(np.asarray(wi, float).reshape(-1, 3), np.asarray(wo, float).reshape(-1, 3))
        return np.sum(weight * self.f.reshape(-1)[entry], axis=1)

    def _linear_form(self, wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The interpolant F(wi, wo) before it is made reciprocal (module doc), as (entry,
        weight), each (n, 16): 4 incidences x 4 cells."""
        mu_i, phi_i = _polar(wi)
        mu_o, phi_o = _polar(wo)
        incidence, weight, azimuth = self.grid.weights(mu_i, phi_i)
        theta_o, relative = np.arccos(mu_o), phi_o - phi_i
        cell, cell_weight = (np.stack(a, axis=1) for a in zip(  # each incidence's cells in its own frame
            *(self.cells.corners(theta_o, relative + azimuth[:, j]) for j in range(4))))
        entry = incidence[:, :, None] * self.sensor.n_cells + cell
        return entry.reshape(-1, 16), (weight[:, :, None] * cell_weight).reshape(-1, 16)

    def cell_average_noise(self, rule, projected) -> CellNoise:
        """The averages of f over the cells of a fixed quadrature ``rule``
        (:class:`microsim.analysis.averages.CellRule`, one incidence) and what the table's errors make of
        them (:class:`CellNoise`; the albedo: sum(averages * ``projected``)). The table's values are
        taken as independent but for the common scale of its realizations
        (:func:`microsim.core.table_noise.realization_scale`, every incidence's the same
        realizations'); a table of cell values has no errors."""
        self.require_full_brdf()
        form = sparse.csr_matrix((rule.n_cells, self.f.size))
        for start in range(0, len(rule.nodes), CHUNK):  # bounded memory, as _eval
            part = slice(start, start + CHUNK)
            entry, weight = self.coefficients(rule.wi[part], rule.nodes[part])
            rows = np.repeat(rule.cells[part], entry.shape[1])
            form = form + sparse.csr_matrix(((weight * rule.weights[part, None]).reshape(-1),
                                             (rows, entry.reshape(-1))), shape=form.shape)
        own, scale = self._noise()
        shared = form.multiply(np.sqrt(own)[None, :]).tocsr()
        covariance = shared @ shared.T
        common = (form @ (scale * self.f.reshape(-1))) ** 2
        albedo_form = form.T @ projected
        albedo_common = float(albedo_form @ (scale * self.f.reshape(-1)))
        return CellNoise(form @ self.f.reshape(-1), covariance.diagonal() + common, common, covariance,
                         float(albedo_form**2 @ own) + albedo_common**2, albedo_common)

    def _noise(self) -> tuple[np.ndarray, np.ndarray]:
        """(each table value's own variance, the square root of its realizations' common relative
        variance), flat as the entries of :meth:`coefficients`."""
        if self._noise_of_values is None:
            if isinstance(self.table, CellValues):
                self._noise_of_values = np.zeros(self.f.size), np.zeros(self.f.size)
            else:
                t, p = self.table, self.sensor.projected_solid_angle()
                g = realization_scale(t.brdf, t.brdf_stderr, t.albedo, t.albedo_stderr, p, t.paths, realizations(t))
                own = np.maximum(t.brdf_stderr**2 - g[:, None] * t.brdf**2, 0.0)
                self._noise_of_values = own.reshape(-1), np.repeat(np.sqrt(g), self.sensor.n_cells)
        return self._noise_of_values

    def pdf(self, wi, wo) -> np.ndarray:
        """The density of :meth:`sample`'s directions wo, per steradian, (n,); 0 below the horizon."""
        wi, wo = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wo, float))
        wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
        out = np.zeros(wi.shape[0])
        above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
        if not above.any():
            return out
        self.require_full_brdf()
        wi, wo = wi[above], wo[above]
        mu_i, phi_i = _polar(wi)
        incidence, weight, azimuth = self.grid.weights(mu_i, phi_i)
        projected = self.sensor.projected_solid_angle()
        density = np.zeros(len(wi))
        for j in range(4):  # the cell of wo in each incidence's own frame
            cell = self.sensor.lookup(_turned(wo, azimuth[:, j] - phi_i))
            density += weight[:, j] * self.share[incidence[:, j], cell] / projected[cell]
        out[above] = density * wo[:, 2]
        return out

    def sample(self, wi, sample1, sample2) -> tuple[np.ndarray, np.ndarray]:
        """Directions wo (n, 3) drawn for incidences ``wi`` (n, 3) from uniform numbers
        ``sample1`` (n,) and ``sample2`` (n, 2), and their pdf (module doc). An incidence whose
        table incidences reflect nothing gets wo = (0, 0, 0) and pdf 0."""
        self.require_full_brdf()
        wi = np.asarray(wi, float).reshape(-1, 3)
        sample1, sample2 = np.asarray(sample1, float).reshape(-1), np.asarray(sample2, float).reshape(-1, 2)
        mu_i, phi_i = _polar(wi)
        incidence, weight, azimuth = self.grid.weights(mu_i, phi_i)
        edges = np.cumsum(weight, axis=1)
        pick = np.minimum(np.sum(sample1[:, None] >= edges, axis=1), 3)
        chosen = incidence[np.arange(len(wi)), pick]
        turn = phi_i - azimuth[np.arange(len(wi)), pick]
        w = weight[np.arange(len(wi)), pick]
        before = edges[np.arange(len(wi)), pick] - w
        u = np.clip((sample1 - before) / np.where(w > 0, w, 1.0), 0.0, np.nextafter(1.0, 0.0))
        cell = self._cells(chosen, u)
        cos2 = self.cos2_hi[cell] + sample2[:, 0] * (self.cos2_lo[cell] - self.cos2_hi[cell])
        phi = self.phi_lo[cell] + sample2[:, 1] * (self.phi_hi[cell] - self.phi_lo[cell]) + turn
        wo = direction(np.arccos(np.sqrt(np.clip(cos2, 0.0, 1.0))), phi).reshape(-1, 3)
        pdf = self.pdf(wi, wo)
        dark = (self.albedo[chosen] <= 0) | (wi[:, 2] <= 0)
        wo[dark], pdf[dark] = 0.0, 0.0
        return wo, pdf

    def _cells(self, chosen: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The cell of each uniform number ``u`` in the cell distribution of incidence ``chosen``."""
        cell = np.empty(u.size, int)
        for k in np.unique(chosen):
            mine = chosen == k
            cell[mine] = np.searchsorted(self.cdf[k], u[mine], side="right")
        return np.minimum(cell, self.sensor.n_cells - 1)


def _polar(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(cos theta, phi) of unit vectors (n, 3)."""
    return np.clip(w[:, 2], -1.0, 1.0), np.arctan2(w[:, 1], w[:, 0])


def _turned(w: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """``w`` (n, 3) turned about the normal by ``angle`` (n,)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * w[:, 0] - s * w[:, 1], s * w[:, 0] + c * w[:, 1], w[:, 2]], 1)
