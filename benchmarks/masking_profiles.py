"""Masking on Gaussian surfaces by facet slope, computed without microsim: an independent check of
what benchmarks/gaussian_surfaces.py measures with the tracer's shadow rays.

Exact reduction to one dimension. With wo = (sin t, 0, cos t), a ray from (x0, y0, h0) towards wo
stays on the line y = y0, so it is blocked iff h(x, y0) > h0 + (x - x0) cot t for some x > x0:
only the profile h(., y0) matters, and along a line the isotropic field is a 1-D Gaussian process
with the same C(r) = sigma^2 exp(-r^2 / l^2) (sigma = alpha l / 2). A point sampled uniformly in
(x, y) weighs its area projected towards wo, dx dy max(0, cos t - sin t h_x) (the 1 / m_z of the
area cancels, h_y drops out); the facet is tilted away from wo where h_x > 0, towards it where
h_x < 0. So every quantity is a functional of profiles: FFT-synthesized periodic profiles of
length ``--length`` (long enough that no ray meets a periodic copy of its own track within the
band of heights), piecewise linear between samples ``--spacing`` apart; on each segment the
visible part is exact, from a reverse running maximum of g(x) = h(x) - x cot t.

Printed and written (benchmarks/out/masking_profiles.json): per alpha and theta_o, the weighted
visible fraction of all facets and of those tilted away from and towards wo, over Smith's
G1 = 1 / (1 + Lambda) (Beckmann Lambda), with jackknife errors over the profiles.

    python benchmarks/masking_profiles.py [--alphas 0.3 0.8] [--thetas 60 75 85] [--profiles 1000]

Defaults: about a minute of one core. 2026-12-02: alpha 0.8, away / Smith 0.9232 +- 0.0002,
0.8324 +- 0.0005, 0.8073 +- 0.0012 at 60, 75, 85 deg; towards 1.0161, 1.0115, 1.0018.
"""

from __future__ import annotations

import argparse
import math

import numpy as np
from report import save_figures
from scipy.special import erf


def smith_g1(alpha: float, theta: float) -> float:
    """1 / (1 + Lambda) of Beckmann's distribution."""
    if theta == 0.0:
        return 1.0
    a = 1.0 / (alpha * math.tan(theta))
    return 1.0 / (1.0 + (erf(a) - 1.0) / 2.0 + math.exp(-a * a) / (2.0 * a * math.sqrt(math.pi)))


def profile(rng, n: int, spacing: float, sigma: float) -> np.ndarray:
    """A periodic Gaussian profile of n samples with C(x) = sigma^2 exp(-x^2) (l = 1)."""
    k = 2.0 * np.pi * np.fft.rfftfreq(n, spacing)
    spectral_density = sigma**2 * math.sqrt(math.pi) * np.exp(-(k**2) / 4.0)
    return np.fft.irfft(np.fft.rfft(rng.standard_normal(n)) * np.sqrt(spectral_density / spacing), n=n)


def tallies(h: np.ndarray, spacing: float, theta: float) -> dict:
    """Weighted facing and visible lengths of one profile: all segments, those tilted away (slope
    > 0) and those tilted towards wo."""
    n = h.size
    slope = (np.roll(h, -1) - h) / spacing
    weight = np.maximum(0.0, math.cos(theta) - math.sin(theta) * slope) * spacing
    if theta == 0.0:
        visible = np.ones(n)
    else:
        cot = 1.0 / math.tan(theta)
        length = n * spacing
        assert length * cot > 1.05 * (h.max() - h.min()), "profile too short for this angle"
        g = h - np.arange(n) * spacing * cot
        ahead = np.concatenate([g, g - length * cot, [g[0] - 2.0 * length * cot] * 2])
        highest = np.maximum.accumulate(ahead[::-1])[::-1]  # highest[j] = max of ahead[j:]
        drop = g - ahead[1:n + 1]  # spacing (cot - slope) > 0 on segments that face wo
        with np.errstate(divide="ignore", invalid="ignore"):
            visible = np.clip((g - highest[2:n + 2]) / drop, 0.0, 1.0)
        visible[drop <= 0.0] = 0.0
    out = {}
    for name, side in (("all", np.ones(n, bool)), ("away", slope > 0.0), ("toward", slope < 0.0)):
        out[name] = (float(weight[side].sum()), float((weight * visible)[side].sum()))
    return out


def jackknife_ratio(seen, facing, scale: float) -> tuple[float, float]:
    """sum(seen) / sum(facing) / scale, and its jackknife standard error over the profiles."""
    seen, facing = np.asarray(seen), np.asarray(facing)
    n = len(seen)
    ratio = seen.sum() / facing.sum() / scale
    leave_one_out = (seen.sum() - seen) / (facing.sum() - facing) / scale
    return float(ratio), float(math.sqrt((n - 1) / n * np.sum((leave_one_out - leave_one_out.mean()) ** 2)))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--alphas", type=float, nargs="+", default=[0.3, 0.8])
    parser.add_argument("--thetas", type=float, nargs="+", default=[0.0, 30.0, 60.0, 75.0, 85.0])
    parser.add_argument("--profiles", type=int, default=1000)
    parser.add_argument("--length", type=float, default=4096.0, help="profile length, in correlation lengths")
    parser.add_argument("--spacing", type=float, default=1 / 32, help="sample spacing, in correlation lengths")
    parser.add_argument("--seed", type=int, default=11)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    figures = {"profiles": args.profiles, "length": args.length, "spacing": args.spacing, "alphas": {}}
    n = round(args.length / args.spacing)
    for alpha in args.alphas:
        rng = np.random.default_rng(args.seed)
        rows = {theta: [] for theta in args.thetas}
        for _ in range(args.profiles):
            h = profile(rng, n, args.spacing, alpha / 2.0)
            for theta in args.thetas:
                rows[theta].append(tallies(h, args.spacing, math.radians(theta)))
        figures["alphas"][alpha] = {}
        for theta, tally in rows.items():
            g1 = smith_g1(alpha, math.radians(theta))
            entry = {"smith_g1": g1}
            for name in ("all", "away", "toward"):
                entry[f"{name}_over_smith"] = jackknife_ratio([t[name][1] for t in tally], [t[name][0] for t in tally],
                                                              g1)
            figures["alphas"][alpha][theta] = entry
            print(f"alpha {alpha:g}, theta_o {theta:4.1f}: Smith G1 {g1:.5f}; over Smith: all "
                  f"{entry['all_over_smith'][0]:.5f} +- {entry['all_over_smith'][1]:.5f}, away "
                  f"{entry['away_over_smith'][0]:.4f} +- {entry['away_over_smith'][1]:.4f}, towards "
                  f"{entry['toward_over_smith'][0]:.4f} +- {entry['toward_over_smith'][1]:.4f}", flush=True)
    save_figures(figures, "masking_profiles", args.json)


if __name__ == "__main__":
    main()
