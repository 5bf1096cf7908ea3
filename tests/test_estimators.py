"""The estimator seam: a new estimator is one module and one registration (tests/toy_estimator.py),
and the runner, the unit store and the table writer carry its outputs by name.

The checks run in a process of their own, with a numba cache of their own: the toy's hook is
compiled into microsim's kernels, whose cache stamp then covers its file (microsim.tracer.jit.kernel_cache),
and the suite's other processes, which do not register it, keep theirs.
"""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from microsim import tables
from microsim.config import validate
from microsim.run import unit_store
from microsim.run.plan import Plan
from microsim.testing import trace, trace_albedos, write_table
from microsim.tracer import estimators

HERE = Path(__file__).resolve().parent


def vcavities(albedo, paths=20_000):
    return validate({
        "scene": {"kind": "vcavities", "roughness": 0.8}, "material": {"kind": "lambert", "albedo": albedo},
        "illumination": {"theta_i_deg": [0.0, 60.0]}, "sensor": {"cells": 100},
        "run": {"paths": paths, "realizations": 4, "seed": 3}})


def check_a_registered_estimator_writes_its_dataset(tmp_path):
    """On white V-cavities every path keeps weight 1 (no absorption, no roulette), so the fraction
    of paths leaving after k interactions is the albedo of order k, which the exit binning counts
    by weight: the two estimators agree to rounding, in every realization (stderr too)."""
    cfg = vcavities(1.0)
    path = write_table(cfg, tmp_path / "t.h5")
    table = tables.load(path).arrays
    fraction, error = table["exit_fraction_order"], table["exit_fraction_order_stderr"]
    assert fraction.shape == (2, 4)
    assert np.allclose(fraction, table["albedo_order"], rtol=1e-12, atol=0)
    assert np.allclose(error, table["albedo_order_stderr"], rtol=1e-9, atol=1e-15)
    assert np.allclose(fraction.sum(axis=1), 1.0, rtol=1e-12)


def check_an_estimator_counts_each_albedo_of_a_run_of_several(tmp_path):
    """Counts do not depend on the albedo: every table of a run of several holds the same."""
    first, second = trace_albedos(vcavities([0.5, 1.0], paths=4000))
    a, b = (np.stack([e.mean for e in r.estimates["exit_fraction_order"]]) for r in (first, second))
    assert np.array_equal(a, b) and np.allclose(a.sum(axis=1), 1.0, rtol=1e-12)


def check_the_unit_store_keeps_and_gives_back_an_estimators_fields(tmp_path):
    cfg = vcavities(0.9, paths=4000)
    plan = Plan.from_config(cfg)
    store = unit_store.UnitStore.open(tmp_path / "t.h5.partial", plan, resume=False)
    traced = trace(cfg, store=store)
    saved = store.load(plan.units[0])[0]
    # the points' record is every run's (empty without points: one kernel for runs with and without)
    assert [type(record).__name__ for record in saved.estimates] == ["ExitBinsTally", "PointsTally", "ExitCountsTally"]
    resumed = trace(cfg, store=store)  # every unit from the store
    assert resumed.units_traced == 0
    for name, estimates in traced.estimates.items():
        for mine, theirs in zip(estimates, resumed.estimates[name]):
            assert np.array_equal(mine.mean, theirs.mean) and np.array_equal(mine.stderr, theirs.stderr)


def main(directory: str) -> None:
    """Register the toy estimator and run every check (in the subprocess of the test)."""
    estimators.ESTIMATORS["exit_counts"] = "toy_estimator:ExitCounts"
    for name, check in sorted(globals().items()):
        if name.startswith("check_"):
            (Path(directory) / name).mkdir()
            check(Path(directory) / name)


def test_a_toy_estimator_is_one_module_and_one_registration(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba"),
           "PYTHONPATH": os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-c", f"import test_estimators; test_estimators.main({str(tmp_path)!r})"],
                          env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]


if __name__ == "__main__":
    main(sys.argv[1])


#: unpickles a run's plan as a Dask worker does, then lists the records whose exit hook is registered
UNPICKLED_PLAN = """
import pickle, sys
plan = pickle.loads(sys.stdin.buffer.read())
from microsim.tracer.estimators.hooks import ON_EXIT, ON_INTERACTION
print(sorted(c.__name__ for c in (*ON_EXIT.implementations, *ON_INTERACTION.implementations)))
"""


def test_a_plan_unpickled_in_another_process_has_its_estimators_hooks_registered():
    """A Dask worker unpickles the plan with its estimators and compiles the tracer where its cache
    misses (another machine): the estimators' hook modules are imported there too, or the
    kernels would compile without them and tally nothing."""
    import pickle

    plan = Plan.from_config(vcavities(0.5))
    assert plan.estimators and plan.tracer_class  # built, cached, pickled with the plan, as a run has them
    done = subprocess.run([sys.executable, "-c", UNPICKLED_PLAN], input=pickle.dumps(plan), capture_output=True,
                          cwd=HERE.parent)
    assert done.returncode == 0, done.stderr.decode()
    assert done.stdout.decode().split("\n")[0] == "['ExitBinsTally', 'PointsTally']"
