"""The estimator seam: a new estimator with a config key and a comparison is one module and one
registration (tests/toy_estimator.py), and the config, the runner, the unit store, the table
writer, compare, fit and the CLI carry its keys, outputs and judge without naming it.

The checks run in a process of their own, with a numba cache of their own: the toy's hook is
compiled into microsim's kernels, whose cache stamp then covers its file (microsim.tracer.jit.kernel_cache),
and the suite's other processes, which do not register it, keep theirs. The registration comes
before anything imports ``microsim.config``, whose ``[sensor]`` section is composed of the
registered estimators' keys when it is imported.
"""

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from microsim import tables
from microsim.cli import cli
from microsim.config import ConfigError, validate
from microsim.run import unit_store
from microsim.run.plan import Plan
from microsim.testing import trace, trace_albedos, write_table
from microsim.tracer import estimators

HERE = Path(__file__).resolve().parent


def medium(cone_deg: float | None = None, albedo=0.8, paths: int = 400_000):
    """A half space of isotropic point scatterers (whose BRDF is rte_isotropic's, exactly) at three
    incidences, the cone of ``cone_deg`` tallied (None: the key's default); the medium's kernel
    compiles in a few seconds."""
    sensor = {"cells": 50} | ({} if cone_deg is None else {"cone_deg": cone_deg})
    return validate({"scene": {"kind": "halfspace_medium", "phase": "isotropic"},
                     "material": {"kind": "lambert", "albedo": albedo},
                     "illumination": {"theta_i_deg": [0.0, 40.0, 75.0]}, "sensor": sensor,
                     "run": {"paths": paths, "realizations": 8, "seed": 2}})


def check_a_registered_estimator_writes_its_dataset(tmp_path):
    """Over the whole hemisphere (the key's default) the cone's f by order is the albedo by
    order over pi, which the exit binning sums over its cells: the two agree to rounding, in
    every realization (stderr too)."""
    path = write_table(medium(paths=20_000), tmp_path / "t.h5")
    table = tables.load(path)
    cone, error = table.arrays["brdf_cone_order"] * math.pi, table.arrays["brdf_cone_order_stderr"] * math.pi
    assert cone.shape == (3, 4) and table.attrs["cone_deg"] == 90.0
    assert np.allclose(cone, table.arrays["albedo_order"], rtol=1e-12, atol=0)
    assert np.allclose(error, table.arrays["albedo_order_stderr"], rtol=1e-9, atol=1e-15)


def check_an_estimator_counts_each_albedo_of_a_run_of_several(tmp_path):
    """Each table of a run of several albedos holds the cone of its own albedo."""
    for result in trace_albedos(medium(albedo=[0.5, 1.0], paths=4000)):
        cone = np.stack([e.mean[:4] for e in result.estimates["brdf_cone"]]) * math.pi
        albedo = np.stack([e.mean[:4] for e in result.estimates["albedo"]])
        assert np.allclose(cone, albedo, rtol=1e-12, atol=0)


def check_its_key_is_a_config_key_and_refused_out_of_range(tmp_path):
    """Its key joins [sensor], with its range: one line naming it refuses a value outside."""
    assert medium(40.0).sensor.cone_deg == 40.0
    try:
        medium(120.0)
    except ConfigError as refused:
        assert "sensor.cone_deg" in str(refused) and "\n" not in str(refused), str(refused)
    else:
        raise AssertionError("cone_deg = 120 was not refused")


def check_compare_and_fit_judge_it_by_its_flag(tmp_path):
    """In the half space, ``compare --cone`` finds rte_isotropic of the medium's albedo consistent
    and one 2 % off not; ``fit --cone`` finds the albedo within 3 of its standard errors, which are
    under 0.5 %."""
    path = write_table(medium(40.0), tmp_path / "medium.h5")
    runner = CliRunner()
    verdicts = []
    for albedo in (0.8, 0.816):
        done = runner.invoke(cli, ["compare", str(path), "--model", "rte_isotropic", "--param", f"albedo={albedo}",
                                   "--cone", "--json"])
        assert done.exit_code == 0, done.output
        result = json.loads(done.output)
        assert result["on"] == "cone" and result["overall"]["cones_compared"] == 3
        verdicts.append(result["overall"]["consistent"])
    assert verdicts == [True, False]
    done = runner.invoke(cli, ["fit", str(path), "--model", "rte_isotropic", "--free", "albedo", "--cone", "--json"])
    assert done.exit_code == 0, done.output
    value, error = (json.loads(done.output)["fit"]["albedo"][k] for k in ("value", "stderr"))
    assert 0 < error < 0.004 and abs(value - 0.8) < 3 * error, (value, error)


def check_the_unit_store_keeps_and_gives_back_an_estimators_fields(tmp_path):
    cfg = medium(paths=4000)
    plan = Plan.from_config(cfg)
    store = unit_store.UnitStore.open(tmp_path / "t.h5.partial", plan, resume=False)
    traced = trace(cfg, store=store)
    saved = store.load(plan.units[0])[0]
    # the points' record is every run's (empty without points: one kernel for runs with and without)
    assert [type(record).__name__ for record in saved.estimates] == ["ExitBinsTally", "RetroRingsTally", "PointsTally",
                                                                      "ConeTally"]
    resumed = trace(cfg, store=store)  # every unit from the store
    assert resumed.units_traced == 0
    for name, estimates in traced.estimates.items():
        for mine, theirs in zip(estimates, resumed.estimates[name]):
            assert np.array_equal(mine.mean, theirs.mean) and np.array_equal(mine.stderr, theirs.stderr)


#: the registration of the toy, made in the test's process before microsim.config is imported
REGISTRATION = "from microsim.tracer import estimators; estimators.ESTIMATORS['cone'] = 'toy_estimator:Cone'"


def main(directory: str) -> None:
    """Run every check (in the subprocess of the test, the toy registered)."""
    assert estimators.ESTIMATORS["cone"] == "toy_estimator:Cone"
    for name, check in sorted(globals().items()):
        if name.startswith("check_"):
            (Path(directory) / name).mkdir()
            check(Path(directory) / name)


def test_a_toy_estimator_with_a_key_and_a_comparison_is_one_module_and_one_registration(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba"),
           "PYTHONPATH": os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-c", f"{REGISTRATION}; import test_estimators; test_estimators.main({str(tmp_path)!r})"],
                          env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]


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

    plan = Plan.from_config(medium())
    assert plan.estimators and plan.tracer_class  # built, cached, pickled with the plan, as a run has them
    done = subprocess.run([sys.executable, "-c", UNPICKLED_PLAN], input=pickle.dumps(plan), capture_output=True,
                          cwd=HERE.parent)
    assert done.returncode == 0, done.stderr.decode()
    assert done.stdout.decode().split("\n")[0] == "['ExitBinsTally', 'PointsTally', 'RetroRingsTally']"
