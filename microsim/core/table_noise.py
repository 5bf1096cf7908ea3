"""The noise of a table's cells: what their standard errors, the paths and the realizations
imply, shared by ``compare`` (chi-square per cell and its bounds) and ``fit`` (weights and
errors).

A cell's estimate f_C = (sum of the weights of the paths that exit into C) / (N paths x P_C,
its projected solid angle) has, from the paths, variance f_C E[w^2] / (E[w] N P_C) =
k f_C / P_C: the dispersion k = E[w^2] / (N E[w]) is one number per incidence, pooled over its
cells with signal as sum(stderr_C^2 P_C) / sum(f_C) (a ratio of sums, nearly free of any one
cell's noise; :func:`variance_model`). A path exits into one cell, so the cells of an incidence
are tied (:func:`path_covariance`); in a random scene its realizations differ, and a denser one
brightens every cell: a common relative scale of variance g (:func:`realization_scale`).

If a model's cell averages m_C were the table's BRDF, cell C would have variance
v_C = k' max(m_C, floor) / P_C + g m_C^2 (:func:`predicted_variance`), k' = k less the share of
the realizations, and the floor VARIANCE_FLOOR of the incidence's mean value (a model of zero
in a cell with signal would otherwise weigh without limit). Weighing each cell by its own
estimated error instead runs high at few paths a cell, as a cell that fluctuated low also gets
a small error (measurements: docs/developer/performance.md, section 'Fits and chi-square:
weights, covariance and cells').

Chi-square per cell of an exact model, (1/N) sum_C (m_C - f_C)^2 / v_C, is 1 in expectation.
Its variance (:func:`chi2_bounds`) is [sum_C (1 - a_C)^2 (2 + kappa_C) + 4 sum_C a_C (1 - a_C)] /
N^2 + 2 (mean a_C)^2, with a_C = g m_C^2 / v_C the realizations' share of a cell's variance and
kappa_C the excess kurtosis of its paths' share, 1 / (the paths' worth max(m_C, floor) P_C / k'):
the paths' part is independent from cell to cell (their tie through a path's one exit is left
out), the realizations' part one common number. The bounds are the two-sided CHI2_OUTSIDE points
of the gamma distribution of mean 1 and that variance.

The retro rings are bins that the same paths exit into: their variance is predicted from the
cells' dispersion (``predicted_variance(..., at=)``). The points of next-event estimation are
not bins, and nothing predicts theirs: a point is judged by its own standard error, whose
randomness (R realizations) :func:`normal_squares` takes into account, or, where the table holds
the covariance of its points' errors (estimated from the same R realizations), the points of an
incidence together by Hotelling's T^2 (:func:`hotelling`).

Hotelling's T^2 = d^T C^+ d of the deviations d of an incidence's points, C the covariance of
their mean: taken in the eigenbasis of C, along the K directions whose eigenvalue exceeds
``KEPT_ROUNDING`` times the rounding of C, (R - K) / (K (R - 1)) T^2 follows F(K, R - K) if the
realizations are normal and the model is their mean. The other directions are relations
between the points (exact ones: on a Lambertian facet seen by every point, or at two points of
one theta_o in a medium's order 1) or their noise is below what C resolves; along each the
deviation must lie within ``DROPPED_LIMIT`` standard errors of the largest variance a dropped
direction can have, KEPT_ROUNDING times the rounding, plus a rounding floor of the values. The
rounding of C (:func:`covariance_rounding`) is eps |f|^2 / R: C is the sums of the
realizations' products less the product of their sums, over R (R - 1), and the cancellation
leaves that much (the negative eigenvalues of a half space's covariances lie within it:
docs/validation/statistics.md, 'Points'). A fixed fraction of the largest eigenvalue (1e-9, as tests/test_points.py
takes) does not do: the eigenvalues of a half space's points at order 1 fall geometrically
(8 points: 1, 6e-2, 5e-3, 1e-4, 4e-6, 8e-8, 2e-10, then the rounding), and the noise
directions under 1e-9, judged by their own estimated errors, reject an exact model far more
often than their level: along the smallest of a sample covariance's eigenvectors the mean
deviates by more than the eigenvalue says (docs/validation/statistics.md, 'Points'), which
Hotelling's F distribution holds but a direction judged alone does not. With as many points as
realizations or more (n >= R) there is no test: the covariance of R realizations has rank
R - 1 at most, and a direction they did not sample
would pass for an exact relation; the caller falls back to the bounds of :func:`normal_squares`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: a cell's predicted variance is at least that of a cell this fraction of its incidence's mean value
VARIANCE_FLOOR = 1e-3
#: two-sided probability outside the bounds of chi-square per cell, for an exact model
CHI2_OUTSIDE = 0.01
#: eigenvalues of a covariance of points under this many times its rounding are dropped (module doc)
KEPT_ROUNDING = 10.0
#: along a dropped direction, the deviation must lie within this many of its standard errors (module doc)
DROPPED_LIMIT = 5.0


def variance_model(sim, stderr, signal, projected) -> tuple[np.ndarray, np.ndarray]:
    """(k, floor), each (n_i,): the dispersion of each incidence's paths, pooled over its cells
    with signal as sum(stderr_C^2 P_C) / sum(f_C), and VARIANCE_FLOOR x their mean value. If the
    table's BRDF were m_C, cell C would have variance k max(m_C, floor) / P_C (the realizations'
    share included in k, as an average: :func:`predicted_variance` takes it apart)."""
    total = _over_signal(sim, signal)
    count = np.maximum(signal.sum(axis=1), 1)
    return _over_signal(stderr**2 * projected, signal) / _positive(total), VARIANCE_FLOOR * total / count


def _over_signal(values, signal) -> np.ndarray:
    """(n_i,) sums of ``values`` over each incidence's cells with signal."""
    return np.sum(np.where(signal, values, 0.0), axis=1)


def _positive(values) -> np.ndarray:
    """``values`` with zeros (an incidence without a cell of signal) taken as 1: a ratio of 0."""
    return np.where(values > 0, values, 1.0)


def predicted_variance(model_values, sim, stderr, signal, projected, scale, at=None) -> tuple[np.ndarray, ...]:
    """(variance v_C, the paths' excess kurtosis kappa_C, the realizations' share a_C), each
    (n_i, n_c), of every cell's estimate if the table's BRDF were ``model_values`` (module doc);
    ``scale``: :func:`realization_scale` of each incidence. The paths' dispersion k' is the pooled
    k less what the realizations add to it, g sum(f_C^2 P_C) / sum(f_C) (at least
    VARIANCE_FLOOR of k). ``at``: (n_i, n) projected solid angles of other bins that the same
    paths exit into (the retro rings), whose ``model_values`` these are instead of the cells'
    (a bin of projected solid angle 0 has no paths' share)."""
    dispersion, floor = variance_model(sim, stderr, signal, projected)
    shared = scale * _over_signal(sim**2 * projected, signal) / _positive(_over_signal(sim, signal))
    own = np.maximum(dispersion - shared, VARIANCE_FLOOR * dispersion)
    at = np.broadcast_to(projected, model_values.shape) if at is None else at
    per_path = np.divide(own[:, None], at, out=np.zeros(model_values.shape), where=at > 0)
    floored = np.maximum(model_values, floor[:, None])
    common = scale[:, None] * model_values**2
    variance = per_path * floored + common
    # an incidence without a cell of signal has no dispersion: its cells have no variance, and no share
    kurtosis = np.divide(per_path, floored, out=np.zeros_like(variance), where=floored > 0)
    return variance, kurtosis, np.divide(common, variance, out=np.zeros_like(variance), where=variance > 0)


def realizations(table) -> int:
    """The realizations a table's standard errors come from (2 in a table that does not say)."""
    return int(table.attrs.get("realizations", 2))


def independent_sum(*parts) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(variance, excess kurtosis of the paths' part, realizations' share) of the difference of
    independent estimates, each given as :func:`predicted_variance` gives it (two tables, or a
    table and a tabulated BRDF): the variances add, the paths' parts' fourth cumulants add, and
    the realizations' common scales add into one (a sum of independent normal scales common to
    every cell is one such scale, exactly so where their ratio is the same in every cell)."""
    variance = sum(v for v, _, _ in parts)
    paths = [v * (1 - c) for v, _, c in parts]
    path_total = sum(paths)
    kurtosis = np.divide(sum(k * p**2 for (_, k, _), p in zip(parts, paths)), path_total**2,
                         out=np.zeros_like(variance), where=path_total > 0)
    common = np.divide(sum(v * c for v, _, c in parts), variance, out=np.zeros_like(variance), where=variance > 0)
    return variance, kurtosis, common


def correlated_pairs(covariance, variance: np.ndarray, signal: np.ndarray) -> float:
    """The sum over pairs of distinct cells with ``signal`` of (covariance / sqrt(v v'))^2, for
    :func:`chi2_bounds`: ``covariance`` (a sparse matrix over the cells) of a part of their
    errors, ``variance`` their whole variance."""
    chosen = np.flatnonzero(signal & (variance > 0))
    part = covariance.tocsr()[chosen][:, chosen].tocoo()
    off = part.row != part.col
    scaled = part.data[off] / np.sqrt(variance[chosen][part.row[off]] * variance[chosen][part.col[off]])
    return float(np.sum(scaled**2))


def chi2_bounds(kurtosis: np.ndarray, common: np.ndarray, correlated: float = 0.0) -> tuple[float, float]:
    """Two-sided CHI2_OUTSIDE bounds of chi-square per cell for an exact model over cells of
    these excess kurtoses of the paths' part and realizations' shares (:func:`predicted_variance`):
    the gamma distribution of mean 1 and their variance (module doc). ``correlated``: the sum over
    pairs of distinct cells of their errors' squared correlation beyond the common scale (0 for
    one table's cells; a tabulated BRDF's cells share its table's values), which adds
    2 ``correlated`` / n^2 to the variance (normal errors: Var sum z^2 = 2 sum rho^2)."""
    from scipy.stats import gamma

    n = kurtosis.size
    if n == 0:
        return float("nan"), float("nan")
    variance = (np.sum((1 - common) ** 2 * (2 + kurtosis)) + 2 * correlated + 4 * np.sum(common * (1 - common))) \
        / n**2 + 2 * float(np.mean(common)) ** 2
    shape = 1.0 / variance
    low, high = gamma.ppf([CHI2_OUTSIDE / 2, 1 - CHI2_OUTSIDE / 2], shape, scale=1.0 / shape)
    return float(low), float(high)


def normal_squares(z, realizations: int) -> np.ndarray:
    """Squares of the standard normal numbers of the same tail probabilities as ``z``, each a
    difference over a standard error from ``realizations`` realizations: Student's t of
    realizations - 1 degrees of freedom if the difference has mean 0 (exact for normal
    realizations, whatever their number). Their mean over n values is 1 in expectation, and for
    independent ones chi-square of n degrees of freedom over n (:func:`chi2_bounds` with
    kurtoses and shares 0; of one common error, shares 1: one degree of freedom); mean z^2
    itself is (R - 1) / (R - 3), with infinite variance below R = 5."""
    from scipy.special import ndtri_exp
    from scipy.stats import t

    return ndtri_exp(t.logsf(np.abs(z), realizations - 1)) ** 2


def realization_scale(sim, stderr, albedo, albedo_stderr, projected, paths, realizations) -> np.ndarray:
    """Per incidence, the variance g of a common relative scale of every cell: what the table's
    albedo error (from its ``realizations``) holds beyond the paths' own share
    (:func:`path_covariance` of the albedo, sum f_C P_C). A random scene's realizations differ,
    and a denser one brightens every cell; a fixed scene has g = 0, and its albedo variance
    estimated from R realizations scatters about the paths' share as chi^2(R - 1) / (R - 1): g
    counts only where the ratio exceeds that distribution's 99th percentile (clipped at 0 alone,
    the scatter made a fixed scene's errors 5-19 % too large in half its tables)."""
    from scipy.stats import chi2

    significant = chi2.ppf(0.99, realizations - 1) / (realizations - 1)
    out = np.zeros(len(albedo))
    for i, n in enumerate(paths):
        lit = sim[i] > 0
        if not lit.any() or albedo[i] <= 0:
            continue
        own = path_covariance(projected[lit, None], sim[i, lit], stderr[i, lit], n)[0, 0]
        if albedo_stderr[i] ** 2 > significant * own:
            out[i] = (albedo_stderr[i] ** 2 - own) / albedo[i] ** 2
    return out


def path_covariance(coefficients, f, stderr, n) -> np.ndarray:
    """Covariance of the sums ``coefficients^T f`` over cells f_C of one incidence's n paths.

    A path exits into one cell C with weight w, or not at all; f_C = p_C E[w | C] / P_C, and the
    sum is the mean over the paths of Y = c_C w / P_C: its covariance is (sum_C c_C c_C^T n D_C
    - E[Y] E[Y]^T) / n, exactly, with D_C = stderr_C^2 + f_C^2 / n = p_C E[w^2 | C] / (n P_C^2)
    from the table. It is computed in the two-pass form sum_C q_C (y_C - E[Y])(y_C - E[Y])^T +
    q_0 E[Y] E[Y]^T, with q_C = f_C^2 / (n D_C) (p_C E[w]^2 / E[w^2], at most p_C),
    y_C = c_C n D_C / f_C and q_0 = 1 - sum q_C, which is the same whatever the weights, but
    never negative: a plane's albedo sums every path, and there the one-pass form subtracts two
    near-equal noisy terms. Where noise makes sum q_C > 1, q_0 is taken as 0, which errs high."""
    lit = f > 0  # a cell no path reached holds no share of the covariance
    coefficients, f, stderr = coefficients[lit], f[lit], stderr[lit]
    d = stderr**2 + f**2 / n
    p = f**2 / (n * d)
    y = coefficients * (n * d / f)[:, None]
    mean = coefficients.T @ f
    spread = (y - mean).T @ ((y - mean) * p[:, None])
    return (spread + max(1.0 - p.sum(), 0.0) * np.outer(mean, mean)) / n


def covariance_rounding(values: np.ndarray, realizations: int) -> float:
    """The rounding of the covariance of the mean of points of ``values`` (n,) from
    ``realizations`` realizations (module doc): eps |values|^2 / R."""
    return float(np.finfo(float).eps * np.sum(np.square(values)) / realizations)


def eigenbasis(covariance: np.ndarray, rounding: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(eigenvalues, eigenvectors as columns, kept) of a covariance of points whose entries are
    rounded by ``rounding`` (:func:`covariance_rounding`): kept where the eigenvalue exceeds
    KEPT_ROUNDING times it, and 0."""
    spread, axes = np.linalg.eigh(covariance)
    return spread, axes, spread > max(KEPT_ROUNDING * rounding, 0.0)


@dataclass
class Hotelling:
    """Hotelling's test of one incidence's points (module doc): T^2 over the K kept directions
    of R realizations, and the largest deviation along a dropped direction over its limit
    (DROPPED_LIMIT standard errors plus the rounding floor; at most 1 where the points'
    relations hold)."""

    t2: float
    k: int
    realizations: int
    dropped: int
    dropped_ratio: float

    @property
    def dof(self) -> tuple[int, int]:
        return self.k, self.realizations - self.k

    @property
    def f(self) -> float:
        r, k = self.realizations, self.k
        return (r - k) / (k * (r - 1)) * self.t2

    def bounds(self, outside: float = CHI2_OUTSIDE) -> tuple[float, float]:
        """Two-sided bounds of F holding it with probability 1 - ``outside`` for the table's own BRDF."""
        from scipy.stats import f

        low, high = f.ppf([outside / 2, 1 - outside / 2], *self.dof)
        return float(low), float(high)

    @property
    def p(self) -> float:
        """The two-sided p-value of F: within :meth:`bounds` at ``outside`` exactly when p >= outside."""
        from scipy.stats import f

        return float(min(1.0, 2 * min(f.cdf(self.f, *self.dof), f.sf(self.f, *self.dof))))

    @property
    def relations_hold(self) -> bool:
        return self.dropped_ratio <= 1.0


def hotelling(deviation: np.ndarray, covariance: np.ndarray, realizations: int, values: np.ndarray,
              floor: float) -> Hotelling | None:
    """Hotelling's test (module doc) of ``deviation`` (n,) of points of ``values`` whose mean has
    ``covariance`` (n, n) from ``realizations`` realizations; ``floor``: the rounding of the
    values along a relation. None where it has no test: n >= R (module doc), or no direction kept."""
    if len(deviation) >= realizations:
        return None
    rounding = covariance_rounding(values, realizations)
    spread, axes, kept = eigenbasis(covariance, rounding)
    k = int(kept.sum())
    if k == 0:
        return None
    along = axes.T @ deviation
    limit = np.full(int((~kept).sum()), DROPPED_LIMIT * math.sqrt(KEPT_ROUNDING * rounding) + floor)
    ratio = np.divide(np.abs(along[~kept]), limit, out=np.full(limit.shape, math.inf), where=limit > 0)
    ratio[(limit == 0) & (along[~kept] == 0)] = 0.0
    return Hotelling(float(np.sum(along[kept] ** 2 / spread[kept])), k, realizations, int((~kept).sum()),
                     float(ratio.max(initial=0.0)))


def chi2_1dof_p(mean_square: float) -> float:
    """The two-sided p-value of a mean of squared normal scores against chi-square of one degree
    of freedom (the bounds of one error common to every point: :func:`chi2_bounds` with shares
    1): within those bounds at ``outside`` exactly when p >= outside."""
    from scipy.stats import chi2

    return float(min(1.0, 2 * min(chi2.cdf(mean_square, 1), chi2.sf(mean_square, 1))))
