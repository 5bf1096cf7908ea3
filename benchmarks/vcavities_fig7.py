"""V-cavity inter-reflections (the analogue of Fig. 7 of Meneveaux et al. 2015) and where the
Oren-Nayar model stops holding.

(a) Fig. 7: the shipped runs runs/vcavities_{lambert,interfaced_lambert,conductor}.toml (Beckmann
    grooves, roughness 0.8 for the diffuse facets and 0.3 for the near-specular conductor, 3240
    cells, 100 M paths per incidence), traced as they are (tables in benchmarks/out/, reused with
    --reuse). One row per facet material: f1 (order 1), f2 (orders 1
    and 2, the table's brdf_orders12) and f_inf (all orders) on the plane of incidence at
    theta_i = 30 and 60 deg, with their standard errors; a polar map of f_inf at 60 deg; and a
    polar map of the inter-reflected share (f_inf - f1) / f_inf there. Printed per material and
    incidence: the albedos of f1, f2 and f_inf.
(b) Oren-Nayar against V-cavities with the gaussian distribution of Eq. 13 (the one the paper says
    Oren and Nayar use; roughness = sigma in rad, ``microsim.physics.distributions``), Lambertian
    facets of albedo 0.8, sigma from 0.1 to 1.2 rad, theta_i in {0, 30, 60, 80} deg, 3240 cells,
    --paths per incidence: ``microsim.analysis.compare`` of the cell-averaged model against the table,
    median |rel| over the cells with signal (table > 3 standard errors) and the directional
    albedo ratio model / table, for
      - the direct term L1 (``terms = "direct"``) against order 1,
      - L1 + L2 (the full model) against orders 1 + 2 (f2: what its two-bounce term models),
      - the full model against all orders (f_inf).
Writes benchmarks/out/vcavities_fig7.png, vcavities_oren_nayar.png and vcavities_fig7.json.
About 6 minutes on this 2-core machine (--workers 2).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from report import OUT, save_figures

from microsim import config, models, tables
from microsim.analysis import compare
from microsim.analysis.plots import incidence_plane_cells, polar_cells
from microsim.testing import write_table

ROOT = Path(__file__).resolve().parent.parent
MATERIALS = ("lambert", "interfaced_lambert", "conductor")
PLANE_THETA = (30.0, 60.0)
POLAR_THETA = 60.0
SIGMAS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.1, 1.2)
ALBEDO = 0.8
ON_THETA = (0.0, 30.0, 60.0, 80.0)


def shipped_table(material: str, workers: int, reuse: bool) -> tables.Table:
    path = OUT / f"vcavities_{material}.h5"
    if not (reuse and path.exists()):
        cfg = config.load(ROOT / "runs" / f"vcavities_{material}.toml")
        write_table(cfg, path, workers=workers, overwrite=True)
    return tables.load(path)


def incidence(table, theta_deg: float) -> int:
    return int(np.argmin(np.abs(np.degrees(table.theta_i) - theta_deg)))


def fig7(workers: int, reuse: bool) -> dict:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import colors

    fig = plt.figure(figsize=(17, 12))
    figures = {}
    for row, material in enumerate(MATERIALS):
        table = shipped_table(material, workers, reuse)
        a = table.arrays
        curves = {"f1": (table.brdf_order[:, 0], a["brdf_order_stderr"][:, 0]),
                  "f2": (a["brdf_orders12"], a["brdf_orders12_stderr"]),
                  "f_inf": (table.brdf, table.brdf_stderr)}
        albedos = {"f1": a["albedo_order"][:, 0], "f2": a["albedo_orders12"], "f_inf": table.albedo}
        figures[material] = {f"{np.degrees(t):g}": {k: float(v[i]) for k, v in albedos.items()}
                             for i, t in enumerate(table.theta_i)}
        for column, theta in enumerate(PLANE_THETA):
            i = incidence(table, theta)
            ax = fig.add_subplot(3, 4, 4 * row + column + 1)
            x, cells = incidence_plane_cells(table.sensor, table.phi_i[i])
            for name, (values, errors) in curves.items():
                ax.errorbar(x, values[i, cells], yerr=errors[i, cells], fmt="o-", ms=2, lw=1, capsize=1, label=name)
            ax.axvline(-theta, color="grey", ls=":", lw=1, label="retro")
            ax.set_title(f"{material}, theta_i = {theta:g} deg", fontsize=9)
            ax.set_xlabel("theta_o (deg), backscatter < 0", fontsize=8)
            ax.set_ylabel("f (1/sr)", fontsize=8)
            if material == "conductor":
                ax.set_yscale("log")
            ax.legend(fontsize=7)
        i = incidence(table, POLAR_THETA)
        f_inf = table.brdf[i]
        share = np.where(f_inf > 3 * table.brdf_stderr[i], (f_inf - table.brdf_order[i, 0]) / np.where(f_inf > 0, f_inf, 1), np.nan)
        for column, (values, norm, cmap, title) in enumerate((
                (f_inf, colors.Normalize(0, float(np.max(f_inf))) if material != "conductor"
                 else colors.LogNorm(max(float(np.max(f_inf)) * 1e-4, 1e-6), float(np.max(f_inf))),
                 plt.cm.viridis, f"f_inf, theta_i = {POLAR_THETA:g} deg"),
                (share, colors.Normalize(0, max(0.05, float(np.nanmax(share)))), plt.cm.magma,
                 "(f_inf - f1) / f_inf: inter-reflected share"))):
            ax = fig.add_subplot(3, 4, 4 * row + column + 3, projection="polar")
            polar_cells(ax, table.sensor, values, cmap, norm)
            fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax, shrink=0.7, pad=0.1)
            ax.set_title(f"{material}: {title}", fontsize=9, pad=12)
    fig.suptitle("V-cavities, Beckmann grooves (roughness 0.8; conductor 0.3), 3240 cells: f1, f2 = f1 + order 2, "
                 "f_inf (all orders)")
    fig.tight_layout()
    fig.savefig(OUT / "vcavities_fig7.png", dpi=90)
    plt.close(fig)
    return figures


def oren_nayar_study(paths: int, workers: int) -> list[dict]:
    rows = []
    for sigma in SIGMAS:
        cfg = config.validate({
            "scene": {"kind": "vcavities", "distribution": "gaussian", "roughness": sigma},
            "material": {"kind": "lambert", "albedo": ALBEDO},
            "illumination": {"theta_i_deg": list(ON_THETA)}, "sensor": {"cells": 3240},
            "run": {"paths": paths, "realizations": 32, "seed": 1},
        })
        path = OUT / "vcavities_oren_nayar.h5"
        write_table(cfg, path, workers=workers, overwrite=True)
        table = tables.load(path)
        row = {"sigma": sigma}
        for label, terms, order in (("L1 vs order 1", "direct", "1"), ("L1+L2 vs orders 1+2", "full", "1+2"),
                                    ("L1+L2 vs all orders", "full", "all")):
            model = models.create("oren_nayar", albedo=ALBEDO, roughness=sigma, terms=terms)
            result = compare.compare(table, model, order)
            per = [result.metrics(i) for i in range(len(ON_THETA))]
            row[label] = {
                "median_abs_rel_err": result.metrics()["median_abs_rel_err"],
                "median_abs_rel_err_per_theta": [m["median_abs_rel_err"] for m in per],
                "albedo_ratio_per_theta": [m["albedo_model"] / m["albedo_sim"] for m in per],
            }
        rows.append(row)
        print(f"sigma {sigma:4.2f}: " + "; ".join(
            f"{k}: median |rel| {v['median_abs_rel_err']:.3f}, albedo ratio "
            + "/".join(f"{r:.3f}" for r in v["albedo_ratio_per_theta"])
            for k, v in row.items() if k != "sigma"))
    return rows


def oren_nayar_chart(rows: list[dict]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sigma = [r["sigma"] for r in rows]
    labels = [k for k in rows[0] if k != "sigma"]
    fig, (left, right) = plt.subplots(1, 2, figsize=(13, 4.8))
    for k, label in enumerate(labels):
        left.plot(sigma, [r[label]["median_abs_rel_err"] for r in rows], "o-", color=f"C{k}", label=label)
        for j, theta in enumerate(ON_THETA):
            right.plot(sigma, [r[label]["albedo_ratio_per_theta"][j] for r in rows], "o-", color=f"C{k}",
                       alpha=0.35 + 0.65 * j / (len(ON_THETA) - 1), ms=3,
                       label=f"{label}, theta_i = {theta:g}" if j in (0, len(ON_THETA) - 1) else None)
    left.set_xlabel("sigma (rad)")
    left.set_ylabel("median |model / table - 1| over cells with signal")
    left.set_yscale("log")
    left.legend(fontsize=8)
    left.set_title(f"Oren-Nayar vs V-cavities (gaussian D, Lambertian facets, albedo {ALBEDO:g})", fontsize=10)
    right.axhline(1.0, color="grey", lw=1)
    right.set_xlabel("sigma (rad)")
    right.set_ylabel("directional albedo, model / table")
    right.legend(fontsize=7)
    right.set_title("albedo ratio per theta_i (faint: 0 deg ... dark: 80 deg)", fontsize=10)
    fig.tight_layout()
    fig.savefig(OUT / "vcavities_oren_nayar.png", dpi=100)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paths", type=int, default=16_000_000, help="paths per incidence of part (b)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--reuse", action="store_true", help="reuse part (a)'s tables in benchmarks/out")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    OUT.mkdir(exist_ok=True)
    albedos = fig7(args.workers, args.reuse)
    for material, per_theta in albedos.items():
        print(f"{material}: " + "; ".join(f"theta_i {t}: f1 {v['f1']:.4f} f2 {v['f2']:.4f} f_inf {v['f_inf']:.4f}"
                                          for t, v in per_theta.items()))
    rows = oren_nayar_study(args.paths, args.workers)
    oren_nayar_chart(rows)
    print(f"wrote {OUT / 'vcavities_fig7.png'}, {OUT / 'vcavities_oren_nayar.png'}, {OUT / 'vcavities_fig7.json'}")
    save_figures({"fig7_albedos": albedos, "oren_nayar": rows}, "vcavities_fig7", args.json)


if __name__ == "__main__":
    main()
