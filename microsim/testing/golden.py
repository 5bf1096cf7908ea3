"""The golden tables: small tables traced now against the ones kept in tests/data, on every host.

Contract: :data:`GOLDEN` names the config of each golden; :func:`trace` gives every dataset of
its table as traced now, by HDF5 path; :func:`load_golden` the datasets kept in
``tests/data/golden_<name>.npz`` and the platform (:func:`platform_key`) they were made on;
:func:`byte_moves` lists the datasets whose bytes differ (the check on the golden's own
platform), :func:`host_moves` those that moved by more than a change of CPU can move them (the
check on any other: :data:`HOST_TOLERANCE`, measured as tests/test_golden.py's docstring
says); :func:`regenerate` traces and keeps them anew. tests/test_golden.py holds the tests, and
benchmarks/cross_isa.py traces the goldens as a CPU of another instruction set would.
"""

from __future__ import annotations

import os
import platform
import re
from pathlib import Path

import numpy as np

from microsim.testing.tables import trace_table

#: where the goldens are kept: the repository's tests/data
DATA = Path(__file__).resolve().parents[2] / "tests" / "data"
#: instruction sets Embree dispatches on, widest first, as Linux names them in /proc/cpuinfo, and
#: as Embree's ``max_isa`` device setting names them
SIMD = ("avx512f", "avx2", "avx", "sse4_2")
EMBREE_ISA = {"avx512": "avx512f", "avx2": "avx2", "avx": "avx", "sse4.2": "sse4_2"}

GOLDEN = {
    "spheres": {
        "scene": {"kind": "poisson_spheres", "volume_fraction": 0.3, "tile": 8.0, "depth": 4.0, "subdivisions": 1},
        "material": {"kind": "lambert", "albedo": 0.9},
        "base": {"kind": "interfaced_lambert", "albedo": 0.7, "eta": 1.5},
        "illumination": {"theta_i_deg": [0.0, 70.0]},
        "sensor": {"cells": 20},
        "run": {"paths": 4000, "realizations": 2, "seed": 3, "backend": "embreex"},
    },
    "conductor": {
        "scene": {"kind": "poisson_spheres", "volume_fraction": 0.4, "tile": 8.0, "depth": 3.0, "subdivisions": 1},
        "material": {"kind": "conductor", "eta": 0.2, "k": 3.0},
        "illumination": {"theta_i_deg": [30.0, 85.0]},
        "sensor": {"cells": 20},
        "run": {"paths": 2000, "realizations": 2, "seed": 4, "max_order": 3, "backend": "embreex"},
    },
    "exact": {
        "scene": {"kind": "poisson_spheres", "volume_fraction": 0.3, "tile": 8.0, "depth": 4.0, "intersector": "embree"},
        "material": {"kind": "lambert", "albedo": 0.9},
        "base": {"kind": "lambert", "albedo": 0.5},
        "illumination": {"theta_i_deg": [0.0, 70.0]},
        "sensor": {"cells": 20},
        "run": {"paths": 4000, "realizations": 2, "seed": 3, "backend": "direct"},
    },
    "sphere_grid": {
        "scene": {"kind": "poisson_spheres", "volume_fraction": 0.3, "tile": 8.0, "depth": 4.0},
        "material": {"kind": "lambert", "albedo": 0.9},
        "base": {"kind": "lambert", "albedo": 0.5},
        "illumination": {"theta_i_deg": [0.0, 70.0]},
        "sensor": {"cells": 20},
        "run": {"paths": 4000, "realizations": 2, "seed": 3},
    },
    "vcavities": {
        "scene": {"kind": "vcavities", "distribution": "ggx", "roughness_x": 0.4, "roughness_y": 0.8},
        "material": {"kind": "interfaced_lambert", "albedo": 0.7, "eta": 1.5},
        "illumination": {"theta_i_deg": [0.0, 80.0], "phi_i_deg": [0.0, 90.0]},
        "sensor": {"cells": 20},
        "run": {"paths": 4000, "realizations": 2, "seed": 3},
    },
    "vcavities_lambert": {
        "scene": {"kind": "vcavities", "distribution": "beckmann", "roughness": 0.8},
        "material": {"kind": "lambert", "albedo": 0.8},
        "illumination": {"theta_i_deg": [0.0, 60.0]},
        "sensor": {"cells": 20},
        "run": {"paths": 4000, "realizations": 2, "seed": 3},
    },
    "medium": {
        "scene": {"kind": "halfspace_medium", "phase": "lambert_sphere"},
        "material": {"kind": "lambert", "albedo": 0.9},
        "illumination": {"theta_i_deg": [0.0, 60.0]},
        "sensor": {"cells": 20},
        "run": {"paths": 4000, "realizations": 2, "seed": 3},
    },
}

#: how far each golden may move on a host of another platform, as a fraction of the largest value
#: of each traced dataset (of the estimate, for a ``_stderr``): the table of tests/test_golden.py's docstring
HOST_TOLERANCE = {"vcavities": 0.0, "vcavities_lambert": 0.0, "medium": 0.0, "sphere_grid": 0.0, "conductor": 1e-6,
                  "exact": 2e-2, "spheres": 2e-2}
#: the goldens whose paths diverge from one platform to another, and the bound on the move of their
#: event counts, in square roots of the largest count (a count over the diverged paths)
DIVERGING, COUNT_SPREAD = {"exact", "spheres"}, 5.0
#: datasets of the table's layout (not traced), and the ulps numpy's SIMD functions may move them by
LAYOUT, LAYOUT_ULPS = ("sensor/", "incidence/", "theta_", "phi_"), 8


def trace(name: str, directory: Path, **changes) -> dict:
    """Every dataset of the table of GOLDEN[name], by HDF5 path; ``changes`` replace keys of its
    sections, e.g. ``material={"albedo": 0.7000000000000001}``."""
    data = {section: {**values, **changes.get(section, {})} for section, values in GOLDEN[name].items()}
    return trace_table(data, directory / f"{name}.h5").arrays


def platform_key() -> str:
    """Machine, widest SIMD instruction set Embree runs and CPU vendor, e.g. 'x86_64-avx512f-GenuineIntel'.

    ``max_isa`` in ``MICROSIM_EMBREE_CONFIG`` (see :mod:`microsim.tracer.embree`) caps the instruction
    set, as ``benchmarks/cross_isa.py`` does to trace as another CPU would.
    """
    try:
        cpuinfo = Path("/proc/cpuinfo").read_text()
    except OSError:
        cpuinfo = ""
    flags = set(cpuinfo.split())
    isas = [isa for isa in SIMD if isa in flags]
    capped = re.search(r"max_isa=([\w.]+)", os.environ.get("MICROSIM_EMBREE_CONFIG", ""))
    if capped and EMBREE_ISA.get(capped.group(1)) in SIMD:
        isas = [isa for isa in isas if SIMD.index(isa) >= SIMD.index(EMBREE_ISA[capped.group(1)])]
    vendor = re.search(r"^vendor_id\s*:\s*(\S+)", cpuinfo, re.MULTILINE)
    return f"{platform.machine()}-{isas[0] if isas else 'unknown'}-{vendor.group(1) if vendor else 'unknown'}"


def golden_path(name: str) -> Path:
    return DATA / f"golden_{name}.npz"


def load_golden(name: str) -> tuple[dict, str]:
    """The golden datasets by HDF5 path, and the platform they were made on."""
    with np.load(golden_path(name)) as stored:
        arrays = {key.replace(".", "/"): stored[key] for key in stored.files if key != "platform"}
        return arrays, str(stored["platform"])


def _largest_change(value: np.ndarray, expected: np.ndarray) -> float:
    return float(np.max(np.abs(value.astype(float) - expected.astype(float)), initial=0.0))


def byte_moves(now: dict, golden: dict) -> list[str]:
    """Datasets whose bytes differ, with the size of their largest change."""
    return [f"{key} (largest change {_largest_change(now[key], expected):.3g})" for key, expected in golden.items()
            if now[key].dtype != expected.dtype or now[key].tobytes() != expected.tobytes()]


def host_moves(name: str, now: dict, golden: dict) -> list[str]:
    """Datasets that moved by more than a change of CPU can move them (tests/test_golden.py's docstring)."""
    moved = []
    for key, expected in golden.items():
        value = now[key]
        if key.startswith(LAYOUT):
            bound = LAYOUT_ULPS * np.spacing(np.abs(expected)) if expected.dtype.kind == "f" else 0
        elif expected.dtype.kind != "f":
            diverging = name in DIVERGING and key.startswith("diagnostics/")
            bound = COUNT_SPREAD * np.sqrt(np.max(np.abs(expected), initial=0)) if diverging else 0
        else:
            estimate = golden[key.removesuffix("_stderr")]
            bound = HOST_TOLERANCE[name] * np.max(np.abs(estimate), initial=0.0)
        change = np.abs(value.astype(float) - expected.astype(float))
        change[np.isnan(value) & np.isnan(expected)] = 0.0  # NaN where it was: no move
        if not np.all(change <= bound):  # a NaN that appears or leaves is a move
            moved.append(f"{key} (largest change {np.max(change):.3g}, bound {np.max(bound):.3g})")
    return moved


def regenerate(names) -> None:
    import tempfile

    DATA.mkdir(exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            arrays = trace(name, Path(tmp))
            np.savez_compressed(golden_path(name), platform=np.array(platform_key()),
                                **{key.replace("/", "."): value for key, value in arrays.items()})
            print(f"wrote {golden_path(name)} ({golden_path(name).stat().st_size} bytes)")
