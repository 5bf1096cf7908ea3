"""Peak memory against triangle count: the sphere scenes up to
phi = 0.6 at their full default depth and tile, with exact spheres and icospheres of growing
level, traced by one process, two worker processes, two threads sharing one scene, and a Dask
LocalCluster of two workers.

Each run is ``microsim run`` with 4 realizations (so that each of two workers builds two
scenes, one after the other) and a few paths, in a fresh process tree sampled every 0.2 s:
the peak of the largest process's resident set (what one worker needs), and the peak of the
tree's proportional set size (what the run needs: forked workers share the interpreter's pages
with their parent, PSS counts each shared page once). The table's ``scene/triangles`` is the
largest realization's count. A straight line through the one-process peaks against triangles
gives the bytes a triangle costs and the largest scene a 24 GiB machine traces, with one
process and with two workers; the runner's own estimate (``memory.memory_estimate``) is printed
beside each measured peak.

    python benchmarks/memory.py [--phis 0.1 0.3 0.6] [--levels 1 2 3] [--paths 80000]

Writes benchmarks/out/memory.json and memory.png. About 15 minutes on 2 cores.
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
import psutil

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from microsim import config as config_module  # noqa: E402
from microsim import tables
from microsim.run.memory import memory_estimate
from microsim.run.plan import Plan

MACHINE = 24 * 2**30
CONFIG = """[scene]
kind = "poisson_spheres"
volume_fraction = {phi}
{model}
[material]
kind = "lambert"
albedo = 0.8
[illumination]
theta_i_deg = [0.0, 60.0]
[sensor]
cells = 3240
[run]
paths = {paths}
realizations = 4
seed = 1
"""
WAYS = {"1 process": [], "2 workers": ["--workers", "2"], "2 threads": ["--threads", "2"],
        "dask, 2 workers": ["--executor", "dask", "--workers", "2"]}


WRAPPER = """
import resource, subprocess, sys
done = subprocess.run(sys.argv[1:], capture_output=True, text=True)
if done.returncode:
    sys.exit(done.stderr)
print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
"""


def measure(config: Path, flags: list[str], out: Path) -> dict:
    """Peak RSS of the largest process (exact: ru_maxrss of every waited-for descendant, from a
    wrapper) and peak PSS of the whole tree (sampled), in bytes."""
    process = psutil.Popen([sys.executable, "-c", WRAPPER, sys.executable, "-m", "microsim", "run", str(config),
                            "--out", str(out), "--force", *flags], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           cwd=ROOT)
    total = 0
    while process.poll() is None:
        infos = []
        for p in process.children(recursive=True) if process.is_running() else []:
            try:
                infos.append(p.memory_full_info())
            except (psutil.NoSuchProcess, psutil.AccessDenied):
                pass
        total = max(total, sum(i.pss for i in infos))
        time.sleep(0.1)
    stdout, stderr = process.communicate()
    if process.returncode:
        raise SystemExit(f"{config}: {stderr.decode()}")
    return {"largest_process_rss": int(stdout.split()[-1]) * 1024, "tree_pss": total}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--phis", type=float, nargs="+", default=[0.1, 0.3, 0.6])
    parser.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--paths", type=int, default=80_000)
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        warm = Path(tmp) / "warm.toml"  # numba compiles (and caches) the kernels outside the measures
        warm.write_text(CONFIG.format(phi=0.3, model="", paths=400))
        for flags in WAYS.values():
            measure(warm, flags, Path(tmp) / "warm.h5")
        for phi in args.phis:
            for level in [None, *args.levels]:
                model = "" if level is None else f"subdivisions = {level}"
                config = Path(tmp) / f"phi{phi}-{level}.toml"
                config.write_text(CONFIG.format(phi=phi, model=model, paths=args.paths))
                out = Path(tmp) / "t.h5"
                ways = WAYS if level in (None, 2) else {k: v for k, v in WAYS.items() if k in ("1 process", "2 workers")}
                peaks = {name: measure(config, flags, out) for name, flags in ways.items()}
                table = tables.load(out)
                plan = Plan.from_config(config_module.load(config))
                row = {"phi": phi, "sphere_model": "exact" if level is None else f"icosphere level {level}",
                       "triangles": int(table.scene["triangles"]),
                       "spheres": int(np.max(table.arrays.get("scene/spheres", [0]))),
                       "depth": float(table.scene["depth"]), "tile": float(table.scene["tile"]),
                       "estimate_1": memory_estimate(plan, 1),
                       "estimate_2": memory_estimate(plan, 2), "peaks": peaks}
                rows.append(row)
                print(f"phi {phi} {row['sphere_model']}: {row['triangles']:,} triangles, {row['spheres']:,} spheres; "
                      + "; ".join(f"{k}: largest {v['largest_process_rss'] / 2**20:.0f} MiB, all {v['tree_pss'] / 2**20:.0f} MiB"
                                  for k, v in peaks.items())
                      + f"; estimate 1 process {row['estimate_1'] / 2**20:.0f} MiB, 2 workers {row['estimate_2'] / 2**20:.0f} MiB",
                      flush=True)
    meshed = [r for r in rows if r["triangles"]]
    x = np.array([r["triangles"] for r in meshed], float)
    one = np.array([r["peaks"]["1 process"]["largest_process_rss"] for r in meshed], float)
    two = np.array([r["peaks"]["2 workers"]["tree_pss"] for r in meshed], float)
    slope1, base1 = np.polyfit(x, one, 1)
    slope2, base2 = np.polyfit(x, two, 1)
    largest1, largest2 = (MACHINE - base1) / slope1, (MACHINE - base2) / slope2
    print(f"one process: {slope1:.0f} bytes a triangle + {base1 / 2**20:.0f} MiB; two workers: {slope2:.0f} bytes a "
          f"triangle (both scenes) + {base2 / 2**20:.0f} MiB")
    print(f"largest scene on 24 GiB: {largest1 / 1e6:.0f} M triangles with one process (or threads), "
          f"{largest2 / 1e6:.0f} M with two workers (each holds one scene at a time)")
    out_dir = ROOT / "benchmarks" / "out"
    out_dir.mkdir(parents=True, exist_ok=True)
    summary = {"bytes_per_triangle_one_process": slope1, "base_one_process": base1,
               "bytes_per_triangle_two_workers": slope2, "base_two_workers": base2,
               "largest_triangles_24GiB_one_process": largest1, "largest_triangles_24GiB_two_workers": largest2}
    (out_dir / "memory.json").write_text(json.dumps({"rows": rows, "fit": summary}, indent=1))
    plot(rows, out_dir / "memory.png")


def plot(rows, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for way, marker in zip(WAYS, "osd^"):
        for measure_name, style in (("largest_process_rss", "-"), ("tree_pss", ":")):
            pts = sorted((r["triangles"], r["peaks"][way][measure_name]) for r in rows if way in r["peaks"] and r["triangles"])
            if pts:
                ax.plot([p[0] / 1e6 for p in pts], [p[1] / 2**30 for p in pts], style, marker=marker,
                        label=f"{way}, {'largest process' if measure_name.startswith('largest') else 'all processes (PSS)'}")
    ax.set_xlabel("triangles in the scene (millions; exact spheres: 0)")
    ax.set_ylabel("peak memory (GiB)")
    ax.set_title("Sphere scenes at default depth and 64 r tile (phi 0.1-0.6)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    main()
