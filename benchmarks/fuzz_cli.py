"""Fuzz `microsim run` at full size: at least 500 configs and command lines drawn by
hypothesis (microsim.testing.fuzzing: every scene kind's example config, edge values, NaN and
infinity, huge counts, wrong types, unknown keys, sweeps with bad keys, files that are not
TOML, good and bad flags). Each must either write a valid table or exit 2 with one line and
write nothing; a traceback, another exit status or a stray file stops the run, and hypothesis
prints the smallest case that fails.

    python benchmarks/fuzz_cli.py [--cases 600] [--seed 1]     # 10 s on 2 cores, numba's cache warm

Prints the cases by outcome and writes benchmarks/out/fuzz_cli.json.
"""

from __future__ import annotations

import argparse
import collections
import json
import tempfile
import time
from pathlib import Path

from hypothesis import HealthCheck, given, seed, settings

from microsim.testing import fuzzing as cli_fuzzing

ROOT = Path(__file__).resolve().parent.parent


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=600)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    outcomes = collections.Counter()

    @seed(args.seed)
    @settings(max_examples=args.cases, deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(cli_fuzzing.cases())
    def fuzz(case):
        with tempfile.TemporaryDirectory() as folder:
            status, _ = cli_fuzzing.check(Path(folder), *case)
        outcomes[("ran" if status == 0 else "refused") + (" (sweep)" if case[2] else "")] += 1

    start = time.perf_counter()
    fuzz()
    elapsed = time.perf_counter() - start
    cases = sum(outcomes.values())
    print(f"{cases} cases in {elapsed:.0f} s: " + ", ".join(f"{k} {v}" for k, v in sorted(outcomes.items()))
          + "; tracebacks 0, files written by refused cases 0")
    out = ROOT / "benchmarks" / "out"
    out.mkdir(parents=True, exist_ok=True)
    (out / "fuzz_cli.json").write_text(json.dumps({"cases": cases, "seed": args.seed, "seconds": elapsed,
                                                   "outcomes": dict(outcomes), "tracebacks": 0,
                                                   "files_written_by_refused_cases": 0}, indent=1))


if __name__ == "__main__":
    main()
