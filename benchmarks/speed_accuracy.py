"""Speed against accuracy: error against a long reference run versus
wall time, for Boolean spheres (phi = 0.3, albedo 0.8) and the Lambert-sphere medium.

The reference is the default config traced with --reference-paths paths and
REFERENCE_REALIZATIONS realizations (another seed). Each
variant changes one choice of the default: the path count, the sphere model (icosphere levels
0-3 against exact native spheres), the tile and the depth (fractions and multiples of their
defaults). Every variant is timed as a run of the same three incidences (theta_i 0, 60, 85 deg,
1 M paths unless the path count is the choice), on the same two threads, in one process, the
shorter of two runs.

Error figures (``errors``): the expected root-mean-square relative error of a run like the
variant, its noise (its own standard error) and its bias (from the difference to the reference,
squared, less the variance of that difference) in quadrature; for the albedo, the largest over
the incidences, for the BRDF the same averaged over the cells with signal. The signed albedo
differences are printed too, with their standard errors.

The front: a variant is dominated if another is at least as fast and at least as accurate in both
figures. The chart marks the defaults; the script prints whether any variant dominates them.

    python benchmarks/speed_accuracy.py [--reference-paths N] [--json]

Writes benchmarks/out/speed_accuracy.png and .json. About 8 minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from report import OUT, save_figures

from microsim import config
from microsim.analysis.selection import with_signal
from microsim.core.orders import RESULT_ALL_ORDERS
from microsim.geometry import poisson_spheres
from microsim.testing import trace

THETA_I_DEG = [0.0, 60.0, 85.0]
#: realizations of the reference run: its geometric spread is then small beside every variant's
REFERENCE_REALIZATIONS = 512
CELLS = 3240
PATHS = 1_000_000
PHI, ALBEDO = 0.3, 0.8


def sphere_config(paths, seed, realizations=32, **scene):
    return config.validate({
        "scene": {"kind": "poisson_spheres", "volume_fraction": PHI, **scene},
        "material": {"kind": "lambert", "albedo": ALBEDO},
        "illumination": {"theta_i_deg": THETA_I_DEG},
        "sensor": {"cells": CELLS},
        "run": {"paths": paths, "realizations": realizations, "seed": seed},
    })


def medium_config(paths, seed, realizations=32):
    return config.validate({
        "scene": {"kind": "halfspace_medium", "phase": "lambert_sphere"},
        "material": {"kind": "lambert", "albedo": ALBEDO},
        "illumination": {"theta_i_deg": THETA_I_DEG},
        "sensor": {"cells": CELLS},
        "run": {"paths": paths, "realizations": realizations, "seed": seed},
    })


def timed(cfg, repeats=1):
    """The result of the first run and the shortest wall time of ``repeats`` (this machine's
    timings drift by 10-20 % from run to run)."""
    results, seconds = [], []
    for _ in range(repeats):
        start = time.perf_counter()
        results.append(trace(cfg, threads=2))
        seconds.append(time.perf_counter() - start)
    return results[0], min(seconds)


def errors(result, reference):
    """(albedo error, BRDF error): the expected root-mean-square error of a run like this one,
    its own noise and its bias added in quadrature, the larger over the incidences. The noise is
    the run's relative standard error; the bias is estimated from the difference d to the
    reference as d^2 - var(d), which is unbiased for the squared bias, floored at 0. For the BRDF,
    both are averaged over the cells with signal."""
    albedo, brdf = [], []
    for a, b, fa, fb in zip(result.albedo, reference.albedo, result.brdf, reference.brdf):
        x, se, y, ye = (v[RESULT_ALL_ORDERS] for v in (a.mean, a.stderr, b.mean, b.stderr))
        bias2 = max((x - y) ** 2 - se**2 - ye**2, 0.0) / y**2
        albedo.append(float(np.sqrt(se**2 / y**2 + bias2)))
        f, fe, g, ge = (v[RESULT_ALL_ORDERS] for v in (fa.mean, fa.stderr, fb.mean, fb.stderr))
        ok = with_signal(g, ge)
        noise2 = np.mean(fe[ok] ** 2 / g[ok] ** 2)
        cell_bias2 = max(np.mean(((f[ok] - g[ok]) ** 2 - fe[ok] ** 2 - ge[ok] ** 2) / g[ok] ** 2), 0.0)
        brdf.append(float(np.sqrt(noise2 + cell_bias2)))
    return max(albedo), max(brdf)


def albedo_bias(result, reference):
    """Per incidence: (albedo / reference - 1, its standard error)."""
    out = []
    for a, b in zip(result.albedo, reference.albedo):
        x, se, y, ye = a.mean[RESULT_ALL_ORDERS], a.stderr[RESULT_ALL_ORDERS], b.mean[RESULT_ALL_ORDERS], b.stderr[RESULT_ALL_ORDERS]
        out.append((float(x / y - 1.0), float(np.hypot(se / y, x * ye / y**2))))
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reference-paths", type=int, default=16_000_000)
    parser.add_argument("--seed", type=int, default=51)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    resolved = poisson_spheres.resolve(sphere_config(PATHS, 1))
    tile, depth = resolved["tile"], resolved["depth"]

    scenes = {
        "spheres": (sphere_config, [
            ("default", "default", PATHS, {}),
            *[("paths", f"{p / 1e6:g} M paths", p, {}) for p in (125_000, 250_000, 500_000, 2_000_000, 4_000_000)],
            *[("sphere model", f"icosphere level {k}", PATHS, {"subdivisions": k}) for k in (0, 1, 2, 3)],
            *[("tile", f"tile {f * tile:g}", PATHS, {"tile": f * tile}) for f in (0.25, 0.5, 0.75, 2.0)],
            *[("depth", f"depth x{f:g}", PATHS, {"depth": f * depth}) for f in (0.25, 0.5, 0.75, 2.0)],
        ]),
        "medium": (medium_config, [
            ("default", "default", PATHS, {}),
            *[("paths", f"{p / 1e6:g} M paths", p, {}) for p in (125_000, 250_000, 500_000, 2_000_000, 4_000_000)],
        ]),
    }
    figures = {"theta_i_deg": THETA_I_DEG, "cells": CELLS, "volume_fraction": PHI, "albedo": ALBEDO,
               "default_tile": tile, "default_depth": depth, "reference_paths": args.reference_paths, "scenes": {}}
    for name, (make, variants) in scenes.items():
        reference, reference_seconds = timed(make(args.reference_paths, args.seed, REFERENCE_REALIZATIONS))
        print(f"{name}: reference {args.reference_paths:,} paths in {reference_seconds:.0f} s", flush=True)
        rows = []
        for k, (kind, label, paths, scene) in enumerate(variants):
            result, seconds = timed(make(paths, args.seed + 1 + k, **scene), repeats=2)
            albedo_error, brdf_error = errors(result, reference)
            bias = albedo_bias(result, reference)
            rows.append({"kind": kind, "label": label, "paths": paths, **scene, "seconds": seconds,
                         "albedo_error": albedo_error, "brdf_error": brdf_error, "albedo_bias": bias})
            print(f"  {label:<20} {seconds:6.1f} s  albedo error {100 * albedo_error:6.3f} %  BRDF error "
                  f"{100 * brdf_error:6.3f} %  albedo - reference at theta_i " + ", ".join(
                      f"{t:g}: {100 * d:+.3f} +- {100 * e:.3f} %" for t, (d, e) in zip(THETA_I_DEG, bias)), flush=True)
        default = rows[0]
        dominating = [r["label"] for r in rows[1:] if r["seconds"] <= default["seconds"]
                      and r["albedo_error"] <= default["albedo_error"] and r["brdf_error"] <= default["brdf_error"]]
        print(f"  variants that dominate the default: {', '.join(dominating) or 'none'}", flush=True)
        figures["scenes"][name] = {"reference_seconds": reference_seconds, "variants": rows,
                                   "dominating_default": dominating}
    save_figures(figures, "speed_accuracy", args.json)
    plot(figures)


def plot(figures):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    markers = {"default": "*", "paths": "o", "sphere model": "^", "tile": "s", "depth": "D"}
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4))
    for ax, what, title in zip(axes, ("albedo_error", "brdf_error"),
                               ("albedo: expected rms error (%), worst incidence",
                                "BRDF: expected rms error over cells (%), worst incidence")):
        for scene, entry in figures["scenes"].items():
            for kind in markers:
                rows = [r for r in entry["variants"] if r["kind"] == kind]
                if not rows:
                    continue
                ax.scatter([r["seconds"] for r in rows], [100 * r[what] for r in rows], marker=markers[kind],
                           s=120 if kind == "default" else 30, label=f"{scene}: {kind}",
                           edgecolors="k" if kind == "default" else "none",
                           c="C0" if scene == "spheres" else "C1", alpha=0.8)
                for r in rows:
                    ax.annotate(r["label"], (r["seconds"], 100 * r[what]), fontsize=5, xytext=(3, 2),
                                textcoords="offset points")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time (s), 3 incidences, 2 threads")
        ax.set_title(title, fontsize=9)
    axes[0].legend(fontsize=6)
    fig.tight_layout()
    OUT.mkdir(exist_ok=True)
    fig.savefig(OUT / "speed_accuracy.png", dpi=120)


if __name__ == "__main__":
    main()
