"""The Dask executor against the process pool on this machine.

Runs one config with ``--workers 2`` (forked processes) and with ``--executor dask --workers 2``
(a LocalCluster of two single-threaded processes), alternated ``--repeats`` times so that both
see the same machine, and compares their tables bit for bit. Reports the wall time of each
whole run (the cluster's start included, as a user waits for it), paths/s, and the overhead
ratio dask / process pool; a run of a few paths measures the fixed cost of starting a cluster.

    python benchmarks/executors.py [--config runs/spheres_phi030.toml] [--paths 4000000] [--repeats 3]

Writes benchmarks/out/executors.json and executors.png.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from microsim.testing.tables import same_table

ROOT = Path(__file__).resolve().parent.parent

WAYS = {"process pool": ["--workers", "2"], "dask": ["--executor", "dask", "--workers", "2"]}


def timed_run(config: str, paths: int, flags: list[str], out: Path) -> float:
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "microsim", "run", config, "--paths", str(paths), "--out", str(out),
                    "--force", *flags], check=True, capture_output=True, cwd=ROOT)
    return time.perf_counter() - start


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="runs/spheres_phi030.toml")
    parser.add_argument("--paths", type=int, default=4_000_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    incidences = len(__import__("tomllib").loads((ROOT / args.config).read_text())["illumination"]["theta_i_deg"])
    times = {name: [] for name in WAYS}
    small = {name: [] for name in WAYS}
    with tempfile.TemporaryDirectory() as tmp:
        outs = {name: Path(tmp) / f"{k}.h5" for k, name in enumerate(WAYS)}
        for name, flags in WAYS.items():  # compile and warm the caches
            timed_run(args.config, 64_000, flags, outs[name])
        for _ in range(args.repeats):
            for name, flags in WAYS.items():
                small[name].append(timed_run(args.config, 64_000, flags, outs[name]))
                times[name].append(timed_run(args.config, args.paths, flags, outs[name]))
        identical = same_table(*outs.values())
    best = {name: min(t) for name, t in times.items()}
    ratio = best["dask"] / best["process pool"]
    start_cost = min(small["dask"]) - min(small["process pool"])
    for name in WAYS:
        print(f"{name}: {', '.join(f'{t:.1f}' for t in times[name])} s; best {best[name]:.1f} s = "
              f"{args.paths * incidences / best[name]:.3g} paths/s; a run of 64 000 paths: {min(small[name]):.1f} s")
    print(f"dask / process pool wall time: {ratio:.3f} (best of {args.repeats}, alternated); per pair: "
          + ", ".join(f"{d / p:.3f}" for d, p in zip(times["dask"], times["process pool"]))
          + f"; the cluster's fixed cost {start_cost:.1f} s; tables bit-identical: {identical}")
    out_dir = ROOT / "benchmarks" / "out"
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "executors.json").write_text(json.dumps(
        {"config": args.config, "paths": args.paths, "times": times, "small_runs": small, "ratio": ratio,
         "fixed_cost_s": start_cost, "bit_identical": identical}, indent=1))
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.5))
    for k, name in enumerate(WAYS):
        ax.scatter(np.full(len(times[name]), k), times[name], label=name)
    ax.set_xticks(range(len(WAYS)), list(WAYS))
    ax.set_ylabel("wall time of the run (s)")
    ax.set_title(f"{args.config}, {args.paths:,} paths x {incidences} incidences, 2 workers: ratio {ratio:.3f}")
    fig.tight_layout()
    fig.savefig(out_dir / "executors.png", dpi=120)


if __name__ == "__main__":
    main()
