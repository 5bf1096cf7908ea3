"""Do the sphere defaults model enough? Tile and depth biases against 2x and 4x.

For each (volume fraction, albedo) the default config is run beside the same config with the
tile, then the depth, doubled and quadrupled; the 4x run is the reference. Exact native spheres
are the default, so the tessellation bias of the default is nil by construction; the icosphere
fallback of the embreex backend is measured by ``benchmarks/tessellation.py``.

Printed per case, incidence and choice: the albedo's relative bias against the 4x reference
with its standard error (independent runs, so the errors add in quadrature), and chi^2 per
cell of the BRDF (400 cells) against the reference (about 1 when they agree); and the bound on
the depth's bias that needs no reference: the slab loses only the light that crosses its bottom,
so its albedo is low by at most energy/transmitted. The rule:
every bias below max(se/3, 0.3 %), se the relative standard error of the albedo
that a default run (1 M paths, 32 realizations, as in runs/) reaches. A bias counts as over
the bound only if it is over it by more than two of its standard errors, and as settled below
it only if bias + 2 se is under it; anything else is reported as not resolved.

    python benchmarks/sphere_defaults.py [--cases phi:c ...] [--paths N] [--realizations R]

Writes benchmarks/out/sphere_defaults.json and .png. About 20 minutes on 2 cores by default.
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np
from report import OUT, save_figures

from microsim import config as config_module
from microsim.core.orders import RESULT_ALL_ORDERS
from microsim.core.tally import TRANSMITTED
from microsim.geometry import poisson_spheres
from microsim.testing import trace

THETA_I_DEG = [0.0, 60.0, 85.0]
CELLS = 400
DEFAULT_RUN = {"paths": 1_000_000, "realizations": 32}
BIAS_FLOOR = 0.003


def sphere_config(phi, albedo, paths, realizations, seed, **scene):
    return config_module.validate({
        "scene": {"kind": "poisson_spheres", "volume_fraction": phi, **scene},
        "material": {"kind": "lambert", "albedo": albedo},
        "illumination": {"theta_i_deg": THETA_I_DEG},
        "sensor": {"cells": CELLS},
        "run": {"paths": paths, "realizations": realizations, "seed": seed},
    })


def default_scene(phi, albedo):
    """The resolved default tile and depth of a case (the generator's rule)."""
    resolved = poisson_spheres.resolve(sphere_config(phi, albedo, 1000, 2, 1))
    return resolved["tile"], resolved["depth"]


def measure(cfg, threads):
    start = time.perf_counter()
    result = trace(cfg, threads=threads)
    seconds = time.perf_counter() - start
    return {
        "albedo": [float(a.mean[RESULT_ALL_ORDERS]) for a in result.albedo],
        "albedo_stderr": [float(a.stderr[RESULT_ALL_ORDERS]) for a in result.albedo],
        "brdf": [b.mean[RESULT_ALL_ORDERS] for b in result.brdf],
        "brdf_stderr": [b.stderr[RESULT_ALL_ORDERS] for b in result.brdf],
        "transmitted": [float(e.mean[TRANSMITTED]) for e in result.energy],
        "seconds": seconds,
    }


def against(run, reference, i, paths, realizations):
    """Relative albedo bias of ``run`` against ``reference`` at incidence i, and BRDF chi^2 per cell."""
    a, b = run["albedo"][i], reference["albedo"][i]
    se = math.hypot(run["albedo_stderr"][i], reference["albedo_stderr"][i])
    per_realization = run["albedo_stderr"][i] * math.sqrt(min(realizations / DEFAULT_RUN["realizations"],
                                                               paths / DEFAULT_RUN["paths"]))
    bound = max(per_realization / a / 3.0, BIAS_FLOOR)
    rel, rel_se = a / b - 1.0, se / b
    signal = reference["brdf"][i] > 0
    z = (run["brdf"][i] - reference["brdf"][i])[signal] / np.hypot(run["brdf_stderr"][i], reference["brdf_stderr"][i])[signal]
    if abs(rel) - 2.0 * rel_se > bound:
        verdict = "OVER"
    elif abs(rel) + 2.0 * rel_se < bound:
        verdict = "below"
    else:
        verdict = "not resolved"
    return {"bias": rel, "bias_stderr": rel_se, "bound": bound, "verdict": verdict,
            "chi2_per_cell": float(np.mean(z * z)), "cells": int(signal.sum())}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="+", default=["0.02:0.8", "0.1:0.8", "0.3:0.8", "0.6:0.8", "0.3:0.99", "0.6:0.99"],
                        help="volume_fraction:albedo pairs (the depth rule is in optical depth, so albedo 0.99 is "
                             "measured where it is cheap)")
    parser.add_argument("--paths", type=int, default=8_000_000, help="per incidence, at albedo 0.8; halved at 0.99")
    parser.add_argument("--realizations", type=int, default=1024)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--seed", type=int, default=31)
    parser.add_argument("--merge", action="store_true",
                        help="keep the cases of benchmarks/out/sphere_defaults.json that this run does not repeat")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    figures = {"theta_i_deg": THETA_I_DEG, "cells": CELLS, "cases": []}
    previous = OUT / "sphere_defaults.json"
    if args.merge and previous.exists():
        repeated = {tuple(map(float, case.split(":"))) for case in args.cases}
        figures["cases"] = [case for case in json.loads(previous.read_text())["cases"]
                            if (case["volume_fraction"], case["albedo"]) not in repeated]
    print("phi    c     choice    tile   depth   theta  albedo    bias vs 4x        bound   verdict       chi2/cell  seconds")
    for phi, albedo in (map(float, case.split(":")) for case in args.cases):
        paths = args.paths if albedo < 0.95 else args.paths // 2
        tile, depth = default_scene(phi, albedo)
        choices = {"default": {}}
        for factor in (2, 4):
            choices[f"tile x{factor}"] = {"tile": factor * tile}
            choices[f"depth x{factor}"] = {"depth": factor * depth}
        runs = {}
        for k, (name, scene) in enumerate(choices.items()):
            cfg = sphere_config(phi, albedo, paths, args.realizations, args.seed + 1000 * k, **scene)
            runs[name] = measure(cfg, args.threads)
        case = {"volume_fraction": phi, "albedo": albedo, "default_tile": tile, "default_depth": depth,
                "paths": paths, "realizations": args.realizations, "choices": {}}
        for name, scene in choices.items():
            if name == "default":
                continue
            case["choices"][name] = {**scene, "seconds": runs[name]["seconds"],
                                     "transmitted": runs[name]["transmitted"]}
        case["choices"]["default"] = {"seconds": runs["default"]["seconds"],
                                      "transmitted": runs["default"]["transmitted"]}
        for what in ("tile", "depth"):
            reference = runs[f"{what} x4"]
            for name in ("default", f"{what} x2"):
                rows = [against(runs[name], reference, i, paths, args.realizations) for i in range(len(THETA_I_DEG))]
                case["choices"][name][f"vs {what} x4"] = rows
                for i, row in enumerate(rows):
                    size = choices[name].get("tile", tile), choices[name].get("depth", depth)
                    print(f"{phi:<6} {albedo:<5} {name:<9} {size[0]:6.1f} {size[1]:7.1f} {THETA_I_DEG[i]:5.0f}  "
                          f"{runs[name]['albedo'][i]:.5f}  {100 * row['bias']:+6.3f} +- {100 * row['bias_stderr']:.3f} %  "
                          f"{100 * row['bound']:.2f} %  {row['verdict']:<12} {row['chi2_per_cell']:6.2f}  "
                          f"{runs[name]['seconds']:7.1f}", flush=True)
        transmitted = runs["default"]["transmitted"]
        print(f"{phi:<6} {albedo:<5} default depth: transmitted " + " ".join(f"{t:.2e}" for t in transmitted)
              + ", so the depth bias is within 0 and -" + " ".join(
                  f"{100 * t / a:.3f}" for t, a in zip(transmitted, runs["default"]["albedo"])) + " %", flush=True)
        case["depth_bias_bound"] = [t / a for t, a in zip(transmitted, runs["default"]["albedo"])]
        figures["cases"].append(case)
        save_figures(figures, "sphere_defaults", False)
    save_figures(figures, "sphere_defaults", args.json)
    plot(figures)


def plot(figures):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    for ax, what in zip(axes, ("tile", "depth")):
        for case in figures["cases"]:
            for name, marker in (("default", "o"), (f"{what} x2", "s")):
                rows = case["choices"][name][f"vs {what} x4"]
                x = np.array(figures["theta_i_deg"]) + (1.5 if name != "default" else 0.0)
                ax.errorbar(x, [100 * r["bias"] for r in rows], [200 * r["bias_stderr"] for r in rows], fmt=marker,
                            label=f"phi {case['volume_fraction']}, c {case['albedo']}, {name}", ms=4, capsize=2)
        ax.axhspan(-100 * BIAS_FLOOR, 100 * BIAS_FLOOR, color="0.9", zorder=0)
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_xlabel("theta_i (deg)")
        ax.set_title(f"albedo bias against {what} x4 (2 se bars; band: 0.3 %)")
    axes[0].set_ylabel("relative albedo bias (%)")
    axes[1].legend(fontsize=6, ncol=2)
    fig.tight_layout()
    OUT.mkdir(exist_ok=True)
    fig.savefig(OUT / "sphere_defaults.png", dpi=120)


if __name__ == "__main__":
    main()
