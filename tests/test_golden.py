"""Bit identity: four small tables traced now equal, byte for byte, the golden ones checked in.

``tests/data/golden_<name>.npz`` holds every dataset of the table that ``GOLDEN[name]`` gave
when it was last regenerated, and the platform it was made on (machine and widest SIMD
instruction set: Embree picks its kernels by it, so float32 hit distances may differ in the last
bit elsewhere; on another platform the test skips and says so). The
two tessellated configs run on the embreex backend, whose tables are those of c8660dd, the
commit before issue 7; ``exact`` runs native spheres on the direct backend; ``vcavities`` the
analytic V-cavity tracer (issue 11). Between them they
reach every tracer event: Lambertian, interfaced-Lambertian and conductor interactions, Russian
roulette, pass-through of overlapping spheres, side wraps, a base plane, transmission through
the slab and truncation by ``max_order``. Any change that moves a single
bit of a table fails here, with the size of the largest move. A change meant to move results
(new physics, another sampling order) regenerates them, and its commit message says why:

    python tests/test_golden.py --regenerate [NAME ...]
"""

from __future__ import annotations

import platform
import sys
from pathlib import Path

import numpy as np
import pytest

from microsim import config, runner, tables

DATA = Path(__file__).parent / "data"
#: instruction sets Embree dispatches on, widest first, as Linux names them in /proc/cpuinfo
SIMD = ("avx512f", "avx2", "avx", "sse4_2")

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
        "scene": {"kind": "poisson_spheres", "volume_fraction": 0.3, "tile": 8.0, "depth": 4.0},
        "material": {"kind": "lambert", "albedo": 0.9},
        "base": {"kind": "lambert", "albedo": 0.5},
        "illumination": {"theta_i_deg": [0.0, 70.0]},
        "sensor": {"cells": 20},
        "run": {"paths": 4000, "realizations": 2, "seed": 3, "backend": "direct"},
    },
    "vcavities": {
        "scene": {"kind": "vcavities", "distribution": "ggx", "roughness_x": 0.4, "roughness_y": 0.8},
        "material": {"kind": "interfaced_lambert", "albedo": 0.7, "eta": 1.5},
        "illumination": {"theta_i_deg": [0.0, 80.0], "phi_i_deg": [0.0, 90.0]},
        "sensor": {"cells": 20},
        "run": {"paths": 4000, "realizations": 2, "seed": 3},
    },
}


def trace(name: str, directory: Path) -> dict:
    """Every dataset of the table of GOLDEN[name], by HDF5 path."""
    cfg = config.validate(GOLDEN[name])
    path = directory / f"{name}.h5"
    tables.write(path, runner.run(cfg), cfg)
    return tables.load(path).arrays


def platform_key() -> str:
    """Machine and widest SIMD instruction set of this CPU, e.g. 'x86_64-avx512f'."""
    try:
        flags = set(Path("/proc/cpuinfo").read_text().split())
    except OSError:
        flags = set()
    return f"{platform.machine()}-{next((isa for isa in SIMD if isa in flags), 'unknown')}"


def golden_path(name: str) -> Path:
    return DATA / f"golden_{name}.npz"


def load_golden(name: str) -> tuple[dict, str]:
    """The golden datasets by HDF5 path, and the platform they were made on."""
    with np.load(golden_path(name)) as stored:
        arrays = {key.replace(".", "/"): stored[key] for key in stored.files if key != "platform"}
        return arrays, str(stored["platform"])


@pytest.mark.parametrize("name", sorted(GOLDEN))
def test_table_is_bit_identical_to_the_golden_one(name, tmp_path):
    golden, made_on = load_golden(name)
    if made_on != platform_key():
        pytest.skip(f"golden tables made on {made_on}, this is {platform_key()}: regenerate them here to guard bits")
    now = trace(name, tmp_path)
    assert now.keys() == golden.keys()
    moved = []
    for key, expected in golden.items():
        value = now[key]
        if value.dtype != expected.dtype or value.shape != expected.shape or value.tobytes() != expected.tobytes():
            largest = np.max(np.abs(value.astype(float) - expected.astype(float))) if value.shape == expected.shape else "shape"
            moved.append(f"{key} (largest change {largest})")
    assert not moved, "moved: " + ", ".join(moved)


def test_the_golden_tables_reach_every_tracer_event():
    (spheres, _), (conductor, _), (exact, _) = (load_golden(name) for name in ("spheres", "conductor", "exact"))
    assert np.all(spheres["diagnostics/roulette_kills"] > 0) and np.all(spheres["diagnostics/inside_hits"] > 0)
    assert np.all(exact["diagnostics/roulette_kills"] > 0)
    assert np.all(conductor["energy/transmitted"] > 0) and np.all(conductor["energy/truncated"] > 0)
    assert np.all(spheres["albedo_order"][:, 3] > 0)  # paths reach order 4+


def regenerate(names) -> None:
    import tempfile

    DATA.mkdir(exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            arrays = trace(name, Path(tmp))
            np.savez_compressed(golden_path(name), platform=np.array(platform_key()),
                                **{key.replace("/", "."): value for key, value in arrays.items()})
            print(f"wrote {golden_path(name)} ({golden_path(name).stat().st_size} bytes)")


if __name__ == "__main__":
    if sys.argv[1:2] != ["--regenerate"] or not set(sys.argv[2:]) <= set(GOLDEN):
        sys.exit(f"usage: python tests/test_golden.py --regenerate [NAME ...] (names: {', '.join(GOLDEN)})")
    regenerate(sys.argv[2:] or list(GOLDEN))
