"""Every albedo from one run (docs/conventions.md §4): its wall time against separate runs, and its
tables against theirs.

For the Lambert-sphere medium and a sphere suspension (phi = 0.3, default tile and depth), albedos
0.3, 0.6, 0.9, 0.99, theta_i = 0 and 60 deg, 3240 cells, --paths per incidence, 32 realizations,
one worker: one run of the four albedos, then four runs of one albedo each (another seed), timed
side by side (best of --repeats, alternated). Printed per albedo and incidence: the mean z^2 per
cell of the joint table against the separate one (errors combined) and the albedo of each. JSON
in benchmarks/out/albedos.json (--json prints it too).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from report import save_figures

from microsim import config
from microsim.testing import trace, trace_albedos

ALBEDOS = [0.3, 0.6, 0.9, 0.99]
SCENES = {"medium": {"kind": "halfspace_medium", "phase": "lambert_sphere"},
          "spheres": {"kind": "poisson_spheres", "volume_fraction": 0.3}}


def settings(scene, albedo, paths, seed):
    return config.validate({"scene": SCENES[scene], "material": {"kind": "lambert", "albedo": albedo},
                            "illumination": {"theta_i_deg": [0.0, 60.0]}, "sensor": {"cells": 3240},
                            "run": {"paths": paths, "realizations": 32, "seed": seed}})


def measure(scene, paths, repeats) -> dict:
    trace(settings(scene, 0.5, 1000, 9))  # compile (or load) the kernels first
    best = {"joint": np.inf, "separate": np.inf}
    for _ in range(repeats):
        start = time.perf_counter()
        joint = trace_albedos(settings(scene, ALBEDOS, paths, 1))
        best["joint"] = min(best["joint"], time.perf_counter() - start)
        start = time.perf_counter()
        separate = [trace(settings(scene, albedo, paths, 2)) for albedo in ALBEDOS]
        best["separate"] = min(best["separate"], time.perf_counter() - start)
    rows = []
    for albedo, a, b in zip(ALBEDOS, joint, separate):
        for i, theta in enumerate((0.0, 60.0)):
            se2 = a.brdf[i].stderr[4] ** 2 + b.brdf[i].stderr[4] ** 2
            ok = se2 > 0
            z2 = float(np.mean((a.brdf[i].mean[4][ok] - b.brdf[i].mean[4][ok]) ** 2 / se2[ok]))
            rows.append({"albedo": albedo, "theta_i_deg": theta, "cells": int(ok.sum()), "chi2_per_cell": z2,
                         "albedo_joint": float(a.albedo[i].mean[4]), "albedo_separate": float(b.albedo[i].mean[4]),
                         "albedo_stderr": float(np.hypot(a.albedo[i].stderr[4], b.albedo[i].stderr[4]))})
    return {"paths": paths, "joint_s": best["joint"], "separate_s": best["separate"],
            "speedup": best["separate"] / best["joint"], "rows": rows}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paths", type=int, default=2_000_000)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    figures = {}
    for scene in SCENES:
        f = figures[scene] = measure(scene, args.paths, args.repeats)
        print(f"{scene}: four albedos in one run {f['joint_s']:.1f} s, in four runs {f['separate_s']:.1f} s "
              f"({f['speedup']:.2f} x)")
        for row in f["rows"]:
            print(f"  c = {row['albedo']:<5g} theta_i {row['theta_i_deg']:4.0f}: chi^2 / cell {row['chi2_per_cell']:.3f} "
                  f"({row['cells']} cells); albedo {row['albedo_joint']:.5f} vs {row['albedo_separate']:.5f} "
                  f"(+- {row['albedo_stderr']:.5f})")
    save_figures(figures, "albedos", args.json)


if __name__ == "__main__":
    main()
