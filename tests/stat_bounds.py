"""Statistical bounds shared by the physics tests."""

import math


def chi2_bound(n_cells: int, realizations: int) -> float:
    """Upper bound on the mean z^2 over n cells when each z is Student-t with R - 1 degrees of
    freedom (a standard error from R realizations): mean nu / (nu - 2), variance of z^2
    2 nu^2 (nu - 1) / ((nu - 2)^2 (nu - 4)), plus 5 standard deviations of the mean. For the
    difference of two such tables (Welch, about 2 (R - 1) degrees of freedom) it is conservative."""
    nu = realizations - 1
    variance = 2 * nu**2 * (nu - 1) / ((nu - 2) ** 2 * (nu - 4))
    return nu / (nu - 2) + 5 * math.sqrt(variance / n_cells)
