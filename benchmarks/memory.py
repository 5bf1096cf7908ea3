"""Peak memory of a run: threads share one scene, worker processes each build their own.

Runs ``microsim run runs/spheres_phi060.toml`` (and the other configs given) with 1 thread,
2 threads and 2 worker processes, each in a fresh wrapper process, with exact spheres (the
default) and with icosphere level --level (a scene large enough to be seen next to the ~220 MiB
of Python, numba and scipy), and reports the peak resident set size of the largest process
(ru_maxrss of the waited-for descendants): with threads it is the run's whole footprint; with
workers each of the two holds a scene of its own.

    python benchmarks/memory.py [--paths 400000] [--level 3] [--configs runs/spheres_phi060.toml ...]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

WRAPPER = """
import resource, subprocess, sys
done = subprocess.run(sys.argv[1:], capture_output=True, text=True)
if done.returncode:
    sys.exit(done.stderr)
print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
"""


def peak_rss_mib(config: Path, paths: int, flags: list[str], out: Path) -> float:
    """Peak RSS (MiB) of the largest process of one `microsim run`, measured from a fresh wrapper."""
    command = [sys.executable, "-c", WRAPPER, sys.executable, "-m", "microsim.cli", "run", str(config),
               "--paths", str(paths), "--out", str(out), "--force", *flags]
    done = subprocess.run(command, capture_output=True, text=True, check=True, cwd=ROOT)
    return int(done.stdout.split()[-1]) / 1024.0  # Linux reports kB


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paths", type=int, default=400_000)
    parser.add_argument("--level", type=int, default=3, help="icosphere level of the meshed variant")
    parser.add_argument("--configs", nargs="+", default=["runs/spheres_phi060.toml", "runs/spheres_phi030.toml"])
    args = parser.parse_args()
    ways = {"1 thread": ["--threads", "1"], "2 threads": ["--threads", "2"], "2 workers": ["--workers", "2"]}
    with tempfile.TemporaryDirectory() as tmp:
        for config in args.configs:
            meshed = Path(tmp) / f"level{args.level}-{Path(config).name}"
            text = (ROOT / config).read_text()
            meshed.write_text(text.replace("[scene]\n", f"[scene]\nsubdivisions = {args.level}\n", 1))
            for label, path in ((f"{config} (exact)", ROOT / config), (f"{config} (level {args.level})", meshed)):
                report(label, {name: peak_rss_mib(path, args.paths, flags, Path(tmp) / "t.h5")
                               for name, flags in ways.items()})


def report(label: str, peaks: dict) -> None:
    print(f"{label}: peak RSS of the largest process "
          + ", ".join(f"{name} {mib:.0f} MiB" for name, mib in peaks.items())
          + f"; 2 threads / 1 thread = {peaks['2 threads'] / peaks['1 thread']:.2f}")


if __name__ == "__main__":
    main()
