"""Memory does not grow with ``paths``, and a run that cannot fit is refused before it starts."""

import dataclasses

import numpy as np
import pytest

from microsim import config, tables
from microsim.cli import main
from microsim.physics.rng import geometry_rng
from microsim.run import memory
from microsim.run.memory import available_memory, check_memory, memory_estimate
from microsim.run.plan import Plan
from microsim.tracer.integrators import embreex
from microsim.tracer.integrators.surface import SurfaceTracer
from microsim.tracer.sensor import Sensor


def spheres(paths: int, backend: str = "direct", **scene) -> config.Config:
    return config.validate({
        "scene": {"kind": "poisson_spheres", "volume_fraction": 0.3, "tile": 8.0, "depth": 3.0, **scene},
        "material": {"kind": "lambert", "albedo": 0.8},
        "illumination": {"theta_i_deg": [0.0, 60.0]},
        "sensor": {"cells": 100},
        "run": {"paths": paths, "realizations": 4, "backend": backend},
    })


def test_the_embreex_backend_traces_a_unit_in_batches_of_bounded_size(monkeypatch):
    cfg = spheres(4, "embreex", subdivisions=1)
    plan = Plan.from_config(cfg)
    scene = plan.generator.generate(plan.scene, plan.config, geometry_rng(1, 0))
    sensor = Sensor.build(100)
    whole = SurfaceTracer(scene, sensor, "embreex").trace(plan.incidence_direction(1), 5000, 7, 0)
    monkeypatch.setattr(embreex, "BATCH_PATHS", 1024)
    tracer = SurfaceTracer(scene, sensor, "embreex")
    batched = tracer.trace(plan.incidence_direction(1), 5000, 7, 0)
    assert len(tracer.backend.paths.weight) == 1024  # rows held at once
    assert np.array_equal(whole.counts, batched.counts)  # the same paths: streams keyed by path number
    assert np.allclose(whole.estimates[0].weight, batched.estimates[0].weight, rtol=1e-12, atol=0)
    assert np.allclose(whole.energy, batched.energy, rtol=1e-12, atol=0)


def test_the_memory_estimate_does_not_grow_with_paths():
    for backend, scene in (("direct", {}), ("embreex", {"subdivisions": 2})):
        two_batches, huge = (Plan.from_config(spheres(paths, backend, **scene))
                             for paths in (4 * 2 * embreex.BATCH_PATHS, 10**12))
        assert memory_estimate(huge, 2) == memory_estimate(two_batches, 2)
        assert memory_estimate(huge, 1) < 2**30


@pytest.mark.skipif(available_memory() is None, reason="no /proc/meminfo: the free memory is unknown")
def test_a_run_that_cannot_fit_is_refused_in_one_line(tmp_path, capsys):
    path = tmp_path / "huge.toml"
    path.write_text(tables.config_to_toml(spheres(1000, tile=10_000.0, depth=1000.0)))  # 1e10 spheres
    out = tmp_path / "huge.h5"
    assert main(["run", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("microsim: error: this run needs about ") and "GiB are free" in err[0]
    assert not out.exists()


def test_two_threads_build_the_next_realization_ahead_where_two_scenes_fit(monkeypatch):
    cfg = spheres(1000).model_copy(update={"run": spheres(1000).run.model_copy(update={"realizations": 2})})
    plan = Plan.from_config(cfg, threads=2)  # 4 units: too few to trace side by side, so only the scenes differ
    assert plan.builds_ahead and not Plan.from_config(cfg).builds_ahead
    one_scene = memory_estimate(dataclasses.replace(plan, builds_ahead=False), 1)
    assert memory_estimate(plan, 1) - one_scene == plan.generator.scene_bytes(plan.scene)
    monkeypatch.setattr(memory, "available_memory", lambda: one_scene)  # room for one scene, not two
    check_memory(plan, 1)
    assert not plan.builds_ahead
