"""The Lambert-sphere models against their own physics: the radiative-transfer half space of
Lambert-sphere scatterers, every albedo from one run.

One run of ``halfspace_medium`` (phase ``lambert_sphere``) at albedos 0.3, 0.6, 0.9, 0.99
(docs/conventions.md §4: traced once at 0.99), theta_i = 0, 30, 60, 80 deg, 3240 cells, --paths per
incidence, 32 realizations; then, per albedo and incidence, ``microsim.analysis.compare`` of
``lambert_sphere`` (method exact: exact single scattering and the exact Horak-Chandrasekhar
solution of the three-term phase function; method fit: the paper's fits) and
``lambert_sphere_fast`` (Eq. 41): chi^2 per cell, median |rel| over the cells with signal, and the
albedo ratio model / table. Every figure is printed, none is dropped; JSON in
benchmarks/out/medium_models.json, a chart in medium_models.png. About 1 minute on 2 workers.

An open question for the next engineer. With seed 1, the 60 deg column (incidence index 2) comes
out low against ``lambert_sphere`` exact: albedo 0.10700 +- 0.00006 at c = 0.3, 4.3 standard
errors under both the model and an independent discrete-ordinate solution with the full phase
function (0.10725). The next 125 000 paths of the same 32 streams are still 1.9 low. Seeds 11 and
12, and 60 deg as incidence index 0 of seed 1, agree with the model (z = -0.3, +1.3, +0.9), as
does seed 7 at c = 0.9 with 100 M paths (z = -0.6). The path streams of (seed 1, index 2) do not
overlap in SplitMix64's Weyl sequence (smallest gap 9e5 draws), and their first eight uniforms
pass mean, 100-bin chi^2 and lag-1 correlation checks. So this is either a rare fluctuation, found
after many looks, or a weakness of these particular streams; a statistical test suite on the
path streams (PractRand, TestU01) would settle it. Here it is left as measured.
"""

from __future__ import annotations

import argparse

from report import OUT, save_figures

from microsim import config, models, tables
from microsim.analysis import compare
from microsim.testing import trace_albedos

ALBEDOS = [0.3, 0.6, 0.9, 0.99]
THETA_I = [0.0, 30.0, 60.0, 80.0]
MODELS = {"lambert_sphere exact": ("lambert_sphere", {"method": "exact"}),
          "lambert_sphere fit": ("lambert_sphere", {"method": "fit"}),
          "lambert_sphere_fast": ("lambert_sphere_fast", {})}


def measure(paths: int, workers: int) -> list[dict]:
    cfg = config.validate({"scene": {"kind": "halfspace_medium", "phase": "lambert_sphere"},
                           "material": {"kind": "lambert", "albedo": ALBEDOS},
                           "illumination": {"theta_i_deg": THETA_I}, "sensor": {"cells": 3240},
                           "run": {"paths": paths, "realizations": 32, "seed": 1}})
    rows = []
    for albedo, result in zip(ALBEDOS, trace_albedos(cfg, workers=workers)):
        path = tables.write(OUT / "medium_models.h5", result, cfg, overwrite=True)
        table = tables.load(path)
        for label, (name, extra) in MODELS.items():
            comparison = compare.compare(table, models.create(name, albedo=albedo, **extra))
            for i, theta in enumerate(THETA_I):
                m = comparison.metrics(i)
                rows.append({"model": label, "albedo": albedo, "theta_i_deg": theta,
                             "chi2_per_cell": m["chi2_per_cell"], "median_abs_rel_err": m["median_abs_rel_err"],
                             "albedo_model": m["albedo_model"], "albedo_sim": m["albedo_sim"],
                             "albedo_sim_stderr": m["albedo_sim_stderr"]})
    return rows


def chart(rows: list[dict]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(13, 4.6))
    for k, label in enumerate(MODELS):
        for j, theta in enumerate(THETA_I):
            chosen = [r for r in rows if r["model"] == label and r["theta_i_deg"] == theta]
            style = dict(color=f"C{k}", alpha=0.35 + 0.65 * j / (len(THETA_I) - 1), marker="o", ms=3)
            name = f"{label}, theta_i = {theta:g}" if j in (0, len(THETA_I) - 1) else None
            axes[0].plot([r["albedo"] for r in chosen], [r["median_abs_rel_err"] for r in chosen], label=name, **style)
            axes[1].plot([r["albedo"] for r in chosen], [r["albedo_model"] / r["albedo_sim"] for r in chosen], **style)
    axes[0].set_yscale("log")
    axes[0].set_ylabel("median |model / table - 1| over cells with signal")
    axes[1].axhline(1.0, color="grey", lw=1)
    axes[1].set_ylabel("directional albedo, model / table")
    for ax in axes:
        ax.set_xlabel("single-scattering albedo c")
    axes[0].legend(fontsize=7)
    fig.suptitle("Lambert-sphere models against the Lambert-sphere half space (faint: theta_i = 0 ... dark: 80 deg)",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(OUT / "medium_models.png", dpi=100)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paths", type=int, default=4_000_000)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    OUT.mkdir(exist_ok=True)
    rows = measure(args.paths, args.workers)
    for r in rows:
        print(f"{r['model']:21s} c = {r['albedo']:<5g} theta_i {r['theta_i_deg']:4.0f}: chi^2 / cell "
              f"{r['chi2_per_cell']:7.2f}, median |rel| {r['median_abs_rel_err']:.4f}, albedo {r['albedo_model']:.5f} vs "
              f"{r['albedo_sim']:.5f} +- {r['albedo_sim_stderr']:.5f} ({r['albedo_model'] / r['albedo_sim'] - 1:+.2%})")
    chart(rows)
    save_figures({"rows": rows, "paths": args.paths}, "medium_models", args.json)
    print(f"wrote {OUT / 'medium_models.png'}")


if __name__ == "__main__":
    main()
