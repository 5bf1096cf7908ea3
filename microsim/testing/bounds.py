"""Statistical bounds shared by the physics tests: the mean z^2 of a table's cells, and Hotelling's
statistic of realizations with correlated bins.

Contract: with R realizations a cell's z = (estimate - truth) / stderr is Student-t with
R - 1 degrees of freedom; over n cells the mean z^2 lies within :func:`chi2_lower_bound` and
:func:`chi2_bound` (its expectation -+ 5 standard deviations of the mean) unless the estimates
or their standard errors are wrong. Cells that share a realization's geometry are correlated:
the bounds hold for tiles or realizations large enough (docs/developer/testing.md).
"""

import math


def chi2_bound(n_cells: int, realizations: int) -> float:
    """Upper bound on the mean z^2 over n cells when each z is Student-t with R - 1 degrees of
    freedom (a standard error from R realizations): mean nu / (nu - 2), variance of z^2
    2 nu^2 (nu - 1) / ((nu - 2)^2 (nu - 4)), plus 5 standard deviations of the mean. For the
    difference of two such tables (Welch, about 2 (R - 1) degrees of freedom) it is conservative."""
    mean, spread = _mean_z2(n_cells, realizations)
    return mean + spread


def chi2_lower_bound(n_cells: int, realizations: int) -> float:
    """The same mean z^2 minus 5 standard deviations of the mean: a table whose standard errors are
    too large (a mean z^2 far below 1) falls under it, so that "consistent with 1" is two-sided."""
    mean, spread = _mean_z2(n_cells, realizations)
    return mean - spread


def _mean_z2(n_cells: int, realizations: int) -> tuple[float, float]:
    """(expected mean z^2, 5 standard deviations of the mean) over n Student-t cells."""
    nu = realizations - 1
    variance = 2 * nu**2 * (nu - 1) / ((nu - 2) ** 2 * (nu - 4))
    return nu / (nu - 2), 5 * math.sqrt(variance / n_cells)


def mean_z2_interval(n_cells: int, realizations: int, level: float = 0.99) -> tuple[float, float]:
    """The two-sided ``level`` interval of the mean z^2 over n Student-t cells (R - 1 degrees of
    freedom), in the normal approximation of the mean: its expectation -+ the normal quantile
    times its standard deviation."""
    from scipy.stats import norm

    mean, five = _mean_z2(n_cells, realizations)
    half = norm.ppf(0.5 + level / 2) * five / 5
    return mean - half, mean + half


def hotelling_f(samples, expected) -> float:
    """Hotelling's statistic of R realizations' ``samples`` (R, k) against the ``expected`` mean
    (k,), with the realizations' own covariance: F = (R - k) / (k (R - 1)) T^2, T^2 = R (m -
    mu)' S^-1 (m - mu). F(k, R - k)-distributed when the realizations are independent and their
    mean normal (R > k); correlated bins (a histogram's, a g(r)'s) are allowed for."""
    import numpy as np

    samples = np.asarray(samples, np.float64)
    r, k = samples.shape
    if r <= k:
        raise ValueError(f"hotelling_f: {r} realizations for {k} bins; needs more realizations than bins")
    gap = samples.mean(axis=0) - np.asarray(expected, np.float64)
    t2 = r * gap @ np.linalg.solve(np.cov(samples, rowvar=False), gap)
    return (r - k) / (k * (r - 1)) * t2


def hotelling_interval(bins: int, realizations: int, level: float = 0.99) -> tuple[float, float]:
    """The two-sided ``level`` interval of :func:`hotelling_f`: F(bins, realizations - bins)'s quantiles."""
    from scipy.stats import f

    tail = 0.5 - level / 2
    return tuple(float(q) for q in f.ppf([tail, 1.0 - tail], bins, realizations - bins))
