"""Smooth shading (interpolated vertex normals) against flat and exact shading, and what it costs
in reciprocity.

1. Convergence. Boolean spheres (phi 0.3, tile 10, depth 6) as icospheres of level 1-3, traced
   three ways on the same realizations (the same centres and rotations): ``exact`` (hits projected
   onto the sphere, its normal: the reference), ``flat`` (each triangle its own facet) and
   ``smooth`` (vertex normals interpolated). Mirror spheres, where the normal matters most (every
   order), and Lambertian ones (albedo 0.8). Per incidence: chi-square per cell of each shading
   against exact (both errors; the paths of the three share their random streams, so the noise
   is partly common and values near 1 or below mean "not distinguished"), and the albedo
   difference.
2. Reciprocity. The anisotropic ridges height array of microsim.testing.surfaces (tests/test_periodic_tile_physics.py) at 4,
   8, 16 and 32 samples a period, Lambertian (albedo 0.8), ring-centre incidences: the largest z of
   the 45 matching pairs and the mean relative asymmetry |f(a->b) - f(b->a)| / mean, flat and
   smooth. Smooth shading keeps energy exactly (the particle's weight is the material's, whatever
   the normal; a direction sampled under the facet meets the surface again) and therefore cannot
   be reciprocal (Veach 1996): the asymmetry is that of f |wo.ns| / |wo.ng| and shrinks as the
   mesh resolves the surface.

    python benchmarks/smooth_shading.py [--paths 400000] [--levels 1 2 3] [--samples 4 8 16 32] [--json]

Results: docs/validation/benchmarks.md ("Smooth shading").
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from report import save_figures  # benchmarks/report.py, beside this script

from microsim import config, tables
from microsim.testing import write_table
from microsim.testing.reciprocity import RECIPROCITY_CELLS, reciprocity_z, ring_incidences
from microsim.testing.surfaces import ridges

INCIDENCES = [0.0, 60.0, 85.0]
MATERIALS = {"mirror": {"kind": "mirror"}, "lambert": {"kind": "lambert", "albedo": 0.8}}


def run_table(data: dict, directory: Path) -> tables.Table:
    cfg = config.validate(data)
    path = directory / "table.h5"
    path.unlink(missing_ok=True)
    write_table(cfg, path)
    return tables.load(path)


def convergence(paths: int, levels, directory: Path) -> dict:
    out = {}
    for material, spec in MATERIALS.items():
        for level in levels:
            results = {}
            for shading in ("exact", "flat", "smooth"):
                start = time.perf_counter()
                results[shading] = run_table({
                    "scene": {"kind": "poisson_spheres", "volume_fraction": 0.3, "tile": 10.0, "depth": 6.0,
                              "subdivisions": level, "shading": shading},
                    "material": spec, "illumination": {"theta_i_deg": INCIDENCES}, "sensor": {"cells": 100},
                    "run": {"paths": paths, "realizations": 4, "seed": 3}}, directory)
                seconds = time.perf_counter() - start
                print(f"{material} level {level} {shading}: {seconds:.0f} s, albedo {results[shading].albedo.round(4)}",
                      flush=True)
            exact = results["exact"]
            for shading in ("flat", "smooth"):
                table = results[shading]
                chi2 = ((table.brdf - exact.brdf) ** 2 / (table.brdf_stderr**2 + exact.brdf_stderr**2)).mean(axis=1)
                out[f"{material}/level{level}/{shading}"] = {
                    "chi2_per_cell": chi2.round(3).tolist(),
                    "albedo_difference": (table.albedo - exact.albedo).round(5).tolist(),
                    "albedo_stderr": exact.albedo_stderr.round(5).tolist()}
                difference = (table.albedo - exact.albedo).round(4)
                print(f"   {shading}: chi2/cell {chi2.round(2)}, albedo - exact {difference}")
    return out


def reciprocity(paths: int, samples, directory: Path) -> dict:
    incidences = ring_incidences()
    out = {}
    for n in samples:
        np.save(directory / "ridges.npy", ridges(n))
        for shading in ("flat", "smooth"):
            table = run_table({
                "scene": {"kind": "heightfield", "path": str(directory / "ridges.npy"), "pixel": 1.0 / n,
                          "shading": shading},
                "material": {"kind": "lambert", "albedo": 0.8},
                "illumination": {"theta_i_deg": [t for _, t, _ in incidences],
                                 "phi_i_deg": [p for _, _, p in incidences]},
                "sensor": {"cells": RECIPROCITY_CELLS}, "run": {"paths": paths, "realizations": 16, "seed": 5}},
                directory)
            z = reciprocity_z(table, incidences, table.brdf, table.brdf_stderr)
            # |f(a->b) - f(b->a)| over their RMS, and the same of the noise (hypot of the two errors)
            asymmetry = np.sqrt(2.0) * reciprocity_z(table, incidences, table.brdf, table.brdf)
            noise = asymmetry / z
            out[f"samples{n}/{shading}"] = {"max_z": round(float(z.max()), 2), "pairs_over_4.5": int((z > 4.5).sum()),
                                           "mean_relative_asymmetry": round(float(asymmetry.mean()), 4),
                                           "mean_relative_noise": round(float(noise.mean()), 4),
                                           "albedo": table.albedo.round(4).tolist()}
            print(f"ridges {n} samples {shading}: max z {z.max():.2f}, {(z > 4.5).sum()} pairs over 4.5, "
                  f"mean relative asymmetry {asymmetry.mean():.4f} (noise {noise.mean():.4f})", flush=True)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paths", type=int, default=400_000, help="paths an incidence (convergence)")
    parser.add_argument("--reciprocity-paths", type=int, default=1_920_000, help="paths an incidence (reciprocity)")
    parser.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--samples", type=int, nargs="+", default=[4, 8, 16, 32])
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as directory:
        figures = {"convergence": convergence(args.paths, args.levels, Path(directory)),
                   "reciprocity": reciprocity(args.reciprocity_paths, args.samples, Path(directory)),
                   "paths": args.paths, "reciprocity_paths": args.reciprocity_paths}
    save_figures(figures, "smooth_shading", args.json)


if __name__ == "__main__":
    main()
