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
weights, covariance and cells (issue 24)').

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
randomness (R realizations) :func:`normal_squares` takes into account.
"""

from __future__ import annotations

import numpy as np

#: a cell's predicted variance is at least that of a cell this fraction of its incidence's mean value
VARIANCE_FLOOR = 1e-3
#: two-sided probability outside the bounds of chi-square per cell, for an exact model
CHI2_OUTSIDE = 0.01


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


def chi2_bounds(kurtosis: np.ndarray, common: np.ndarray) -> tuple[float, float]:
    """Two-sided CHI2_OUTSIDE bounds of chi-square per cell for an exact model over cells of
    these excess kurtoses of the paths' part and realizations' shares (:func:`predicted_variance`):
    the gamma distribution of mean 1 and their variance (module doc)."""
    from scipy.stats import gamma

    n = kurtosis.size
    if n == 0:
        return float("nan"), float("nan")
    variance = (np.sum((1 - common) ** 2 * (2 + kurtosis)) + 4 * np.sum(common * (1 - common))) / n**2 \
        + 2 * float(np.mean(common)) ** 2
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
