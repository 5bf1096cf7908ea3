"""Two seeds of one config, compared cell by cell (``microsim compare A.h5 --model table --param
path=B.h5``): how often chi-square per cell and the albedos' mean z^2 leave their bounds, where
both tables are of one BRDF. Full BRDFs of Boolean spheres (phi = 0.3, 13 incidences, 1600 cells).

The incidences of a table share its realizations' geometry, so their albedo errors are
correlated (a denser realization brightens every incidence): the bound of the albedos' mean z^2
takes that correlation (microsim.analysis.compare.albedo_bound); with the incidences taken as
independent it was exceeded by two seeds of the same config (shown beside it). Lab notes:
docs/guide/tabulated.md.

    python benchmarks/table_vs_table.py [--pairs 20] [--paths 200000]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from scipy.stats import chi2

from microsim import config
from microsim.analysis import compare
from microsim.core.table_noise import CHI2_OUTSIDE
from microsim.models.tabulated import TabulatedBRDF
from microsim.testing import trace_table

CONFIG = {
    "scene": {"kind": "poisson_spheres", "volume_fraction": 0.3},
    "material": {"kind": "lambert", "albedo": 0.8},
    "illumination": {"incidences": 13},
    "sensor": {"cells": 1600},
    "run": {"realizations": 16},
}


def table(directory: Path, seed: int, paths: int):
    cfg = config.validate({**CONFIG, "run": {**CONFIG["run"], "paths": paths, "seed": seed}})
    return trace_table(cfg, directory / f"seed{seed}.h5")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pairs", type=int, default=20)
    parser.add_argument("--paths", type=int, default=200_000)
    args = parser.parse_args()
    outside = {"chi2": 0, "albedo": 0, "albedo_independent": 0}
    with tempfile.TemporaryDirectory() as tmp:
        for pair in range(args.pairs):
            a, b = table(Path(tmp), 2 * pair + 1, args.paths), table(Path(tmp), 2 * pair + 2, args.paths)
            overall = compare.compare(a, TabulatedBRDF(b)).metrics()
            low, high = overall["chi2_bounds"]
            n = len(a.theta_i)
            independent = chi2.ppf(1 - CHI2_OUTSIDE / 2, n) / n
            outside["chi2"] += not low <= overall["chi2_per_cell"] <= high
            outside["albedo"] += overall["albedo_z2"] > overall["albedo_z2_bound"]
            outside["albedo_independent"] += overall["albedo_z2"] > independent
            print(f"pair {pair}: chi2 per cell {overall['chi2_per_cell']:.4f} in [{low:.4f}, {high:.4f}], albedo z2 "
                  f"{overall['albedo_z2']:.3f} (bound {overall['albedo_z2_bound']:.3f}; independent {independent:.3f})",
                  flush=True)
    print(f"outside their bounds in {args.pairs} pairs: " + ", ".join(f"{k} {v}" for k, v in outside.items()))


if __name__ == "__main__":
    main()
