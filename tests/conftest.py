"""The fixtures of the suite: ``simulate``, a config dictionary run end to end and its table read
back (:mod:`microsim.testing.tables`); and the rule that a test of a million paths or more is
marked ``slow``, checked on every test; and a packing cache of each test process's own
(``MICROSIM_CACHE``, :mod:`microsim.geometry.packings`).

The paths a test traces are counted where every run hands its units to an executor
(``runner.EXECUTORS``: paths per realization for every unit it hands back traced, in this
process, on any executor and any number of workers; units a resumed run takes from its store are
not traced, nor counted), during the test and during the setup of each fixture it uses; a test
that reaches :data:`SLOW_PATHS` without the ``slow`` marker fails and says how many it traced.
Runs in subprocesses, and tracers a test calls itself (``executors.trace_units``), are not counted.
"""

import os
import tempfile

import pytest

# Each process of the suite (an xdist worker, a run it starts) is one of two on two cores:
# OpenBLAS's own threads (two a process by default) in both workers at once spin against each
# other, and the model tests ran 1.7 times slower for it. Set before numpy is first imported.
# Embree's scene builds likewise take one thread (its device's configuration string,
# microsim.tracer.embree.DEVICE_CONFIG_VARIABLE): the tests of Embree scenes ran 6 % faster.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MICROSIM_EMBREE_CONFIG", "threads=1")

from microsim import tables  # noqa: E402
from microsim.run import runner  # noqa: E402
from microsim.testing.tables import trace_table  # noqa: E402

#: paths from which a test is marked slow (the README: ``-m "not slow"`` leaves them out)
SLOW_PATHS = 1_000_000

_traced = [0]  # paths handed to executors in this process
_fixture_paths: dict = {}  # fixture definition -> paths its latest setup traced


def _counting(execute):
    def counted(plan, units, emit, *args, **kwargs):
        def emit_counted(unit, tally, info):
            _traced[0] += plan.paths_per_realization
            emit(unit, tally, info)

        return execute(plan, units, emit_counted, *args, **kwargs)

    return counted


def pytest_configure(config):
    # the packings a test generates are kept for this process's other tests, not in the user's cache
    os.environ["MICROSIM_CACHE"] = tempfile.mkdtemp(prefix="microsim-cache-")
    for name, execute in runner.EXECUTORS.items():
        runner.EXECUTORS[name] = _counting(execute)


@pytest.hookimpl(wrapper=True)
def pytest_fixture_setup(fixturedef, request):
    before = _traced[0]
    try:
        return (yield)
    finally:
        _fixture_paths[fixturedef] = _traced[0] - before


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item):
    before = _traced[0]
    result = yield
    used = [definitions[-1] for definitions in item._fixtureinfo.name2fixturedefs.values() if definitions]
    traced = _traced[0] - before + sum(_fixture_paths.get(definition, 0) for definition in used)
    if traced >= SLOW_PATHS and item.get_closest_marker("slow") is None:
        pytest.fail(f"traces {traced:,} paths (with its fixtures): mark it @pytest.mark.slow (from {SLOW_PATHS:,})")
    return result


@pytest.fixture
def simulate(tmp_path):
    """``simulate(dict, workers=1) -> Table``: validate, trace, write the HDF5 table, load it
    (:func:`microsim.testing.tables.trace_table`), in the test's temporary directory."""
    counter = iter(range(1000))

    def run(data: dict, workers: int = 1) -> tables.Table:
        return trace_table(data, tmp_path / f"table{next(counter)}.h5", workers=workers)

    return run
