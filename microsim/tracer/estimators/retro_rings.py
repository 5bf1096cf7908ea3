"""Retro rings: a second, finer binning of the exits near the retro direction wi, for the opposition peak.

Ring b about the incidence wi holds the directions whose chord to wi, |wo - wi| = 2 sin(gamma / 2)
(gamma the phase angle), lies in [b, b + 1) times a fixed step, out to ``[sensor]
retro_max_deg``: rings of nearly equal width in gamma, found with one square root. A path
leaving along d with weight w adds w / (N x the ring's projected solid angle about wi) to the
ring's f, by scattering order, as a cell's (:mod:`.exit_bins`; a path may count in a cell and a
ring): f is the cos(theta_o)-weighted mean of the BRDF over the part of the ring above the
horizon. Keys ``[sensor] retro_rings`` (0: none) and ``retro_max_deg``; datasets ``brdf_retro``,
``brdf_retro_order`` with their standard errors and the rings' bounds and projected solid
angles; ``compare --retro`` and ``fit --retro`` judge them (:mod:`microsim.analysis.judge_retro`).
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np
from pydantic import Field

from microsim.core.orders import ORDERS
from microsim.core.schema import Section
from microsim.core.table_layout import Dataset
from microsim.tracer.estimators import Estimator

WHEN = "sensor.retro_rings > 0"


class RetroRingsKeys(Section):
    """The retro rings' keys of ``[sensor]``."""

    retro_rings: int = Field(0, ge=0, le=100_000, description="rings about the retro direction, tallied "
                             "apart from the cells (0: none); see microsim.tracer.estimators.retro_rings")
    retro_max_deg: float = Field(10.0, gt=0.0, le=90.0, description="phase angle the retro rings reach, deg")


class RetroRings(NamedTuple):
    """The rings' layout: ``count`` rings of chord width ``step`` (module doc)."""

    count: int
    step: float

    @classmethod
    def reaching(cls, count: int, max_deg: float) -> "RetroRings":
        """``count`` rings out to a phase angle of ``max_deg``."""
        return cls(int(count), 2.0 * math.sin(math.radians(max_deg) / 2.0) / max(count, 1))

    def about(self, wi: np.ndarray) -> np.ndarray:
        """What the kernels read (:func:`microsim.tracer.sensor_kernels.retro_ring`): (wi_x, wi_y,
        wi_z, chord step, ring count)."""
        return np.array([wi[0], wi[1], wi[2], self.step, float(self.count)])

    def phase_bounds(self):
        """(gamma_lo, gamma_hi) of every ring, radians."""
        chord = self.step * np.arange(self.count + 1)
        gamma = 2.0 * np.arcsin(np.clip(chord / 2.0, 0.0, 1.0))
        return gamma[:-1], gamma[1:]

    def _arcs(self, wi: np.ndarray, nodes: int):
        """Gauss-Legendre nodes in cos(gamma) over every ring about wi, and the visible arc at
        each: cos(theta_o) = mu_i cos(gamma) + s sin(gamma) cos(psi) (s = sin theta_i, psi the
        azimuth about wi from its plane of incidence) is positive for |psi| < arc. Returns
        (cos_gamma, sin_gamma, node weights in cos(gamma), arc), each (n_r, nodes)."""
        lo, hi = self.phase_bounds()
        x, w = np.polynomial.legendre.leggauss(nodes)
        c_lo, c_hi = np.cos(lo)[:, None], np.cos(hi)[:, None]
        cos_g = c_hi + (c_lo - c_hi) * 0.5 * (x + 1.0)
        sin_g = np.sqrt(np.clip(1.0 - cos_g**2, 0.0, 1.0))
        mu_i = float(wi[2])
        a, b = mu_i * cos_g, math.sqrt(max(1.0 - mu_i * mu_i, 0.0)) * sin_g
        ratio = np.divide(-a, b, out=np.where(a >= 0, -np.inf, np.inf), where=b > 0)
        return cos_g, sin_g, 0.5 * (c_lo - c_hi) * w, np.arccos(np.clip(ratio, -1.0, 1.0))

    def quadrature(self, wi: np.ndarray, n_gamma: int = 8, n_psi: int = 32):
        """Nodes and weights averaging a function over every ring about wi with the cos(theta_o)
        weight, as :meth:`microsim.tracer.sensor.Sensor.cell_quadrature` does over cells:
        ``(w (n_r, M, 3), weight (n_r, M))``. Gauss-Legendre in cos(gamma) and, at each, in psi
        over the arc above the horizon (all of it for a ring that the horizon does not cut)."""
        wi = np.asarray(wi, np.float64)
        cos_g, sin_g, w_g, arc = self._arcs(wi, n_gamma)
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

    def projected_solid_angle(self, wi: np.ndarray, nodes: int = 64) -> np.ndarray:
        """Integral of max(cos theta_o, 0) d(omega) over every ring about wi: exact in psi
        (2 (mu_i cos(gamma) arc + s sin(gamma) sin(arc))), Gauss-Legendre in cos(gamma); pi mu_i
        (cos^2 lo - cos^2 hi) for a ring the horizon does not cut."""
        cos_g, sin_g, w_g, arc = self._arcs(np.asarray(wi, np.float64), nodes)
        mu_i = float(wi[2])
        s = math.sqrt(max(1.0 - mu_i * mu_i, 0.0))
        return np.sum(2.0 * (mu_i * cos_g * arc + s * sin_g * np.sin(arc)) * w_g, axis=1)


class RetroRingsTally(NamedTuple):
    """Exit weights near retro (rows: the orders 1, 2, 3, 4+; columns: the rings)."""

    weight: np.ndarray


class RetroRingBins(Estimator):
    """The retro rings' binning (module doc): datasets brdf_retro*."""

    name = "retro_rings"
    Record = RetroRingsTally
    HOOKS = "microsim.tracer.estimators.retro_rings_hooks"
    KEYS = RetroRingsKeys
    JUDGE = "microsim.analysis.judge_retro:RETRO"
    DATASETS = tuple(
        dataset
        for name, axes, doc in (
            ("brdf_retro", ("incidences", "retro_rings"), "f averaged (cos-weighted) over each ring about the retro "
             "direction, all orders"),
            ("brdf_retro_order", ("incidences", "orders", "retro_rings"), "brdf_retro by order"),
        )
        for dataset in (
            Dataset(name, axes, "1/sr", doc, when=WHEN, required=False),
            Dataset(f"{name}_stderr", axes, "1/sr", f"standard error of {name}, from the spread of the realizations",
                    when=WHEN, required=False),
        )
    ) + (
        Dataset("sensor/retro_gamma_lo", ("retro_rings",), "rad", "lower phase-angle bound of each retro ring "
                "(widths nearly equal, uniform in the chord 2 sin(gamma / 2))", when=WHEN),
        Dataset("sensor/retro_gamma_hi", ("retro_rings",), "rad", "upper phase-angle bound of each retro ring",
                when=WHEN),
        Dataset("sensor/retro_projected_solid_angle", ("incidences", "retro_rings"), "sr",
                "projected solid angle of each retro ring about each incidence (rings the horizon cuts included)",
                when=WHEN),
    )

    @classmethod
    def wanted(cls, config) -> bool:
        """Every run: its hook is compiled into every tracer, so that a run with rings takes the
        kernel a run without them compiled (as the points do, :class:`.points.Points`); without
        rings it bins nothing and writes nothing."""
        return True

    @functools.cached_property
    def rings(self) -> RetroRings:
        """The rings its keys ask for."""
        return RetroRings.reaching(self.keys.retro_rings, self.keys.retro_max_deg)

    def setup(self, wi, phi_i):
        return self.rings.about(wi)

    def shapes(self):
        return ((ORDERS, self.rings.count),)

    def reduce(self, fields, paths, incidence):
        if not self.rings.count:
            return {}
        per_path = fields.weight / paths
        rings = np.vstack([per_path, per_path.sum(axis=0)])
        projected = self.projected_solid_angle[incidence]
        return {"brdf_retro": np.divide(rings, projected, out=np.zeros_like(rings), where=projected > 0)}

    def estimate_values(self):
        return (ORDERS + 1) * self.rings.count

    @functools.cached_property
    def projected_solid_angle(self) -> list[np.ndarray]:
        """Per incidence of the run, the projected solid angles of the rings about it."""
        return [self.rings.projected_solid_angle(self.plan.incidence_direction(i))
                for i in range(self.plan.n_incidences)]

    def write(self, put, estimates):
        if not self.rings.count:
            return
        for name, bounds in zip(("retro_gamma_lo", "retro_gamma_hi"), self.rings.phase_bounds()):
            put(f"sensor/{name}", bounds)
        put("sensor/retro_projected_solid_angle", np.stack(self.projected_solid_angle))
        for suffix, row in (("", ORDERS), ("_order", slice(0, ORDERS))):
            put(f"brdf_retro{suffix}", np.stack([e.mean[row] for e in estimates["brdf_retro"]]))
            put(f"brdf_retro{suffix}_stderr", np.stack([e.stderr[row] for e in estimates["brdf_retro"]]))
