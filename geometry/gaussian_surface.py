"""Random Gaussian surfaces: the heights of one period, synthesized by FFT (docs/conventions.md §5.7).

The surface is a stationary Gaussian random field h(x, y) of mean 0 with the Gaussian
autocorrelation C(x, y) = sigma^2 exp(-x^2 / lx^2 - y^2 / ly^2), the surfaces on which Smith
derived his masking function (Smith 1967; Heitz 2014, §5; Heitz et al. 2016 traced them). It is
sampled on an n x n periodic grid of spacing ``pixel``: the grid heights are exactly Gaussian
with the covariance of C summed over the periodic images (circulant embedding: the DFT of that
covariance is positive, and h = IDFT(sqrt(DFT(C)) DFT(w)) for white noise w).

Roughness. A continuous surface of this C has slopes h_x, h_y Gaussian with variances
2 sigma^2 / lx^2 and 2 sigma^2 / ly^2: Beckmann's distribution of roughness alpha_x = 2 sigma / lx,
alpha_y = 2 sigma / ly (slope variance alpha^2 / 2 an axis, as in the ``microfacet`` model). The
surface traced is the grid triangulated (microsim.geometry.heightfield.triangulate), and a facet's slopes
are differences of neighbouring samples, (h(x + pixel) - h(x)) / pixel, of variance
2 sigma^2 (1 - exp(-pixel^2 / lx^2)) / pixel^2: smaller than the continuous one by
1 - pixel^2 / (2 lx^2) to first order. :func:`field_parameters` chooses sigma, lx and ly so that
the facets' slopes have exactly the requested variances alpha_x^2 / 2 and alpha_y^2 / 2 and
sqrt(lx ly) is the requested ``correlation_length``: each facet's slope is then exactly Gaussian
with the requested alpha. What the grid still changes: the slopes of a facet along x and y are
correlated, rho = -(1 - exp(-pixel^2 / l^2)) / 2 on one diagonal split and +that on the other
(-sqrt((1 - exp(-pixel^2 / lx^2)) (1 - exp(-pixel^2 / ly^2))) / 2 if anisotropic; the
triangulation alternates the splits, so the NDF is isotropic to first order in rho: -0.008 at 8
samples a correlation length), and the surface between samples is flat (the masking of a
triangulated surface converges to the continuous one as samples per correlation length grow:
``SAMPLES_PER_CORRELATION``, measured in docs/developer/performance.md).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

#: default samples a correlation length: the coarsest grid whose single and multiple scattering
#: agree with finer grids within the errors of a 1.6 M path run (docs/developer/performance.md)
SAMPLES_PER_CORRELATION = 8
#: default tile, in correlation lengths (at least; longer where grazing rays need it: default_tile)
TILE_CORRELATIONS = 16
#: shortest tile accepted, in (the longer) correlation lengths: the grid's covariance is C summed
#: over its periodic images (:func:`spectrum`), which adds about exp(-(L - r)^2 / l^2) sigma^2 to
#: C(r); at L = 4 l the facets' slope variance (from C(0) - C(pixel)) is 2e-5 of itself off
#: (1e-6 at 5 l), negligible beside a realization's own spread
MIN_TILE_CORRELATIONS = 4
#: the heights a ray must climb to clear the surface: this many sigma (+-3 sigma)
BAND_SIGMAS = 6.0
#: most samples a side of a default tile (a longer one must be asked for with ``tile``)
MAX_DEFAULT_SAMPLES = 1024


def field_parameters(roughness_x: float, roughness_y: float, correlation_length: float, pixel: float) -> dict:
    """sigma, lx, ly of the field whose grid facets have slope variances roughness^2 / 2 along x
    and y, with sqrt(lx ly) = correlation_length (module doc). ValueError where no field has
    them: the pixel is too coarse for so different roughnesses (the smoother axis would need a
    correlation longer than the geometric mean allows)."""
    if not _feasible(roughness_x, roughness_y, correlation_length, pixel):
        largest = brentq(lambda p: 0.5 if _feasible(roughness_x, roughness_y, correlation_length, p) else -0.5,
                         1e-9 * pixel, pixel, xtol=1e-6 * pixel)
        raise ValueError(f"scene.pixel = {pixel:g}: too coarse for roughness {roughness_x:g} x {roughness_y:g} at "
                         f"correlation_length {correlation_length:g}; accepted: pixel below {largest:.4g}")

    def excess(sigma):
        return math.log(_length(sigma, roughness_x, pixel) * _length(sigma, roughness_y, pixel)) \
            - 2.0 * math.log(correlation_length)

    low = _lowest_sigma(roughness_x, roughness_y, pixel)
    high = max(correlation_length * math.sqrt(roughness_x * roughness_y), low) * 2.0 + pixel
    while excess(high) < 0.0:
        high *= 2.0
    sigma = brentq(excess, low, high, xtol=1e-15 * high, rtol=1e-15)
    return {"sigma": sigma, "correlation_x": _length(sigma, roughness_x, pixel),
            "correlation_y": _length(sigma, roughness_y, pixel)}


def _length(sigma: float, alpha: float, pixel: float) -> float:
    """The correlation length whose grid facets have slope variance alpha^2 / 2 at this sigma."""
    return pixel / math.sqrt(-math.log1p(-(alpha * pixel / (2.0 * sigma)) ** 2))


def _lowest_sigma(roughness_x: float, roughness_y: float, pixel: float) -> float:
    """Just above the sigma at which the rougher axis's correlation length goes to 0."""
    return 0.5 * max(roughness_x, roughness_y) * pixel * (1.0 + 1e-12)


def _feasible(roughness_x: float, roughness_y: float, correlation_length: float, pixel: float) -> bool:
    """Whether some sigma gives sqrt(lx ly) = correlation_length: lx ly grows with sigma from its
    value at the lowest sigma, which must be below correlation_length^2."""
    low = _lowest_sigma(roughness_x, roughness_y, pixel)
    return _length(low, roughness_x, pixel) * _length(low, roughness_y, pixel) < correlation_length**2


def default_tile(sigma: float, longest_correlation: float, pixel: float, theta_grazing: float) -> tuple[float, float]:
    """(tile, tile_bias_floor). The floor: a ray at ``theta_grazing`` (the run's largest incidence,
    or 85 deg if that is larger) that crosses a whole tile climbs BAND_SIGMAS sigma, so it has left
    the band of heights before it meets the same heights a second time (on the periodic image of
    its own track: in the plane of a tile axis it would pass over exactly the samples that did not
    block it). The tile is that floor, at least TILE_CORRELATIONS correlation lengths, at most
    MAX_DEFAULT_SAMPLES samples a side, in whole samples."""
    floor = BAND_SIGMAS * sigma * math.tan(theta_grazing)
    tile = max(floor, TILE_CORRELATIONS * longest_correlation)
    return min(math.ceil(tile / pixel), MAX_DEFAULT_SAMPLES) * pixel, floor


def spectrum(n: int, pixel: float, sigma: float, correlation_x: float, correlation_y: float) -> np.ndarray:
    """The DFT (n x n, real) of the grid's covariance: C at lags (i pixel, j pixel) summed over
    the periodic images at lags r - 2L, r - L, r, r + L along each axis (L = n pixel), a set
    symmetric under r -> L - r (so the DFT is real); the images left out are at least 2 L
    away, below exp(-64) on a tile of MIN_TILE_CORRELATIONS correlation lengths. Rounding makes a few
    of its smallest values negative (-1e-13): they are taken as 0."""

    def periodic(length):  # C along one axis at lags 0 .. n - 1
        lag = np.arange(n) * pixel
        period = n * pixel
        return sum(np.exp(-((lag + k * period) / length) ** 2) for k in (-2, -1, 0, 1))

    return sigma**2 * np.outer(np.fft.fft(periodic(correlation_x)).real, np.fft.fft(periodic(correlation_y)).real)


def heights(n: int, pixel: float, sigma: float, correlation_x: float, correlation_y: float,
            rng: np.random.Generator) -> np.ndarray:
    """One realization: n x n heights of the periodic field (module doc), sample (i, j) at
    (i pixel, j pixel), of covariance IDFT(:func:`spectrum`) exactly."""
    amplitude = np.sqrt(np.maximum(spectrum(n, pixel, sigma, correlation_x, correlation_y), 0.0))
    return np.fft.ifft2(amplitude * np.fft.fft2(rng.standard_normal((n, n)))).real
