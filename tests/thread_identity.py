"""Bit identity of a tracer's tallies for any number of threads (a check every integrator takes)."""

import math

import numpy as np

from microsim import geometry
from microsim.physics.rng import geometry_rng, stream_key
from microsim.tracer.sensor import Sensor


def assert_bit_identical_for_threads(tracer_class, cfg, paths: int) -> None:
    """The tally of ``paths`` paths of the config's scene at theta_i = 30 deg is the same, bit for
    bit, on one thread and on two."""
    generator = geometry.SCENES[cfg.scene.kind]
    scene = generator.generate(generator.resolve(cfg), cfg, geometry_rng(1, 0))
    sensor = Sensor.build(cfg.sensor.cells)
    wi = np.array([0.5, 0.0, math.sqrt(0.75)])
    tallies = [tracer_class(scene, sensor, threads=k).trace(wi, paths, stream_key(1, 0, 0), 0) for k in (1, 2)]
    assert np.array_equal(tallies[0].estimates[0].weight, tallies[1].estimates[0].weight)
    for field in ("energy", "counts"):
        assert np.array_equal(getattr(tallies[0], field), getattr(tallies[1], field))
