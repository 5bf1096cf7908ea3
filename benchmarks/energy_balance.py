"""Is the energy balance of the default sphere tables 1?

An independent check found ``energy/balance`` (albedo + transmitted + truncated + absorbed, 1 in
expectation: Russian roulette is unbiased) at 1 + 4-6e-5 at theta_i = 0 in three of four default
tables, 2-3 standard errors. This traces each shipped config at theta_i = 0 alone with --paths
paths (another seed), precise enough to see such a bias at 8-20 standard errors, and prints
balance - 1 with its standard error. About 2 minutes on 2 threads at the default 32 M paths.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from report import save_figures

from microsim import config
from microsim.testing import trace

ROOT = Path(__file__).resolve().parent.parent


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", nargs="+", default=["spheres_phi010", "spheres_phi030", "spheres_phi060", "plane"])
    parser.add_argument("--paths", type=int, default=32_000_000)
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    figures = {}
    for name in args.runs:
        cfg = config.load(ROOT / "runs" / f"{name}.toml", {"run.paths": args.paths, "run.seed": args.seed})
        cfg = cfg.model_copy(update={"illumination": cfg.illumination.model_copy(
            update={"theta_i_deg": [0.0], "phi_i_deg": [0.0]})})
        start = time.perf_counter()
        energy = trace(cfg, threads=2).energy[0]
        excess, error = float(energy.mean[3] - 1.0), float(energy.stderr[3])
        figures[name] = {"balance_minus_1": excess, "stderr": error, "seconds": time.perf_counter() - start}
        z = f"{excess / error:+.2f} standard errors" if error > 0 else "exact"
        print(f"{name}: balance - 1 = {excess:+.2e} +- {error:.2e} ({z}), {args.paths:,} paths at theta_i = 0")
    save_figures(figures, "energy_balance", args.json)


if __name__ == "__main__":
    main()
