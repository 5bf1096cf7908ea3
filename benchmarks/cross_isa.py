"""How far do the golden tables move on a CPU of another instruction set? Traced here, as one.

On an x86-64 host, traces the goldens of ``tests/test_golden.py`` as a CPU limited to AVX2, AVX
or SSE4.2 would: Embree with ``max_isa`` (``MICROSIM_EMBREE_CONFIG``; the embreex wheel's own
device gets it through a 20-line ``LD_PRELOAD`` shim of ``rtcNewDevice`` compiled here with the
C compiler), numba with its target CPU and features set to that x86-64 level
(``NUMBA_CPU_NAME``, ``NUMBA_CPU_FEATURES``), numpy with its wider SIMD kernels switched off
(``NPY_DISABLE_CPU_FEATURES``).

    python benchmarks/cross_isa.py measure [--isa native avx2 avx sse4.2]   # 2 min an ISA on 2 cores
    python benchmarks/cross_isa.py pytest avx2 [PYTEST ARGS]          # tests/test_golden.py as on AVX2

Needs numpy 2.4 or later (its dispatch names) and a C compiler. ``measure`` prints, per golden
and ISA, the largest move of any traced dataset as a fraction of the dataset's largest value (of
its estimate, for a ``_stderr``: the measure of ``microsim.testing.golden.HOST_TOLERANCE``), the largest
move of the layout in ulps and of the event counts in square roots of the largest count
(``COUNT_SPREAD``); ``pytest`` runs the golden test under that emulation, where ``platform_key``
names the capped instruction set, so the test takes its other-platform branch.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from microsim.testing import golden as goldens

ROOT = Path(__file__).resolve().parent.parent

#: LLVM features of each x86-64 level (the psABI's x86-64-v2 and -v3; "avx" is v2 + AVX)
_V2 = "64bit cmov cx8 fxsr mmx sse sse2 cx16 popcnt sahf sse3 sse4.1 sse4.2 ssse3"
LEVELS = {
    "avx2": ("x86-64-v3", _V2 + " avx avx2 bmi bmi2 f16c fma lzcnt movbe xsave", "X86_V4 AVX512_ICL AVX512_SPR"),
    "avx": ("x86-64-v2", _V2 + " avx xsave", "X86_V3 X86_V4 AVX512_ICL AVX512_SPR"),
    "sse4.2": ("x86-64-v2", _V2, "X86_V3 X86_V4 AVX512_ICL AVX512_SPR"),
}

SHIM = r"""
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdlib.h>
/* rtcNewDevice of the Embree library named by MICROSIM_EMBREE_LIBRARY, with the configuration
   MICROSIM_EMBREE_CONFIG in place of the caller's (embreex passes NULL) */
void *rtcNewDevice(const char *config) {
    static void *(*real)(const char *) = 0;
    if (!real) real = (void *(*)(const char *))dlsym(dlopen(getenv("MICROSIM_EMBREE_LIBRARY"), RTLD_NOW), "rtcNewDevice");
    const char *forced = getenv("MICROSIM_EMBREE_CONFIG");
    return real(forced ? forced : config);
}
"""


def emulation(isa: str, directory: Path) -> dict:
    """The environment in which this host traces as a CPU of ``isa`` would (``native``: as itself)."""
    import llvmlite.binding as llvm

    if isa == "native":
        return dict(os.environ)

    from microsim.tracer import embree

    cpu, keep, numpy_off = LEVELS[isa]
    host = llvm.get_host_cpu_features()
    keep = set(keep.split())
    features = ",".join(("+" if name in keep else "-") + name for name in sorted(host) if host[name] or name in keep)
    shim = directory / "rtc_new_device_shim.so"
    source = directory / "rtc_new_device_shim.c"
    source.write_text(SHIM)
    subprocess.run(["cc", "-O2", "-shared", "-fPIC", "-o", str(shim), str(source), "-ldl"], check=True)
    return {**os.environ, "NUMBA_CPU_NAME": cpu, "NUMBA_CPU_FEATURES": features, "NPY_DISABLE_CPU_FEATURES": numpy_off,
            embree.DEVICE_CONFIG_VARIABLE: f"max_isa={isa}", "MICROSIM_EMBREE_LIBRARY": str(embree.library_path()),
            "LD_PRELOAD": str(shim)}


def trace_all(out: Path) -> None:
    """Trace every golden here, into ``out/<name>.npz`` (run in the emulated environment)."""
    for name in goldens.GOLDEN:
        arrays = goldens.trace(name, out)
        np.savez(out / f"{name}.npz", **{key.replace("/", "."): value for key, value in arrays.items()})


def moves(now: dict, golden: dict) -> tuple[float, float, float]:
    """(largest move of a traced float dataset as a fraction of its estimate's largest value,
    largest layout move in ulps, largest event-count move in square roots of the largest count)."""
    traced = layout = counts = 0.0
    for key, expected in golden.items():
        change = np.abs(now[key].astype(float) - expected.astype(float))
        if key.startswith(goldens.LAYOUT):
            if expected.dtype.kind == "f":
                layout = max(layout, float(np.max(change / np.spacing(np.abs(expected)))))
        elif expected.dtype.kind != "f":
            counts = max(counts, float(np.max(change) / np.sqrt(max(1, np.max(np.abs(expected))))))
        else:
            scale = np.max(np.abs(golden[key.removesuffix("_stderr")]))
            traced = max(traced, float(np.max(change) / scale) if scale else (np.inf if np.max(change) > 0 else 0.0))
    return traced, layout, counts


def measure(isas) -> None:
    print(f"host {goldens.platform_key()}; moves against the goldens of tests/data")
    print(f"{'golden':18s} {'isa':7s} {'traced (fraction)':>18s} {'layout (ulps)':>14s} {'counts (sqrt)':>18s}  bound")
    for isa in isas:
        with tempfile.TemporaryDirectory() as tmp:
            tmp = Path(tmp)
            subprocess.run([sys.executable, __file__, "_trace", str(tmp)], env=emulation(isa, tmp), check=True)
            for name in goldens.GOLDEN:
                golden, _ = goldens.load_golden(name)
                with np.load(tmp / f"{name}.npz") as stored:
                    now = {key.replace(".", "/"): stored[key] for key in stored.files}
                traced, layout, counts = moves(now, golden)
                print(f"{name:18s} {isa:7s} {traced:18.3g} {layout:14.3g} {counts:18.3g}  "
                      f"{goldens.HOST_TOLERANCE[name]:g}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    measure_parser = commands.add_parser("measure", help="trace the goldens as each ISA and print their moves")
    measure_parser.add_argument("--isa", nargs="+", choices=["native", *LEVELS], default=list(LEVELS))
    pytest_parser = commands.add_parser("pytest", help="run tests/test_golden.py as the ISA")
    pytest_parser.add_argument("isa", choices=list(LEVELS))
    pytest_parser.add_argument("pytest_args", nargs=argparse.REMAINDER)
    trace_parser = commands.add_parser("_trace")
    trace_parser.add_argument("out", type=Path)
    args = parser.parse_args()
    if args.command == "measure":
        measure(args.isa)
    elif args.command == "_trace":
        trace_all(args.out)
    else:
        with tempfile.TemporaryDirectory() as tmp:
            command = [sys.executable, "-m", "pytest", str(ROOT / "tests" / "test_golden.py"), *args.pytest_args]
            sys.exit(subprocess.run(command, env=emulation(args.isa, Path(tmp)), cwd=ROOT).returncode)


if __name__ == "__main__":
    main()
