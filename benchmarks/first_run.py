"""What a user sees on a terminal during a run: the compile announcement, and the time left
against the true time left.

Runs ``microsim run`` under a pseudo-terminal (so the progress line is drawn), reads every
state of the line as it is drawn, with its time, and reports: whether and when "compiling" was
shown, when tracing began (the first "tracing" state), and for every "N s left" the ratio of N
to the true remaining time (the end of the run minus the moment it was shown).

    python benchmarks/first_run.py [--cold] [--json] -- run runs/spheres_phi030.toml --paths 200000 --threads 2 --force

``--cold`` gives the run an empty numba cache (NUMBA_CACHE_DIR in a temporary directory), as a
fresh clone has.
"""

from __future__ import annotations

import argparse
import os
import pty
import re
import select
import subprocess
import sys
import tempfile
import time

from report import save_figures

LEFT = re.compile(r"(\d+) s left")
ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")


def watch(command: list[str], env: dict) -> tuple[list[tuple[float, str]], float, str]:
    """(every state of the terminal line with its time since start, the run's duration, stdout)."""
    primary, secondary = pty.openpty()
    start = time.monotonic()
    process = subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=secondary, env=env,
                               text=False)
    os.close(secondary)
    states, buffer = [], b""
    while True:
        ready, _, _ = select.select([primary], [], [], 0.05)
        if ready:
            try:
                chunk = os.read(primary, 65536)
            except OSError:
                break
            if not chunk:
                break
            buffer += chunk
            *lines, buffer = re.split(rb"[\r\n]", buffer)
            now = time.monotonic() - start
            states += [(now, ANSI.sub("", line.decode(errors="replace")).strip()) for line in lines]
        elif process.poll() is not None:
            break
    out = process.communicate()[0].decode()
    return [(t, s) for t, s in states if s], time.monotonic() - start, out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cold", action="store_true", help="an empty numba cache")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("args", nargs="+", help="the arguments of microsim, after --")
    options = parser.parse_args()
    env = dict(os.environ, COLUMNS="200")
    with tempfile.TemporaryDirectory() as cache:
        if options.cold:
            env["NUMBA_CACHE_DIR"] = cache
        states, duration, out = watch([sys.executable, "-m", "microsim", *options.args], env)
    compiling = [t for t, s in states if s.startswith("compiling")]
    tracing = [t for t, s in states if s.startswith("tracing")]
    ratios = [(t, int(m.group(1)) / max(duration - t, 1e-9)) for t, s in states if (m := LEFT.search(s))]
    figures = {
        "command": options.args, "cold": options.cold, "duration_s": duration,
        "compiling_shown_s": [compiling[0], compiling[-1]] if compiling else None,
        "compiling_text": next((s for _, s in states if s.startswith("compiling")), None),
        "tracing_first_shown_s": tracing[0] if tracing else None,
        "time_left_over_true": [[round(t, 2), round(r, 3)] for t, r in ratios],
        "largest_ratio": max((r for _, r in ratios), default=None),
        "stdout": out,
    }
    for key, value in figures.items():
        print(f"{key}: {value}")
    save_figures(figures, "first_run" + ("_cold" if options.cold else ""), options.json)


if __name__ == "__main__":
    main()
