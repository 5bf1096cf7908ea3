"""Calibration of the standard errors: error bars are checked from below too.

The other physics tests bound |z| from above only, so standard errors inflated 4-16 x pass
them. Here the spread of z over many cells must match its reference distribution, in a
two-sided interval: errors too large fail as surely as errors too small.

Reference distribution. A table's standard error is the spread of R per-realization estimates
over sqrt(R) (microsim.run.reduction.Estimate: sample variance with R - 1 in the denominator, over R).
If the per-realization estimates are normal, z = (mean - exact) / stderr is Student-t with
nu = R - 1 degrees of freedom, not normal: its variance is nu / (nu - 2) (1.15 for R = 16), and
its sample variance over n cells is NOT chi2(n - 1) / (n - 1) (the t's heavy tails widen it). For
two independent tables of the same config (other seed), the true variances of a cell are equal,
so d = (a - b) / sqrt(sa^2 + sb^2) = N(0, 1) / sqrt(chi2(2 nu) / (2 nu)) is exactly Student-t
with 2 nu = 2 (R - 1) degrees of freedom.

The check (:func:`calibration`, the one code path of every assertion below) maps each z to its
normal score u = Phi^-1(F_t,nu(z)), which is then exactly N(0, 1). So, for n independent cells,
(n - 1) var(u) is exactly chi2(n - 1) and sqrt(n) mean(u) exactly N(0, 1); the check accepts
var(u) between the ALPHA and 1 - ALPHA quantiles of chi2(n - 1) / (n - 1) and
|mean(u)| <= Phi^-1(1 - ALPHA) / sqrt(n), ALPHA = 1e-4 in each tail: a false alarm rate of
about 4e-4 per check, with fixed seeds a deterministic outcome. The sample variance of z itself
and its expectation nu / (nu - 2) are reported alongside. Bounds from the analytic
transformation, not from a simulation of the reference distribution.

What the exact reference assumes, and how the runs below keep to it:

- normal per-realization estimates: the smallest cells (at the horizon, P_C / pi = 1e-3 to
  2e-3) get ~200-300 exits in total, the others more; an albedo sums 200 paths a realization;
- independent cells. On the plane cells share no geometry; only the fixed path count of a
  realization links them (and as the plane's albedo is exact, sum_C P_C f_C = albedo in every
  realization, which makes mean(u) LESS variable than N(0, 1 / n): there the mean bound is
  conservative). Sphere cells of one realization share its geometry, and on a small tile that
  correlation is strong: at tile 8, depth 3 (~16 spheres a realization, 3125 paths) the mean
  correlation of two cells across realizations was 0.21 (tr(C^2) / n = 31: the 400 cells of 4
  incidences were worth ~13 independent ones), enough to fail an independent-cell bound. On the
  128-radius tile used here (depth 8, ~11 000 spheres a realization) it is negligible, and a
  sphere run still takes 1-3 s on 2 workers;
- independent albedos. All incidences of a realization share its geometry, and the albedo, a
  sum over every cell, is dominated by it: at tile 32 with 3125 paths a realization, the
  albedos of two incidences correlated at 0.44 across realizations (about 0.03 at tile 64
  with 400 paths). So the albedo check has its own pair of runs of many realizations of few paths (128 x
  200 an incidence, 24 incidences), where path noise, independent between incidences, swamps
  the shared geometry noise.

Measured over many seeds of exactly these runs (same check), var(u) had the mean and spread of
chi2(n - 1) / (n - 1), to within their sampling errors:

    check           n    seeds   var(u): mean, sd (reference 1, sd)   sqrt(n) mean(u): mean, sd
    plane cells     796   200     1.004, 0.051 (0.050)                 -0.42, 0.33
    sphere cells    400    60     0.999, 0.079 (0.071)                 -0.10, 0.63
    sphere albedo    24   100     1.052, 0.317 (0.295)                 +0.01, 1.07

(sd of sqrt(n) mean(u) below 1 on cells: a path leaves through one cell only, which
anti-correlates the cells of a realization, so the mean bound is conservative there; the
plane's offset is the small negative skew of t for Poisson counts, 0.42 of its 3.7 bound.)

Each check is shown to fail: the same data with the standard errors multiplied by 4 and by 1/4
(and, for the cell checks, by 1.5 and 1/1.5, the resolution n = 400-800 cells give) is rejected.

The plane's albedo is not checked: every path leaves the plane with weight exactly albedo, so
albedo_stderr is 0 (test_plane.py checks that exactness), and so is the energy balance's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest
from scipy import stats

from microsim import tables
from microsim.testing import trace_table

pytestmark = pytest.mark.slow  # 1.3 M paths on the plane, 2 x 0.8 M and 2 x 0.6 M on spheres

ALPHA = 1e-4  # probability of each tail of the two-sided intervals


@dataclass(frozen=True)
class Calibration:
    """Spread and centre of n z-values against their exact reference (module docstring)."""

    n: int
    dof: float
    var_z: float  # sample variance of z (expected dof / (dof - 2))
    var_u: float  # sample variance of the normal scores u (exactly chi2(n - 1) / (n - 1))
    var_interval: tuple[float, float]
    mean_u: float
    mean_bound: float
    finite: bool

    @property
    def variance_ok(self) -> bool:
        return self.finite and self.var_interval[0] <= self.var_u <= self.var_interval[1]

    @property
    def ok(self) -> bool:
        return self.variance_ok and abs(self.mean_u) <= self.mean_bound

    def __str__(self) -> str:
        lo, hi = self.var_interval
        return (f"n={self.n} dof={self.dof:g}: var(z)={self.var_z:.4f} (expected {self.dof / (self.dof - 2):.4f}), "
                f"var(u)={self.var_u:.4f} in [{lo:.4f}, {hi:.4f}]?, mean(u)={self.mean_u:+.4f} "
                f"within +-{self.mean_bound:.4f}?")


def normal_scores(z: np.ndarray, dof: float) -> np.ndarray:
    """Phi^-1(F_t,dof(z)), computed from the tail nearest to z so that no precision is lost."""
    return np.sign(z) * stats.norm.isf(stats.t.sf(np.abs(z), dof))


def calibration(value, stderr, reference, reference_stderr, dof: float) -> Calibration:
    """z = (value - reference) / sqrt(stderr^2 + reference_stderr^2) against Student-t(dof)."""
    z = np.ravel((np.asarray(value) - reference) / np.hypot(stderr, reference_stderr))
    finite = bool(np.all(np.isfinite(z)))
    u = normal_scores(z, dof) if finite else np.full_like(z, np.nan)
    n = z.size
    interval = tuple(float(q) for q in stats.chi2.ppf([ALPHA, 1.0 - ALPHA], n - 1) / (n - 1))
    return Calibration(n, dof, float(np.var(z, ddof=1)), float(np.var(u, ddof=1)), interval, float(np.mean(u)),
                       float(stats.norm.isf(ALPHA) / math.sqrt(n)), finite)


def traced(tmp_path_factory, name: str, data: dict) -> tables.Table:
    """Validate, run on 2 workers, write the HDF5 table and read it back (what users get)."""
    return trace_table(data, tmp_path_factory.mktemp(name) / f"{name}.h5", workers=2)


# ---- the plane: exactly albedo / pi in every cell ----

PLANE_ALBEDO = 0.5
PLANE_REALIZATIONS = 16  # z is t with 15 dof: var(z) = 15 / 13 = 1.154, not 1


@pytest.fixture(scope="module")
def plane(tmp_path_factory):
    return traced(tmp_path_factory, "plane", {
        "scene": {"kind": "plane"},
        "material": {"kind": "lambert", "albedo": PLANE_ALBEDO},
        "illumination": {"theta_i_deg": [0.0, 30.0, 60.0, 85.0]},
        "sensor": {"cells": 200},  # 199 cells; the smallest gets ~300 exits in total, ~19 a realization
        "run": {"paths": 320_000, "realizations": PLANE_REALIZATIONS, "seed": 1},
    })


def plane_check(table, factor: float = 1.0) -> Calibration:
    return calibration(table.brdf, factor * table.brdf_stderr, PLANE_ALBEDO / np.pi, 0.0, PLANE_REALIZATIONS - 1)


# ---- Boolean spheres: two independent runs of one config ----

def spheres(seed: int, theta_deg: list, paths: int, realizations: int) -> dict:
    return {
        "scene": {"kind": "poisson_spheres", "volume_fraction": 0.3, "tile": 128.0, "depth": 8.0},
        "material": {"kind": "lambert", "albedo": 0.8},
        "illumination": {"theta_i_deg": theta_deg},
        "sensor": {"cells": 100},
        "run": {"paths": paths, "realizations": realizations, "seed": seed},
    }


# cells: 4 incidences x 100 cells, 32 realizations of 6250 paths (the smallest cell gets ~200 exits)
CELL_REALIZATIONS = 32
CELL_RUN = {"theta_deg": [0.0, 30.0, 60.0, 80.0], "paths": 200_000, "realizations": CELL_REALIZATIONS}
# albedo: 24 incidences, 128 realizations of 200 paths, so that the path noise, independent between
# incidences, swamps the geometry noise they share
ALBEDO_REALIZATIONS = 128
ALBEDO_RUN = {"theta_deg": np.linspace(0.0, 85.0, 24).tolist(), "paths": 25_600, "realizations": ALBEDO_REALIZATIONS}


@pytest.fixture(scope="module")
def sphere_cells(tmp_path_factory):
    return tuple(traced(tmp_path_factory, f"cells{seed}", spheres(seed, **CELL_RUN)) for seed in (31, 32))


@pytest.fixture(scope="module")
def sphere_albedo(tmp_path_factory):
    return tuple(traced(tmp_path_factory, f"albedo{seed}", spheres(seed, **ALBEDO_RUN)) for seed in (41, 42))


def sphere_cells_check(pair, factor: float = 1.0) -> Calibration:
    a, b = pair
    return calibration(a.brdf, factor * a.brdf_stderr, b.brdf, factor * b.brdf_stderr, 2 * (CELL_REALIZATIONS - 1))


def sphere_albedo_check(pair, factor: float = 1.0) -> Calibration:
    a, b = pair
    return calibration(a.albedo, factor * a.albedo_stderr, b.albedo, factor * b.albedo_stderr,
                       2 * (ALBEDO_REALIZATIONS - 1))


# ---- the checks ----

CHECKS = {  # name -> (fixture, check)
    "plane cells": ("plane", plane_check),
    "sphere cells": ("sphere_cells", sphere_cells_check),
    "sphere albedo": ("sphere_albedo", sphere_albedo_check),
}


@pytest.mark.parametrize("name", CHECKS)
def test_standard_errors_are_calibrated(name, request):
    fixture, check = CHECKS[name]
    result = check(request.getfixturevalue(fixture))
    assert result.ok, f"{name}: {result}"


def test_the_runs_are_the_intended_ones(plane, sphere_cells, sphere_albedo):
    """The data sets are as large as the docstring says, and no standard error is 0."""
    assert plane.brdf.shape == (4, 199) and np.all(plane.brdf_stderr > 0)
    for table in sphere_cells:
        assert table.brdf.shape == (4, 100) and np.all(table.brdf_stderr > 0)
    for table in sphere_albedo:
        assert table.albedo.shape == (24,) and np.all(table.albedo_stderr > 0)


MUST_REJECT = [(name, factor) for name in CHECKS for factor in (4.0, 0.25)] + [
    (name, factor) for name in ("plane cells", "sphere cells") for factor in (1.5, 1 / 1.5)]


@pytest.mark.parametrize("name, factor", MUST_REJECT, ids=[f"{n} x{f:.3g}" for n, f in MUST_REJECT])
def test_miscalibrated_standard_errors_are_rejected(name, factor, request):
    """The same data and the same check, with every standard error multiplied by ``factor``."""
    fixture, check = CHECKS[name]
    result = check(request.getfixturevalue(fixture), factor)
    assert not result.variance_ok, f"{name} with stderr x {factor:.3g} passed: {result}"
    assert not result.ok
