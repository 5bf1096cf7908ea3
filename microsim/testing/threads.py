"""Bit identity for any number of threads (a check every integrator takes).

Contract: a tracer's tally, and a run's table, are the same bit for bit whatever the number of
threads: :func:`assert_bit_identical_for_threads` compares one tracer's tallies of one unit on
one thread and on two; :func:`assert_same_table_for_threads` traces a whole config on each
thread count and compares the tables byte for byte (:func:`microsim.testing.tables.same_table`),
with paths enough that every realization spans several of the scheduler's chunks
(:func:`spanning_chunks`), or two threads would have nothing to share.
"""

import math

import numpy as np

from microsim import geometry, tables
from microsim.physics.rng import geometry_rng, stream_key
from microsim.testing.runs import trace, validated
from microsim.testing.tables import same_table
from microsim.tracer.integrators.scheduler import CHUNK_PATHS
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


def spanning_chunks(realizations: int) -> int:
    """``run.paths`` of ``realizations`` realizations of two chunks of paths and part of a third each."""
    return realizations * (2 * CHUNK_PATHS + 17)


def assert_same_table_for_threads(config: dict, directory, threads=(1, 2)) -> None:
    """The table of ``config`` (a dictionary) is the same, byte for byte, on each number of
    ``threads`` (written in ``directory``), each run traced on that many threads indeed."""
    cfg, paths = validated(config), []
    for k in threads:
        result = trace(cfg, threads=k)
        assert result.plan.threads == k, f"traced on {result.plan.threads} thread(s), not {k}: " \
                                         f"{result.plan.backend_note}"
        paths.append(tables.write(directory / f"threads{k}.h5", result, cfg))
    assert all(same_table(paths[0], other) for other in paths[1:]), f"tables differ between threads {threads}"
