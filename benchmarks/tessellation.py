"""Albedo and BRDF versus sphere tessellation, with the exact sphere as the limit (phi = 0.3, 0.6).

Runs the same config (same seed, so the same sphere centres in every realization) with
icosphere levels 0 .. --finest and with exact native spheres, and compares every level with the
exact spheres:

- albedo per incidence with its standard error;
- BRDF: chi-square per cell of (f_level - f_exact) / sqrt(se_level^2 + se_exact^2), whose mean
  is ~1 when the two tables agree within their errors (conservative: the tables share their
  sphere centres, so their difference varies less than two independent tables would);
- tracing time (the cost of the accuracy: triangles per sphere against one sphere primitive).

Writes benchmarks/out/tessellation.png and prints the table (about 4 minutes on 2 cores):

    python benchmarks/tessellation.py [--phis 0.3 0.6] [--finest 4]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from microsim import config as config_module
from microsim import geometry
from microsim.core.orders import RESULT_ALL_ORDERS
from microsim.testing import trace

OUT = Path(__file__).resolve().parent / "out"
EXACT = "exact"


def run_model(phi: float, model, paths: int, realizations: int, threads: int):
    """A run with icosphere level ``model``, or exact spheres; (result, seconds)."""
    scene = {"kind": "poisson_spheres", "volume_fraction": phi}
    if model != EXACT:
        scene["subdivisions"] = model
    cfg = config_module.validate({
        "scene": scene,
        "material": {"kind": "lambert", "albedo": 0.8},
        "illumination": {"theta_i_deg": [0.0, 60.0, 85.0]},
        "sensor": {"cells": 800},
        "run": {"paths": paths, "realizations": realizations, "seed": 4},
    })
    start = time.perf_counter()
    result = trace(cfg, threads=threads)
    return result, time.perf_counter() - start


def versus(result, reference):
    """(albedo, albedo se, chi-square per cell of the BRDF, |albedo difference| / combined se) per incidence."""
    albedo = np.array([a.mean[RESULT_ALL_ORDERS] for a in result.albedo])
    albedo_se = np.array([a.stderr[RESULT_ALL_ORDERS] for a in result.albedo])
    ref = np.array([a.mean[RESULT_ALL_ORDERS] for a in reference.albedo])
    ref_se = np.array([a.stderr[RESULT_ALL_ORDERS] for a in reference.albedo])
    chi2 = []
    for e, f in zip(result.brdf, reference.brdf):
        se2 = e.stderr[RESULT_ALL_ORDERS] ** 2 + f.stderr[RESULT_ALL_ORDERS] ** 2
        ok = se2 > 0
        chi2.append(np.mean((e.mean[RESULT_ALL_ORDERS][ok] - f.mean[RESULT_ALL_ORDERS][ok]) ** 2 / se2[ok]))
    z = np.abs(albedo - ref) / np.sqrt(albedo_se**2 + ref_se**2)
    return albedo, albedo_se, np.array(chi2), z


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--phis", type=float, nargs="+", default=[0.3, 0.6])
    parser.add_argument("--finest", type=int, default=4)
    parser.add_argument("--paths", type=int, default=400_000)
    parser.add_argument("--realizations", type=int, default=16)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    spheres = geometry.SCENES["poisson_spheres"]
    levels = list(range(args.finest + 1))
    table = {}
    for phi in args.phis:
        runs = {m: run_model(phi, m, args.paths, args.realizations, args.threads) for m in [EXACT, *levels]}
        exact = runs[EXACT][0]
        theta = np.degrees(exact.plan.theta_i)
        print(f"phi = {phi}: every model against exact spheres ({args.realizations} realizations, "
              f"{args.paths} paths per incidence; theta_i = {', '.join(f'{t:g}' for t in theta)} deg)")
        print(f"{'model':>8} {'mesh err':>9} {'tri/sph':>7} {'time s':>7}  albedo (+-se) per incidence"
              f"          chi2/cell vs exact   |d albedo|/se")
        for model in [*levels, EXACT]:
            result, seconds = runs[model]
            albedo, albedo_se, chi2, z = versus(result, exact)
            error = 0.0 if model == EXACT else spheres.unit_icosphere(model)[3]
            triangles = 0 if model == EXACT else len(spheres.unit_icosphere(model)[1])
            table[(phi, model)] = (error, albedo, albedo_se, chi2, z, seconds)
            print(f"{model!s:>8} {error:9.4f} {triangles:7d} {seconds:7.1f}  "
                  + " ".join(f"{a:.4f}({s:.4f})" for a, s in zip(albedo, albedo_se))
                  + "   " + " ".join(f"{c:.2f}" for c in chi2) + "   " + " ".join(f"{v:.2f}" for v in z))
    chart(table, args.phis, levels, theta)


def chart(table, phis, levels, theta):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    OUT.mkdir(exist_ok=True)
    fig, axes = plt.subplots(len(phis), 3, figsize=(15, 4.2 * len(phis)), squeeze=False)
    for row, phi in enumerate(phis):
        ax_albedo, ax_chi2, ax_time = axes[row]
        exact = table[(phi, EXACT)]
        for j, t in enumerate(theta):
            ax_albedo.errorbar(np.array(levels) + 0.05 * j, [table[(phi, m)][1][j] - exact[1][j] for m in levels],
                               yerr=[np.hypot(table[(phi, m)][2][j], exact[2][j]) for m in levels], marker="o",
                               capsize=3, label=f"theta_i = {t:g} deg")
            ax_chi2.plot(levels, [table[(phi, m)][3][j] for m in levels], marker="o", label=f"theta_i = {t:g} deg")
        ax_albedo.axhline(0.0, color="k", lw=1.2, label="exact spheres (the limit)")
        ax_albedo.set_ylabel("albedo - exact-sphere albedo (+- combined se)")
        ax_albedo.set_title(f"albedo vs tessellation (phi = {phi}, c = 0.8)")
        ax_chi2.axhline(1.0, color="k", lw=0.8)
        ax_chi2.set_ylabel("mean chi-square per cell vs exact spheres")
        ax_chi2.set_yscale("log")
        ax_chi2.set_title("BRDF difference to exact spheres")
        for ax in (ax_albedo, ax_chi2):
            ax.set_xlabel("icosphere level (20 * 4^level triangles per sphere)")
            ax.legend(fontsize=8)
        ax_time.semilogy(levels, [table[(phi, m)][5] for m in levels], marker="o", label="icospheres")
        ax_time.axhline(exact[5], color="k", lw=1.2, label="exact spheres")
        ax_time.set_xlabel("icosphere level")
        ax_time.set_ylabel("run time (s), builds included")
        ax_time.set_title("cost of accuracy")
        ax_time.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(OUT / "tessellation.png", dpi=110)
    print(f"chart written to {OUT / 'tessellation.png'}")


if __name__ == "__main__":
    main()
