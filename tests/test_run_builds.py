"""A run is planned once: the session builds its plan, sensor, estimators and unit store check once,
and compiles its tracer once, for a run and for each point of a sweep (microsim.run.runner.Run)."""

import collections

import pytest

from microsim import config
from microsim.app import session
from microsim.run import unit_store
from microsim.run.plan import Plan
from microsim.tracer import estimators
from microsim.tracer.integrators.surface import SurfaceTracer
from microsim.tracer.sensor import Sensor

PLANE = {"scene": {"kind": "plane"}, "material": {"kind": "lambert", "albedo": 0.5},
         "illumination": {"theta_i_deg": [0.0, 40.0]},
         "sensor": {"cells": 100, "directions_deg": [[30.0, 0.0]], "retro_rings": 2},
         "run": {"paths": 200, "realizations": 2, "seed": 1}}


@pytest.fixture
def builds(monkeypatch):
    """Counts, by name, of every build of a run's parts in this process."""
    counts = collections.Counter()
    for owner, name in ((Sensor, "build"), (Plan, "from_config"), (unit_store.UnitStore, "check"),
                        (SurfaceTracer, "compile"), (estimators, "build")):
        real = getattr(owner, name)  # a classmethod bound to its class, or a module's function

        def counted(*args, _real=real, _name=f"{owner.__name__.split('.')[-1]}.{name}", **kwargs):
            counts[_name] += 1
            return _real(*args, **kwargs)

        monkeypatch.setattr(owner, name, staticmethod(counted) if isinstance(owner, type) else counted)
    return counts


def test_a_run_builds_each_of_its_parts_once(builds, tmp_path):
    session.run(PLANE, tmp_path / "t.h5")
    assert dict(builds) == {"Sensor.build": 1, "Plan.from_config": 1, "UnitStore.check": 1,
                            "SurfaceTracer.compile": 1, "estimators.build": 1}


def test_a_sweep_builds_each_of_its_points_parts_once(builds, tmp_path):
    sweep = dict(PLANE, sweep={"material.albedo": [0.2, 0.9]})
    session.run(sweep, tmp_path / "sweep")
    assert dict(builds) == {"Sensor.build": 2, "Plan.from_config": 2, "UnitStore.check": 2,
                            "SurfaceTracer.compile": 2, "estimators.build": 2}


def test_the_count_sees_a_second_build(builds):
    """The check itself: a plan's sensor is built once however often it is asked, and a second
    build is counted."""
    plan = Plan.from_config(config.validate(PLANE))
    assert plan.sensor is plan.sensor
    Sensor.build(100)
    assert builds["Sensor.build"] == 2
