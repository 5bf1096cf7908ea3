"""The chi-square test of a material's sampling (after Mitsuba 3's ``chi2.py`` for BSDFs).

Contract: :func:`material_check` returns the p-values of three statistics; a correct material
gives p-values uniform on [0, 1], so a test requires each above a small threshold (1e-4 in
tests/test_materials.py), and a broken sampler gives p-values near 0.

:func:`material_check`: a material's sampling against its ``evaluate`` and ``pdf``
(:mod:`microsim.tracer.materials`), on the hemisphere of a tilted shading normal. Directions are drawn
with :func:`~microsim.tracer.materials.scatter` and binned on a grid in (cos theta, phi) of the normal's
frame; the bins' expected counts are the pdf integrated over them (Gauss-Legendre product rules),
bins expected to hold fewer than ``MIN_EXPECTED`` samples pooled, as Mitsuba does. Three
statistics, each with its p-value:

- Pearson's chi-square of the counts of the samples outside the delta lobes against N x the
  integrated pdf (the sampled density is the pdf);
- the samples in a delta lobe (drawn in the mirror direction), or ended by the sampler (weight 0,
  no direction out: an absorber), against N (1 - the pdf's integral) (a binomial count: what the
  pdf leaves out is the probability of those);
- the weights summed in each bin against N x evaluate integrated over it, each bin's variance its
  expected count times its mean squared weight (the weights are evaluate / pdf on average: where
  a weight is random, as in the interfaced body, only its mean is).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from microsim.physics.rng import path_state
from microsim.physics.sampling import orthonormal_basis, reflect
from microsim.tracer.materials import evaluate, pdf, row_length, scatter

#: bins expected to hold fewer samples are pooled into one
MIN_EXPECTED = 5.0
#: a sample within this of the mirror direction came from a delta lobe
MIRROR_TOLERANCE = 1e-9


class MaterialCheck(NamedTuple):
    """p-values of the three statistics of :func:`material_check` (module doc)."""

    counts_p: float
    delta_p: float
    weights_p: float
    delta_fraction: float  # of the samples: in a delta lobe, or ended
    samples: int

    @property
    def smallest_p(self) -> float:
        return min(self.counts_p, self.delta_p, self.weights_p)


@numba.njit(cache=True, error_model="numpy")
def _draw(code, prm, wi, n, count, key, sample):
    """``count`` interactions of light arriving from wi on the normal n: (directions (count, 3),
    weights, and whether each came from a delta lobe)."""
    states = np.empty(count, np.uint64)
    directions = np.empty((count, 3))
    weights = np.empty(count)
    delta = np.zeros(count, np.bool_)
    d = (-wi[0], -wi[1], -wi[2])
    mirror = reflect(d, n)
    for i in range(count):
        states[i] = path_state(key, i)
        wo, factor, cut = sample(code, prm, states, i, d, n)
        directions[i, 0], directions[i, 1], directions[i, 2] = wo
        weights[i] = factor
        gap = (wo[0] - mirror[0]) ** 2 + (wo[1] - mirror[1]) ** 2 + (wo[2] - mirror[2]) ** 2
        delta[i] = gap < MIRROR_TOLERANCE**2
    return directions, weights, delta


@numba.njit(cache=True, error_model="numpy")
def _density(code, prm, wi, n, wos, kernel):
    """``kernel`` (evaluate or pdf) at each direction of wos (m, 3)."""
    out = np.empty(len(wos))
    for j in range(len(wos)):
        out[j] = kernel(code, prm, wi, (wos[j, 0], wos[j, 1], wos[j, 2]), n)
    return out


def material_check(material, theta_i_deg: float, samples: int = 200_000, seed: int = 1,
                   normal=(0.3, -0.2, 0.9), grid=(20, 40), sample=scatter) -> MaterialCheck:
    """The three statistics of ``material`` (a validated material section, e.g.
    ``MATERIALS["lambert"](kind="lambert", albedo=0.5)``) for light arriving at ``theta_i_deg``
    from the shading normal ``normal``; ``sample`` replaces :func:`~microsim.tracer.materials.scatter`
    (a numba function of its signature) to show that a broken sampler fails."""
    from scipy import stats

    n = np.asarray(normal, np.float64) / np.linalg.norm(normal)
    t, s = (np.array(v) for v in orthonormal_basis(tuple(n)))
    theta = np.radians(theta_i_deg)
    wi = np.sin(theta) * t + np.cos(theta) * n
    row = np.zeros(row_length())
    row[: len(material.row())] = material.row()
    args = (material.code, row, tuple(wi), tuple(n))
    directions, weights, delta = _draw(*args, samples, np.uint64(seed), sample)

    # bins in (cos theta, phi) of the normal's frame; the rules' nodes per bin
    n_cos, n_phi = grid
    local = np.stack([directions @ t, directions @ s, directions @ n], axis=1)
    keep = ~delta & (local[:, 2] > 0.0)
    cos_bin = np.minimum((local[keep, 2] * n_cos).astype(int), n_cos - 1)
    phi = np.mod(np.arctan2(local[keep, 1], local[keep, 0]), 2 * np.pi)
    phi_bin = np.minimum((phi / (2 * np.pi) * n_phi).astype(int), n_phi - 1)
    flat = cos_bin * n_phi + phi_bin
    counts = np.bincount(flat, minlength=n_cos * n_phi).astype(float)
    summed = np.bincount(flat, weights=weights[keep], minlength=n_cos * n_phi)
    squares = np.bincount(flat, weights=weights[keep] ** 2, minlength=n_cos * n_phi)
    expected_pdf, expected_eval = (samples * _bin_integrals(args, kernel, n_cos, n_phi, t, s, n)
                                   for kernel in (pdf, evaluate))

    # the counts: Pearson's chi-square, sparse bins pooled
    sparse = expected_pdf < MIN_EXPECTED
    observed = np.append(counts[~sparse], counts[sparse].sum())
    expected = np.append(expected_pdf[~sparse], expected_pdf[sparse].sum())
    used = expected > 0
    if np.any((observed > 0) & ~used):  # samples where the pdf says none can fall
        counts_p = 0.0
    else:
        statistic = np.sum((observed[used] - expected[used]) ** 2 / expected[used])
        counts_p = float(stats.chi2.sf(statistic, max(used.sum() - 1, 1)))

    # the delta lobes, and the paths the sampler ended (weight 0, no direction out: an absorber):
    # a binomial count against 1 - the pdf's integral
    continuous = min(expected_pdf.sum() / samples, 1.0)
    drawn = int(delta.sum() + np.count_nonzero((weights == 0.0) & (local[:, 2] <= 0.0)))
    delta_p = float(min(1.0, 2 * min(stats.binom.cdf(drawn, samples, 1 - continuous),
                                     stats.binom.sf(drawn - 1, samples, 1 - continuous))))

    # the weights: each bin's sum against N x the integrated evaluate. The variance of a sum of a
    # random number of random weights is its expected count times the mean squared weight; that
    # mean is the bin's own (a ratio of sums: with equal weights, Pearson's form again), or over
    # every bin where the bin holds no sample (sparse bins pooled, as for the counts)
    sums = np.append(summed[~sparse], summed[sparse].sum())
    target = np.append(expected_eval[~sparse], expected_eval[sparse].sum())
    squared = np.append(squares[~sparse], squares[sparse].sum())
    held = observed
    overall = squares.sum() / max(counts.sum(), 1.0)
    mean_square = np.where(held > 0, squared / np.maximum(held, 1.0), overall)
    variance = expected * mean_square
    if np.any((variance <= 0) & (np.abs(sums - target) > 1e-12 * max(abs(target.sum()), 1e-300))):
        weights_p = 0.0  # weight where the pdf says no sample falls, or evaluate where none is drawn
    else:
        lit = variance > 0
        z2 = (sums[lit] - target[lit]) ** 2 / variance[lit]
        weights_p = float(stats.chi2.sf(z2.sum(), max(int(lit.sum()), 1)))
    return MaterialCheck(counts_p, delta_p, weights_p, drawn / samples, samples)


def _bin_integrals(args, kernel, n_cos, n_phi, t, s, n, nodes: int = 6) -> np.ndarray:
    """The integral of ``kernel`` over each (cos theta, phi) bin of the normal's frame (solid
    angle d(cos theta) d(phi)), by a nodes x nodes Gauss-Legendre rule in each bin."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    cos_edges, phi_edges = np.linspace(0, 1, n_cos + 1), np.linspace(0, 2 * np.pi, n_phi + 1)
    c = (cos_edges[:-1, None] + 0.5 * (x + 1) / n_cos)  # (n_cos, nodes)
    p = (phi_edges[:-1, None] + 0.5 * (x + 1) * 2 * np.pi / n_phi)  # (n_phi, nodes)
    cc, pp = c[:, None, :, None], p[None, :, None, :]
    sin = np.sqrt(np.maximum(1 - cc**2, 0.0))
    wos = (sin * np.cos(pp))[..., None] * t + (sin * np.sin(pp))[..., None] * s + np.broadcast_to(cc, sin.shape)[..., None] * n
    wos = np.broadcast_to(wos, (n_cos, n_phi, nodes, nodes, 3))
    values = _density(*args, np.ascontiguousarray(wos.reshape(-1, 3)), kernel)
    weights = np.outer(w, w) * 0.25 * (1.0 / n_cos) * (2 * np.pi / n_phi)
    return np.sum(values.reshape(n_cos, n_phi, nodes, nodes) * weights, axis=(2, 3)).reshape(-1)
