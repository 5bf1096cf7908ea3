"""Packed against Boolean spheres, and both against radiative transfer: the packing study.

``--part dilute`` (the dilute limit): at phi = 0.01, albedo 0.8, theta_i = 0, 30, 60, 80 deg,
default tile and depth, --cells cells, --paths paths an incidence over 16 realizations: tables of
``packed_spheres``, ``poisson_spheres`` and the half space of Lambert-sphere point scatterers
(``halfspace_medium``, the radiative-transfer limit both tend to), each pair compared cell by
cell (``compare`` of one table against the other, :class:`~microsim.models.tabulated.TabulatedBRDF`):
chi-square per cell with its two-sided bounds, the albedos' mean z^2 with its bound, the median
|rel| over the cells with signal, and the albedos. JSON in benchmarks/out/packing_study.json.

    python benchmarks/packing_study.py --part dilute [--paths 400000] [--workers 2]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from report import save_figures

from microsim import config
from microsim.analysis import compare
from microsim.models.tabulated import TabulatedBRDF
from microsim.testing import trace_table

THETA_I = [0.0, 30.0, 60.0, 80.0]
SCENES = {"packed": {"kind": "packed_spheres", "volume_fraction": 0.01},
          "boolean": {"kind": "poisson_spheres", "volume_fraction": 0.01},
          "transfer": {"kind": "halfspace_medium", "phase": "lambert_sphere"}}


def table(directory: Path, scene: dict, albedo: float, paths: int, cells: int, workers: int):
    cfg = config.validate({"scene": scene, "material": {"kind": "lambert", "albedo": albedo},
                           "illumination": {"theta_i_deg": THETA_I}, "sensor": {"cells": cells},
                           "run": {"paths": paths, "realizations": 16, "seed": 11}})
    start = time.perf_counter()
    traced = trace_table(cfg, directory / f"{scene['kind']}-{albedo}.h5", workers=workers)
    return traced, time.perf_counter() - start


def pair(a, b) -> dict:
    """``a`` against ``b`` cell by cell: the figures of the module doc."""
    comparison = compare.compare(a, TabulatedBRDF(b))
    metrics = comparison.metrics()
    return {"chi2_per_cell": round(metrics["chi2_per_cell"], 4), "chi2_bounds": [round(x, 4) for x in metrics["chi2_bounds"]],
            "albedo_z2": round(metrics["albedo_z2"], 3), "albedo_z2_bound": round(metrics["albedo_z2_bound"], 3),
            "median_abs_rel": round(float(metrics["median_abs_rel_err"]), 4), "consistent": metrics["consistent"]}


def dilute(args) -> dict:
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        tables = {}
        for name, scene in SCENES.items():
            tables[name], seconds = table(Path(tmp), scene, 0.8, args.paths, args.cells, args.workers)
            out[f"{name} albedo"] = np.round(tables[name].albedo, 5).tolist()
            out[f"{name} albedo stderr"] = np.round(tables[name].albedo_stderr, 5).tolist()
            out[f"{name} seconds"] = round(seconds, 1)
            print(f"{name}: albedo {out[f'{name} albedo']} +- {out[f'{name} albedo stderr']} ({seconds:.1f} s)", flush=True)
        for a, b in (("packed", "boolean"), ("packed", "transfer"), ("boolean", "transfer")):
            out[f"{a} against {b}"] = figures = pair(tables[a], tables[b])
            print(f"{a} against {b}: {figures}", flush=True)
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", choices=["dilute"], default="dilute")
    parser.add_argument("--paths", type=int, default=400_000)
    parser.add_argument("--cells", type=int, default=400)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--json", action="store_true", help="print the figures as JSON on the last line")
    args = parser.parse_args()
    figures = {"dilute": dilute(args)}
    save_figures(figures, "packing_study", args.json)


if __name__ == "__main__":
    main()
