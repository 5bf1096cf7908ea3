"""The sphere-suspension study: where point-scatterer
models of Boolean Lambertian spheres hold, and by how much they fail.

For volume fractions PHIS, one multi-albedo run of explicit spheres (albedos ALBEDOS traced
together, docs/conventions.md §4) and one of the Lambert-sphere medium (halfspace_medium, the
radiative transfer of the same phase function), theta_i in THETA_I_DEG, CELLS sensor cells and RETRO_RINGS
retro rings out to a phase angle that scales with r / l. Tables are kept in
benchmarks/out/sphere_study/ and reused (``--rerun`` traces them again). Then:

1. explicit against medium, per (phi, c, theta_i) and per order (1, 2, 3, 4+, all): albedo ratio
   with its standard error; median |rel| of the BRDF over the cells where both have signal, beside
   the median |rel| that noise alone gives (0.674 x the median relative standard error of the
   difference); chi^2 per cell; and the signed median of (explicit / medium - 1) over cells more
   than 10 deg from retro, with what the finite-size single-scattering model
   (``boolean_spheres_single``) predicts on the same cells for order 1. The measured law is a
   least-squares power law a (r / l)^b of the order albedo ratio - 1 over phi <= LAW_MAX_PHI.
2. each model against the explicit table (all orders, all incidences): ``lambert_sphere`` exact
   and fit, ``lambert_sphere_fast`` (albedo = c), ``vmf_diffuse`` with its roughness r fitted
   (albedo = c; the paper gives no mapping from phi to r, it chose r by eye per geometry),
   ``oren_nayar`` with sigma fitted (albedo = c), ``lambert`` with its albedo fitted: median |rel|,
   chi^2 per cell, albedo error per theta_i, the fitted parameter. Heat maps phi x c per model.
3. the opposition peak at theta_i = 0 and 30 deg: on the retro rings, the enhancement
   E(gamma) = (f_explicit / f_medium)(gamma) / (same over the outer OUTER_RINGS rings) - 1, which
   divides out the phase function's own slope; its height E(ring 0) with its standard error and
   its half width at half height, for order 1 and for all orders.

    python benchmarks/sphere_study.py [--paths N] [--medium-paths N] [--rerun] [--json]

Writes benchmarks/out/sphere_study.json and sphere_study_{medium,models,opposition}.png.
About 25 minutes on 2 cores at the defaults (the tables take most of it).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
from opposition import half_width
from report import OUT, save_figures

from microsim import config, models, tables
from microsim.analysis import compare
from microsim.analysis.fit import fit
from microsim.analysis.selection import with_signal
from microsim.models.radiative_transfer import single_scattering
from microsim.physics.boolean_model import radius_over_free_path
from microsim.testing import trace_albedos
from microsim.tracer.sensor import Sensor

PHIS = [0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.3, 0.45, 0.6]
ALBEDOS = [0.3, 0.6, 0.9, 0.99]
THETA_I_DEG = [0.0, 30.0, 60.0, 80.0]
CELLS = 800
#: the coarser sensor the BRDFs are also merged onto, where noise would hide a 2 % difference
COARSE_CELLS = 100
RETRO_RINGS = 24
OUTER_RINGS = 4
RETRO_EXCLUSION_DEG = 10.0
LAW_MAX_PHI = 0.1
#: the dilute check: the dilute case, traced again with more paths (albedos up to 0.9: shorter paths)
DILUTE_PHI, DILUTE_ALBEDOS = 0.005, [0.3, 0.6, 0.9]
ORDER_NAMES = ["1", "2", "3", "4+", "all"]
TABLES = OUT / "sphere_study"
#: (label, model, fixed parameters given c, free parameters)
MODELS = [
    ("lambert_sphere exact", "lambert_sphere", lambda c: {"albedo": c, "method": "exact"}, []),
    ("lambert_sphere fit", "lambert_sphere", lambda c: {"albedo": c, "method": "fit"}, []),
    ("lambert_sphere_fast", "lambert_sphere_fast", lambda c: {"albedo": c}, []),
    ("vmf_diffuse, r fitted", "vmf_diffuse", lambda c: {"albedo": c, "roughness": 0.9}, ["roughness"]),
    ("oren_nayar, sigma fitted", "oren_nayar", lambda c: {"albedo": c, "roughness": 0.5}, ["roughness"]),
    ("lambert, albedo fitted", "lambert", lambda c: {"albedo": 0.5}, ["albedo"]),
]


def retro_max_deg(phi: float) -> float:
    """Phase angle the retro rings reach: 8 r / l (the shadow-hiding peak is about r / l wide),
    within [2, 60] deg."""
    return float(min(max(math.degrees(8.0 * radius_over_free_path(phi)), 2.0), 60.0))


def table_path(kind: str, phi: float, c: float) -> Path:
    return TABLES / f"{kind}_phi{phi:g}_albedo{c:g}.h5"


def run_config(kind: str, phi: float, paths: int, seed: int, albedos=ALBEDOS):
    scene = ({"kind": "poisson_spheres", "volume_fraction": phi} if kind.startswith("spheres")
             else {"kind": "halfspace_medium", "phase": "lambert_sphere"})
    return config.validate({
        "name": f"sphere-study-{kind}-phi{phi:g}",
        "scene": scene,
        "material": {"kind": "lambert", "albedo": list(albedos)},
        "illumination": {"theta_i_deg": THETA_I_DEG},
        "sensor": {"cells": CELLS, "retro_rings": RETRO_RINGS, "retro_max_deg": retro_max_deg(phi)},
        "run": {"paths": paths, "realizations": 32, "seed": seed},
    })


def ensure_tables(kind: str, phi: float, paths: int, seed: int, rerun: bool, albedos=ALBEDOS) -> float:
    """Trace the tables of (kind, phi), one per albedo, unless they are there; the seconds it
    took (0 if kept)."""
    targets = [table_path(kind, phi, c) for c in albedos]
    if not rerun and all(p.exists() for p in targets):
        return 0.0
    TABLES.mkdir(parents=True, exist_ok=True)
    cfg = run_config(kind, phi, paths, seed, albedos)
    start = time.perf_counter()
    results = trace_albedos(cfg, threads=2)
    for result, target in zip(results, targets):
        tables.write(target, result, cfg, overwrite=True)
    seconds = time.perf_counter() - start
    print(f"  traced {kind} phi = {phi:g}: {paths:,} paths per incidence in {seconds:.0f} s", flush=True)
    return seconds


def orders(table):
    """(f (5, n_i, n_c), stderr, albedo (5, n_i), stderr): orders 1, 2, 3, 4+ and all."""
    a = table.arrays
    f = np.concatenate([np.moveaxis(a["brdf_order"], 1, 0), a["brdf"][None]])
    fe = np.concatenate([np.moveaxis(a["brdf_order_stderr"], 1, 0), a["brdf_stderr"][None]])
    al = np.concatenate([a["albedo_order"].T, a["albedo"][None]])
    ale = np.concatenate([a["albedo_order_stderr"].T, a["albedo_stderr"][None]])
    return f, fe, al, ale


def coarsened(table, f, stderr):
    """f and its standard error merged onto the COARSE_CELLS cells of a coarser sensor, each cell
    of the table going whole to the coarse cell of its centre (weights: projected solid angles;
    errors combined as independent)."""
    coarse = Sensor.build(COARSE_CELLS)
    group = coarse.lookup(table.direction)
    p = table.projected_solid_angle
    total = np.bincount(group, weights=p, minlength=coarse.n_cells)
    merge = lambda values: np.apply_along_axis(
        lambda v: np.bincount(group, weights=v, minlength=coarse.n_cells), -1, values)
    return merge(f * p) / total, np.sqrt(merge((stderr * p) ** 2)) / total


def explicit_vs_medium(spheres, medium, phi, c):
    """Figures of part 1 for one (phi, c)."""
    f_s, e_s, a_s, ae_s = orders(spheres)
    f_m, e_m, a_m, ae_m = orders(medium)
    cf_s, ce_s = coarsened(spheres, f_s, e_s)
    cf_m, ce_m = coarsened(medium, f_m, e_m)
    wi = spheres.wi
    away = np.degrees(np.arccos(np.clip(spheres.direction @ wi.T, -1, 1))).T > RETRO_EXCLUSION_DEG  # (n_i, n_c)
    out = {}
    for k, name in enumerate(ORDER_NAMES):
        rows = []
        for i in range(len(THETA_I_DEG)):
            ok = with_signal(f_s[k, i], e_s[k, i]) & with_signal(f_m[k, i], e_m[k, i])
            rel = f_s[k, i, ok] / f_m[k, i, ok] - 1.0
            se = np.hypot(e_s[k, i, ok], e_m[k, i, ok])
            z = (f_s[k, i, ok] - f_m[k, i, ok]) / se
            far = ok & away[i]
            ratio = a_s[k, i] / a_m[k, i]
            cok = with_signal(cf_s[k, i], ce_s[k, i]) & with_signal(cf_m[k, i], ce_m[k, i])
            crel = cf_s[k, i, cok] / cf_m[k, i, cok] - 1.0
            cse = np.hypot(ce_s[k, i, cok], ce_m[k, i, cok])
            rows.append({
                "theta_i_deg": THETA_I_DEG[i],
                "albedo_ratio": float(ratio),
                "albedo_ratio_stderr": float(ratio * math.hypot(ae_s[k, i] / a_s[k, i], ae_m[k, i] / a_m[k, i])),
                "median_abs_rel": float(np.median(np.abs(rel))) if rel.size else None,
                "noise_median_abs_rel": float(0.674 * np.median(se / f_m[k, i, ok])) if rel.size else None,
                "chi2_per_cell": float(np.mean(z * z)) if rel.size else None,
                "signed_median_rel_away_from_retro": (float(np.median(f_s[k, i, far] / f_m[k, i, far] - 1.0))
                                                      if far.any() else None),
                "cells": int(ok.sum()),
                "coarse_median_abs_rel": float(np.median(np.abs(crel))) if crel.size else None,
                "coarse_noise_median_abs_rel": float(0.674 * np.median(cse / cf_m[k, i, cok])) if crel.size else None,
                "coarse_chi2_per_cell": float(np.mean(((cf_s[k, i, cok] - cf_m[k, i, cok]) / cse) ** 2))
                if crel.size else None,
                "coarse_cells": int(cok.sum()),
            })
        out[name] = rows
    return out


def order1_model_excess(spheres, phi, c):
    """Signed median of (boolean_spheres_single / radiative transfer - 1) over the cells with
    order-1 signal more than 10 deg from retro, per theta_i: the finite-size model's prediction."""
    model = models.create("boolean_spheres_single", albedo=c, volume_fraction=phi)
    f_s, e_s, _, _ = orders(spheres)
    out = []
    for i, wi in enumerate(spheres.wi):
        away = np.degrees(np.arccos(np.clip(spheres.direction @ wi, -1, 1))) > RETRO_EXCLUSION_DEG
        ok = away & with_signal(f_s[0, i], e_s[0, i])
        w, weight = spheres.sensor.cell_quadrature(2, 2, np.flatnonzero(ok))
        wis = np.broadcast_to(wi, w.reshape(-1, 3).shape)
        finite = np.sum(model(wis, w.reshape(-1, 3)).reshape(weight.shape) * weight, axis=1)
        rt = np.sum(single_scattering(wis, w.reshape(-1, 3), c).reshape(weight.shape) * weight, axis=1)
        out.append(float(np.median(finite / rt - 1.0)))
    return out


def model_figures(spheres, c):
    """Part 2 for one table: every model of MODELS, fitted where it has free parameters."""
    out = {}
    for label, name, fixed, free in MODELS:
        start = time.perf_counter()
        if free:
            result = fit(spheres, name, free, fixed(c))
            comparison, fitted = result.comparison, {k: v for k, v in result.free.items()}
        else:
            comparison, fitted = compare.compare(spheres, models.create(name, **fixed(c))), {}
        overall = comparison.metrics()
        out[label] = {
            "median_abs_rel": overall["median_abs_rel_err"],
            "chi2_per_cell": overall["chi2_per_cell"],
            "albedo_error": [float(m / s - 1.0) for m, s in zip(comparison.albedo_model, comparison.albedo_sim)],
            "fitted": {k: {"value": v, "stderr": e} for k, (v, e) in fitted.items()},
            "seconds": time.perf_counter() - start,
        }
    return out


def opposition(spheres, medium):
    """Part 3: height and half width of the retro enhancement at theta_i = 0 and 30 deg."""
    lo, hi = spheres.arrays["sensor/retro_gamma_lo"], spheres.arrays["sensor/retro_gamma_hi"]
    centre = np.degrees(0.5 * (lo + hi))
    out = {"gamma_deg": centre.tolist()}
    for order_name, key in (("1", "brdf_retro_order"), ("all", "brdf_retro")):
        rows = []
        for i in (0, 1):
            fs, es = spheres.arrays[key][i], spheres.arrays[key + "_stderr"][i]
            fm, em = medium.arrays[key][i], medium.arrays[key + "_stderr"][i]
            if key == "brdf_retro_order":
                fs, es, fm, em = fs[0], es[0], fm[0], em[0]
            ratio = fs / fm
            ratio_se = ratio * np.hypot(es / fs, em / fm)
            base = ratio[-OUTER_RINGS:].mean()
            enhancement = ratio / base - 1.0
            height, height_se = float(enhancement[0]), float(ratio_se[0] / base)
            hwhm = half_width(centre, enhancement) if height > 3.0 * height_se else None
            rows.append({"theta_i_deg": THETA_I_DEG[i], "height": height, "height_stderr": height_se,
                         "hwhm_deg": hwhm, "enhancement": enhancement.tolist(),
                         "enhancement_stderr": (ratio_se / base).tolist()})
        out[order_name] = rows
    return out


def power_law(x, y, e):
    """Weighted least squares of log |y| = log |a| + b log x over the points where |y| > 2 e
    (all of one sign); (a, b), a carrying the sign, or None if fewer than 2 points qualify or the
    signs differ."""
    x, y, e = map(np.asarray, (x, y, e))
    ok = np.abs(y) > 2.0 * e
    if ok.sum() < 2 or len(set(np.sign(y[ok]))) > 1:
        return None
    b, log_a = np.polyfit(np.log(x[ok]), np.log(np.abs(y[ok])), 1, w=np.abs(y[ok]) / e[ok])
    return float(np.sign(y[ok][0]) * math.exp(log_a)), float(b)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--phis", type=float, nargs="+", default=PHIS)
    parser.add_argument("--paths", type=int, default=1_000_000, help="explicit spheres, per incidence")
    parser.add_argument("--medium-paths", type=int, default=4_000_000)
    parser.add_argument("--seed", type=int, default=41)
    parser.add_argument("--dilute-paths", type=int, default=4_000_000,
                        help="explicit spheres at phi = DILUTE_PHI for the dilute check (medium: 4x); 0 skips it")
    parser.add_argument("--rerun", action="store_true")
    parser.add_argument("--from-json", action="store_true",
                        help="redo the laws and the charts from benchmarks/out/sphere_study.json, tracing nothing")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.from_json:
        figures = json.loads((OUT / "sphere_study.json").read_text())
        figures["laws"] = laws(figures)
        for line in describe_laws(figures["laws"]):
            print(line)
        save_figures(figures, "sphere_study", args.json)
        plot(figures)
        return

    figures = {"phis": args.phis, "albedos": ALBEDOS, "theta_i_deg": THETA_I_DEG, "cells": CELLS,
               "paths": args.paths, "medium_paths": args.medium_paths, "cases": []}
    for phi in args.phis:
        seconds = ensure_tables("spheres", phi, args.paths, args.seed, args.rerun)
        ensure_tables("medium", phi, args.medium_paths, args.seed + 1, args.rerun)
        for c in ALBEDOS:
            spheres, medium = tables.load(table_path("spheres", phi, c)), tables.load(table_path("medium", phi, c))
            case = {"volume_fraction": phi, "albedo": c, "r_over_l": radius_over_free_path(phi),
                    "retro_max_deg": retro_max_deg(phi), "trace_seconds": seconds,
                    "vs_medium": explicit_vs_medium(spheres, medium, phi, c),
                    "models": model_figures(spheres, c), "opposition": opposition(spheres, medium)}
            if phi <= LAW_MAX_PHI:
                case["order1_model_excess"] = order1_model_excess(spheres, phi, c)
            figures["cases"].append(case)
            report_case(case)
            save_figures(figures, "sphere_study", False)
    if args.dilute_paths:
        figures["dilute_check"] = dilute_check(args)
    figures["laws"] = laws(figures)
    for line in describe_laws(figures["laws"]):
        print(line)
    save_figures(figures, "sphere_study", args.json)
    plot(figures)


def dilute_check(args):
    """The dilute check: at phi = DILUTE_PHI, every order of the explicit table against the medium,
    on the COARSE_CELLS sensor, from runs precise enough that noise does not hide 2 %."""
    ensure_tables("spheres_dilute", DILUTE_PHI, args.dilute_paths, args.seed + 2, args.rerun, DILUTE_ALBEDOS)
    ensure_tables("medium_dilute", DILUTE_PHI, 4 * args.dilute_paths, args.seed + 3, args.rerun, DILUTE_ALBEDOS)
    out = {"volume_fraction": DILUTE_PHI, "paths": args.dilute_paths, "medium_paths": 4 * args.dilute_paths}
    print(f"Dilute check: phi = {DILUTE_PHI}, {args.dilute_paths:,} paths, {COARSE_CELLS} cells: median |rel| "
          "(noise alone) / chi^2 per cell / albedo ratio, theta_i " + " ".join(f"{t:g}" for t in THETA_I_DEG))
    for c in DILUTE_ALBEDOS:
        vs = explicit_vs_medium(tables.load(table_path("spheres_dilute", DILUTE_PHI, c)),
                                tables.load(table_path("medium_dilute", DILUTE_PHI, c)), DILUTE_PHI, c)
        out[str(c)] = vs
        for name in ORDER_NAMES:
            print(f"  c {c} order {name:<3}: " + "  ".join(
                f"{100 * r['coarse_median_abs_rel']:.2f}% ({100 * r['coarse_noise_median_abs_rel']:.2f}%) / "
                f"{r['coarse_chi2_per_cell']:.2f} / {r['albedo_ratio']:.4f}+-{r['albedo_ratio_stderr']:.4f}"
                for r in vs[name]), flush=True)
    return out


def report_case(case):
    vs = case["vs_medium"]
    parts = []
    for name in ORDER_NAMES:
        r = vs[name]
        parts.append(f"o{name}: " + " ".join(f"{x['albedo_ratio']:.4f}" for x in r))
    print(f"phi {case['volume_fraction']:<6g} c {case['albedo']:<5g} albedo explicit/medium by theta_i | "
          + " | ".join(parts), flush=True)
    print("    median|rel| all orders (noise): " + " ".join(
        f"{x['median_abs_rel']:.3f} ({x['noise_median_abs_rel']:.3f})" for x in vs["all"]), flush=True)
    for label, m in case["models"].items():
        errors = " ".join(f"{e:+.3f}" for e in m["albedo_error"])
        fitted = ", ".join(f"{k} = {v['value']:.3g}" for k, v in m["fitted"].items())
        print(f"    {label:<26} median|rel| {m['median_abs_rel']:.3f}  chi2/cell {m['chi2_per_cell']:9.2f}  "
              f"albedo error at theta_i 0..80: {errors}  {fitted}", flush=True)
    opp = case["opposition"]
    print("    opposition at theta_i 0: order 1 height {:.3f} +- {:.3f}, hwhm {} deg; all orders {:.3f} +- {:.3f}, "
          "hwhm {} deg".format(opp["1"][0]["height"], opp["1"][0]["height_stderr"], _fmt(opp["1"][0]["hwhm_deg"]),
                               opp["all"][0]["height"], opp["all"][0]["height_stderr"], _fmt(opp["all"][0]["hwhm_deg"])),
          flush=True)


def _fmt(value):
    return "n/a" if value is None else f"{value:.2f}"


def laws(figures):
    """Per albedo and order: the power law of (albedo ratio - 1) in r / l over phi <= LAW_MAX_PHI,
    averaged over theta_i 0-60 deg; and for order 1, the model's predicted excess beside the measured one."""
    out = {}
    for c in ALBEDOS:
        cases = [k for k in figures["cases"] if k["albedo"] == c and k["volume_fraction"] <= LAW_MAX_PHI]
        if len(cases) < 2:
            continue
        x = [k["r_over_l"] for k in cases]
        per_order = {}
        for name in ORDER_NAMES:
            y = [np.mean([r["albedo_ratio"] - 1.0 for r in k["vs_medium"][name][:3]]) for k in cases]
            e = [np.sqrt(np.mean([r["albedo_ratio_stderr"] ** 2 for r in k["vs_medium"][name][:3]]) / 3) for k in cases]
            per_order[name] = {"r_over_l": x, "excess": [float(v) for v in y], "excess_stderr": [float(v) for v in e],
                               "power_law": power_law(x, y, e)}
        per_order["1"]["measured_median_excess_away_from_retro"] = [
            float(np.mean([r["signed_median_rel_away_from_retro"] for r in k["vs_medium"]["1"][:3]])) for k in cases]
        per_order["1"]["model_median_excess_away_from_retro"] = [float(np.mean(k["order1_model_excess"][:3])) for k in cases]
        out[str(c)] = per_order
    return out


def describe_laws(laws_by_albedo):
    lines = ["Measured law, explicit / medium - 1 in albedo, theta_i 0-60 mean, phi <= %g:" % LAW_MAX_PHI]
    for c, per_order in laws_by_albedo.items():
        for name in ORDER_NAMES:
            law = per_order[name]["power_law"]
            values = " ".join(f"{v:+.4f}" for v in per_order[name]["excess"])
            lines.append(f"  c {c} order {name}: {values}  ->  "
                         + ("not resolved" if law is None else f"{law[0]:.3g} (r/l)^{law[1]:.2f}"))
        measured = " ".join(f"{v:+.4f}" for v in per_order["1"]["measured_median_excess_away_from_retro"])
        predicted = " ".join(f"{v:+.4f}" for v in per_order["1"]["model_median_excess_away_from_retro"])
        lines.append(f"  c {c} order 1, median cell excess away from retro: measured {measured}; model {predicted}")
    return lines


def plot(figures):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = figures["cases"]
    phis, albedos = figures["phis"], figures["albedos"]
    # 1. explicit / medium albedo ratio by order, theta_i = 0
    fig, axes = plt.subplots(1, len(albedos), figsize=(4 * len(albedos), 3.6), sharey=True)
    for ax, c in zip(axes, albedos):
        sel = [k for k in cases if k["albedo"] == c]
        x = [k["r_over_l"] for k in sel]
        for name in ORDER_NAMES:
            y = [k["vs_medium"][name][0]["albedo_ratio"] - 1.0 for k in sel]
            e = [k["vs_medium"][name][0]["albedo_ratio_stderr"] for k in sel]
            ax.errorbar(x, y, e, marker="o", ms=3, capsize=2, label=f"order {name}")
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_xscale("log")
        ax.set_title(f"c = {c}: explicit / medium - 1 (albedo, theta_i 0)")
        ax.set_xlabel("r / l")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(OUT / "sphere_study_medium.png", dpi=110)
    plt.close(fig)
    # 2. model-failure maps
    labels = [m[0] for m in MODELS]
    fig, axes = plt.subplots(2, len(labels), figsize=(2.9 * len(labels), 7.0), constrained_layout=True)
    for col, label in enumerate(labels):
        for row, (what, title) in enumerate((("median_abs_rel", "median |rel|"), ("albedo_error", "max |albedo error|"))):
            grid = np.full((len(phis), len(albedos)), np.nan)
            for k in cases:
                value = k["models"][label][what]
                grid[phis.index(k["volume_fraction"]), albedos.index(k["albedo"])] = (
                    np.max(np.abs(value)) if what == "albedo_error" else value)
            ax = axes[row, col]
            image = ax.imshow(100 * grid, origin="lower", aspect="auto", cmap="magma_r", vmin=0, vmax=30)
            for (p, a), v in np.ndenumerate(grid):
                ax.text(a, p, f"{100 * v:.1f}", ha="center", va="center", fontsize=6,
                        color="w" if 100 * v > 15 else "k")
            ax.set_xticks(range(len(albedos)), [f"{a:g}" for a in albedos], fontsize=7)
            ax.set_yticks(range(len(phis)), [f"{p:g}" for p in phis], fontsize=7)
            ax.set_title(f"{label}\n{title} (%)", fontsize=8)
            if col == 0:
                ax.set_ylabel("volume fraction")
            if row == 1:
                ax.set_xlabel("particle albedo c")
    fig.colorbar(image, ax=axes, shrink=0.5, label="% (colour clipped at 30)")
    fig.savefig(OUT / "sphere_study_models.png", dpi=110)
    plt.close(fig)
    # 3. opposition peak
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for c in albedos:
        sel = [k for k in cases if k["albedo"] == c]
        x = [k["volume_fraction"] for k in sel]
        for order_name, marker in (("1", "o"), ("all", "s")):
            h = [k["opposition"][order_name][0]["height"] for k in sel]
            he = [k["opposition"][order_name][0]["height_stderr"] for k in sel]
            axes[0].errorbar(x, h, he, marker=marker, ms=3, capsize=2, label=f"c {c}, order {order_name}")
            w = [k["opposition"][order_name][0]["hwhm_deg"] for k in sel]
            axes[1].plot([a for a, b in zip(x, w) if b is not None], [b for b in w if b is not None], marker=marker,
                         ms=3, label=f"c {c}, order {order_name}")
    x = np.array(phis)
    axes[1].plot(x, np.degrees([radius_over_free_path(p) for p in x]), "k--", lw=0.8, label="r / l (deg)")
    for ax, title in zip(axes, ("height of the retro enhancement, theta_i 0", "half width at half height (deg)")):
        ax.set_xscale("log")
        ax.set_xlabel("volume fraction")
        ax.set_title(title)
    axes[1].set_yscale("log")
    axes[0].legend(fontsize=6, ncol=2)
    fig.tight_layout()
    fig.savefig(OUT / "sphere_study_opposition.png", dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
