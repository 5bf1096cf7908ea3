"""Are the tables of this checkout bit-identical to those of another revision?

Traces every shipped run config (at reduced ``--paths``) and the test configs that cover the
scenes, materials and tracer events (plane, furnace, roulette, truncation, single scattering,
conductor, interfaced Lambertian and absorber particles, bases, two workers) once with this
checkout and once with ``--against REV`` (checked out into a temporary git worktree), through
the command line, and compares the two tables of each config dataset by dataset and byte for
byte; attributes that differ (but for creation and wall times and the backend's name) are
listed beside the verdict.

    python benchmarks/bit_identity.py --against c8660dd        # about 5 min on 2 cores

Prints one line per config and exits 1 if any table's datasets differ. A refactoring that must not move
a bit is checked with this before it lands; ``tests/test_golden.py`` keeps small tables of the
same kind under test for every later commit.

The default spheres are exact spheres on the direct backend (whose chunk sums also round
differently from embreex's); against a revision whose default was icospheres on embreex, such
as c8660dd, trace this checkout as that revision did, ``--this-flags "--backend embreex"``
(exact spheres then become icospheres of mesh_error 0.01, as that revision drew them).
"""

from __future__ import annotations

import argparse
import os
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path

import h5py
import numpy as np

from microsim.tables import dict_to_toml

ROOT = Path(__file__).resolve().parent.parent
#: attributes not compared: provenance, and each dataset's SHA-256 digest (its bytes are
#: compared themselves)
PROVENANCE = {"created_utc", "wall_time_s", "backend", "backend_fallback", "sha256"}
SHIPPED_PATHS = 20_000


def config(scene: dict, material: dict, theta: list, cells: int, run: dict, base: dict | None = None,
           sensor: dict | None = None) -> dict:
    data = {"scene": scene, "material": material, "illumination": {"theta_i_deg": theta},
            "sensor": {"cells": cells, **(sensor or {})}, "run": run}
    return data if base is None else dict(data, base=base)


#: the estimators besides the cells: next-event points (directions and retro points) and retro rings
POINTS_AND_RINGS = {"directions_deg": [[0.0, 0.0], [40.0, 90.0], [75.0, 180.0]], "retro_points_deg": [0.0, 4.0],
                    "retro_rings": 8, "retro_max_deg": 20.0}


SPHERES_030 = {"kind": "poisson_spheres", "volume_fraction": 0.3, "tile": 16.0, "depth": 10.0}
LAMBERT_08 = {"kind": "lambert", "albedo": 0.8}
CONDUCTOR = {"kind": "conductor", "eta": 0.2, "k": 3.0}
INTERFACED = {"kind": "interfaced_lambert", "albedo": 0.7, "eta": 1.5}
PLANE = {"kind": "plane"}

#: name -> (config, extra command-line flags): the configs of the tests in tests/
TEST_CONFIGS = {
    "furnace": (config(SPHERES_030, {"kind": "lambert", "albedo": 1.0}, [0.0, 45.0, 70.0, 85.0], 400,
                       {"paths": 40_000, "realizations": 8, "seed": 7}, base={"kind": "lambert", "albedo": 1.0}), []),
    "roulette-transmitted": (config(SPHERES_030, {"kind": "lambert", "albedo": 0.9}, [0.0, 60.0, 89.9], 400,
                                    {"paths": 40_000, "realizations": 8, "seed": 7}), []),
    "max-order-2": (config(SPHERES_030, LAMBERT_08, [30.0], 400,
                           {"paths": 40_000, "realizations": 8, "seed": 7, "max_order": 2}), []),
    "reciprocity-2-workers": (config(dict(SPHERES_030, depth=16.0), LAMBERT_08, [10.0, 35.0, 55.0, 75.0, 85.0], 300,
                                     {"paths": 40_000, "realizations": 16, "seed": 11}), ["--workers", "2"]),
    "single-scattering-phi002": (config({"kind": "poisson_spheres", "volume_fraction": 0.02},
                                        {"kind": "lambert", "albedo": 0.9}, [0.0, 30.0, 60.0], 100,
                                        {"paths": 64_000, "realizations": 16, "seed": 3, "max_order": 1}), []),
    "conductor-spheres-lambert-base": (
        config({"kind": "poisson_spheres", "volume_fraction": 0.2, "tile": 12.0, "depth": 6.0, "mesh_error": 0.05},
               CONDUCTOR, [0.0, 50.0, 80.0], 300, {"paths": 20_000, "realizations": 4, "seed": 9},
               base={"kind": "lambert", "albedo": 0.5}), []),
    "interfaced-spheres-absorber-base": (
        config({"kind": "poisson_spheres", "volume_fraction": 0.4, "tile": 12.0, "depth": 6.0, "subdivisions": 1},
               INTERFACED, [0.0, 70.0], 300, {"paths": 20_000, "realizations": 4, "seed": 4},
               base={"kind": "absorber"}), []),
    "plane-conductor": (config(PLANE, CONDUCTOR, [0.0, 40.0, 75.0], 400,
                               {"paths": 2000, "realizations": 64, "seed": 2}), []),
    "plane-interfaced-lambert": (config(PLANE, INTERFACED, [0.0, 60.0, 89.0], 400,
                                        {"paths": 40_000, "realizations": 64, "seed": 2}), []),
    "plane-absorber": (config(PLANE, {"kind": "absorber"}, [20.0], 400,
                              {"paths": 1000, "realizations": 64, "seed": 2}), []),
    "points-rings-spheres": (config(SPHERES_030, LAMBERT_08, [0.0, 60.0], 200,
                                    {"paths": 20_000, "realizations": 8, "seed": 5}, sensor=POINTS_AND_RINGS), []),
    "points-rings-spheres-embreex": (config(dict(SPHERES_030, subdivisions=1), LAMBERT_08, [30.0], 200,
                                            {"paths": 10_000, "realizations": 4, "seed": 5}, sensor=POINTS_AND_RINGS),
                                     ["--backend", "embreex"]),
    "points-rings-medium": (config({"kind": "halfspace_medium"}, {"kind": "lambert", "albedo": 0.9}, [0.0, 70.0], 200,
                                   {"paths": 40_000, "realizations": 8, "seed": 5}, sensor=POINTS_AND_RINGS), []),
    "points-rings-vcavities": (config({"kind": "vcavities", "roughness": 0.6}, LAMBERT_08, [0.0, 50.0], 200,
                                      {"paths": 40_000, "realizations": 8, "seed": 5}, sensor=POINTS_AND_RINGS), []),
}


def jobs(config_dir: Path) -> dict[str, list[str]]:
    """name -> `microsim run` arguments (without --out) of every config checked."""
    out = {}
    for path in sorted((ROOT / "runs").glob("*.toml")):
        out[f"runs/{path.name}"] = [str(path), "--paths", str(SHIPPED_PATHS)]
    for name, (data, flags) in TEST_CONFIGS.items():
        path = config_dir / f"{name}.toml"
        path.write_text(dict_to_toml(data))
        out[name] = [str(path), *flags]
    return out


def write_tables(source: Path, job_args: dict[str, list[str]], out_dir: Path, flags: list[str]) -> None:
    """Run every job with the microsim of ``source`` (a checkout) and ``flags``, tables into ``out_dir``."""
    env = dict(os.environ, PYTHONPATH=str(source))
    for name, args in job_args.items():
        table = out_dir / (name.replace("/", "_") + ".h5")
        command = [sys.executable, "-m", "microsim", "run", *args, *flags, "--out", str(table), "--force"]
        done = subprocess.run(command, cwd=source, env=env, capture_output=True, text=True)
        if done.returncode != 0:
            raise SystemExit(f"{source}: {name} failed: {done.stderr.strip()}")


def contents(path: Path) -> dict:
    """Every dataset as (dtype, shape, bytes) and every attribute, by HDF5 path, minus provenance."""
    items = {}
    with h5py.File(path, "r") as h5:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset):
                value = obj[()]
                items[name] = (value.dtype.str, np.shape(value), np.asarray(value).tobytes())
            for key, value in obj.attrs.items():
                items[f"{name}@{key}"] = repr(value)
        visit("", h5)
        h5.visititems(visit)
    return {k: v for k, v in items.items() if k.split("@")[-1] not in PROVENANCE}


def differences(a: Path, b: Path) -> tuple[list[str], list[str]]:
    """(datasets that differ, attributes that differ) between two tables."""
    ca, cb = contents(a), contents(b)
    differ = sorted(k for k in ca.keys() | cb.keys() if ca.get(k) != cb.get(k))
    return [k for k in differ if "@" not in k], [k for k in differ if "@" in k]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", required=True, help="git revision whose tables must be matched")
    parser.add_argument("--only", help="check only the configs whose name contains this text")
    parser.add_argument("--this-flags", default="", help="extra `microsim run` flags for this checkout only")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        other = tmp / "checkout"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "--quiet", str(other), args.against],
                       check=True)
        try:
            job_args = {k: v for k, v in jobs(tmp).items() if args.only is None or args.only in k}
            for label, source, flags in (("this", ROOT, shlex.split(args.this_flags)), ("other", other, [])):
                (tmp / label).mkdir()
                write_tables(source, job_args, tmp / label, flags)
            failed = 0
            for name in job_args:
                file = name.replace("/", "_") + ".h5"
                datasets, attributes = differences(tmp / "this" / file, tmp / "other" / file)
                failed += bool(datasets)
                verdict = "identical" if not datasets else "DIFFERS in " + ", ".join(datasets)
                extra = f" (attributes differ: {', '.join(attributes)})" if attributes else ""
                print(f"{name:36s} {verdict}{extra}")
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(other)], check=True)
    print(f"{len(job_args) - failed} of {len(job_args)} tables bit-identical to {args.against}, dataset by dataset")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
