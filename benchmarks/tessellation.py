"""Albedo and BRDF versus sphere tessellation level (phi = 0.3): is the default level converged?

Runs the same config (same seed, so the same sphere centres and rotations in every
realization) at icosphere levels 0 .. --finest, and compares every level with the finest:

- albedo per incidence with its standard error;
- BRDF: chi-square per cell of (f_level - f_finest) / sqrt(se_level^2 + se_finest^2), whose
  mean is ~1 when the two tables agree within their errors (conservative: the tables share
  their geometry, so their difference varies less than two independent tables would);
- relative change of the albedo, and tracing time (the cost of the accuracy).

Writes benchmarks/out/tessellation.png and prints the table; the default level is the one
chosen by the default mesh-error budget (geometry.poisson_spheres.DEFAULT_MESH_ERROR).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import geometry
from microsim import config as config_module
from microsim import runner

OUT = Path(__file__).resolve().parent / "out"


def run_level(level: int, paths: int, realizations: int, workers: int):
    cfg = config_module.validate({
        "scene": {"kind": "poisson_spheres", "volume_fraction": 0.3, "subdivisions": level},
        "material": {"kind": "lambert", "albedo": 0.8},
        "illumination": {"theta_i_deg": [0.0, 60.0, 85.0]},
        "sensor": {"cells": 800},
        "run": {"paths": paths, "realizations": realizations, "seed": 4},
    })
    start = time.perf_counter()
    result = runner.run(cfg, workers=workers)
    return result, time.perf_counter() - start


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--finest", type=int, default=4)
    parser.add_argument("--paths", type=int, default=400_000)
    parser.add_argument("--realizations", type=int, default=16)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    spheres = geometry.SCENES["poisson_spheres"]
    default_level = spheres.level_for(spheres.DEFAULT_MESH_ERROR)
    levels = list(range(args.finest + 1))
    runs = {lv: run_level(lv, args.paths, args.realizations, args.workers) for lv in levels}
    finest, _ = runs[args.finest]
    theta = np.degrees(finest.plan.theta_i)
    rows = []
    print(f"{'level':>5} {'mesh err':>9} {'tri/sph':>7} {'time s':>7}  albedo (+-se) per incidence        "
          f"chi2/cell vs finest   max |d albedo|/se")
    for lv in levels:
        res, seconds = runs[lv]
        albedo = np.array([a.mean[-1] for a in res.albedo])
        albedo_se = np.array([a.stderr[-1] for a in res.albedo])
        ref = np.array([a.mean[-1] for a in finest.albedo])
        ref_se = np.array([a.stderr[-1] for a in finest.albedo])
        chi2 = []
        for e, f in zip(res.brdf, finest.brdf):
            se2 = e.stderr[-1] ** 2 + f.stderr[-1] ** 2
            ok = se2 > 0
            chi2.append(np.mean((e.mean[-1][ok] - f.mean[-1][ok]) ** 2 / se2[ok]))
        dz = np.abs(albedo - ref) / np.sqrt(albedo_se**2 + ref_se**2) if lv != args.finest else np.zeros_like(albedo)
        error = spheres.unit_icosphere(lv)[3]
        rows.append((lv, error, albedo, albedo_se, np.array(chi2), dz, seconds))
        marker = " (default)" if lv == default_level else ""
        print(f"{lv:>5} {error:9.4f} {len(spheres.unit_icosphere(lv)[1]):7d} {seconds:7.1f}  "
              + " ".join(f"{a:.4f}({s:.4f})" for a, s in zip(albedo, albedo_se))
              + "   " + " ".join(f"{c:.2f}" for c in chi2) + f"   {dz.max():.2f}{marker}")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    OUT.mkdir(exist_ok=True)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    lv = np.array([r[0] for r in rows])
    finest_albedo, finest_se = rows[-1][2], rows[-1][3]
    for j, t in enumerate(theta):
        axes[0].errorbar(lv[:-1] + 0.05 * j, [r[2][j] - finest_albedo[j] for r in rows[:-1]],
                         yerr=[np.hypot(r[3][j], finest_se[j]) for r in rows[:-1]], marker="o", capsize=3,
                         label=f"theta_i = {t:g} deg")
        axes[1].plot(lv[:-1], [r[4][j] for r in rows[:-1]], marker="o", label=f"theta_i = {t:g} deg")
    for ax in axes[:2]:
        ax.axvline(default_level, color="grey", ls="--", lw=1)
        ax.set_xlabel("icosphere level (triangles per sphere 20 * 4^level)")
        ax.legend(fontsize=8)
    axes[0].axhline(0.0, color="k", lw=0.8)
    axes[0].set_ylabel(f"albedo - albedo at level {args.finest} (+- combined se)")
    axes[0].set_title("albedo vs tessellation (phi = 0.3, c = 0.8)")
    axes[1].axhline(1.0, color="k", lw=0.8)
    axes[1].set_ylabel("mean chi-square per cell vs finest")
    axes[1].set_yscale("log")
    axes[1].set_title("BRDF difference to the finest level")
    axes[2].loglog([r[1] for r in rows], [r[6] for r in rows], marker="o")
    for r in rows:
        axes[2].annotate(f"L{r[0]}", (r[1], r[6]))
    axes[2].set_xlabel("max mesh-to-sphere distance (radii)")
    axes[2].set_ylabel("run time (s)")
    axes[2].set_title("cost of accuracy")
    fig.tight_layout()
    fig.savefig(OUT / "tessellation.png", dpi=110)
    print(f"chart written to {OUT / 'tessellation.png'} (default level {default_level})")


if __name__ == "__main__":
    main()
