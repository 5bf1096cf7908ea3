"""The two Embree backends, threads, and the choice between them.

On the same tessellated scene the direct backend (numba calling Embree, fused per-path kernel)
must trace exactly the paths the embreex backend traces (both build robust scenes, so every hit
is the same): every event count equal, and tables equal but for the order in which chunk sums
are added (a few ulp). Its tables must not depend on the number of threads.
"""

import subprocess
import sys
import threading

import numpy as np
import pytest

from microsim import config, tables
from microsim.cli import main
from microsim.run import executors
from microsim.run.plan import Plan, PlanError
from microsim.testing import trace
from microsim.tracer import embree
from microsim.tracer.integrators import scheduler
from microsim.tracer.integrators.surface import SurfaceTracer


def spheres(backend: str, paths: int = 24_000, **scene) -> dict:
    return {
        "scene": {"kind": "poisson_spheres", "volume_fraction": 0.4, "tile": 12.0, "depth": 6.0, **scene},
        "material": {"kind": "lambert", "albedo": 0.9},
        "base": {"kind": "interfaced_lambert", "albedo": 0.6, "eta": 1.5},
        "illumination": {"theta_i_deg": [0.0, 75.0]},
        "sensor": {"cells": 200},
        "run": {"paths": paths, "realizations": 2, "seed": 13, "backend": backend},
    }


def test_direct_backend_traces_the_same_paths_as_embreex_on_triangles():
    old = trace(config.validate(spheres("embreex", subdivisions=1)))
    new = trace(config.validate(spheres("direct", subdivisions=1)))
    assert np.array_equal(old.counts, new.counts) and old.counts[:, 1].sum() > 0  # segments, inside hits, kills
    for a, b in zip(old.brdf + old.albedo + old.energy, new.brdf + new.albedo + new.energy):
        assert np.allclose(a.mean, b.mean, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("intersector", ["embree", "grid"])
def test_tables_are_bit_identical_for_any_thread_count(intersector):
    paths = 2 * scheduler.WAVE_CHUNKS_PER_THREAD * scheduler.CHUNK_PATHS + 3 * scheduler.CHUNK_PATHS + 17  # 3 waves of one thread
    cfg = config.validate(spheres("direct", paths=paths, intersector=intersector))  # and a partial chunk
    one = trace(cfg, threads=1)
    for threads in (2, 3):  # 3: shares of a wave that differ in size
        other = trace(cfg, threads=threads)
        assert np.array_equal(one.counts, other.counts)
        for a, b in zip(one.brdf + one.albedo + one.energy, other.brdf + other.albedo + other.energy):
            assert a.total.tobytes() == b.total.tobytes() and a.squares.tobytes() == b.squares.tobytes()


@pytest.mark.parametrize("intersector", ["embree", "grid"])
def test_units_traced_side_by_side_give_the_table_of_one_thread(intersector):
    """With units enough, two or three threads trace a unit each (the next realization built on one
    of them): the table of one thread, bit for bit."""
    data = spheres("direct", paths=8 * (scheduler.CHUNK_PATHS + 17), intersector=intersector)
    data["run"]["realizations"] = 8  # 16 units of a chunk and 17 paths
    cfg = config.validate(data)
    one = trace(cfg, threads=1)
    for threads in (2, 3):
        other = trace(cfg, threads=threads)
        assert executors.side_by_side(other.plan, 16)
        assert np.array_equal(one.counts, other.counts)
        for a, b in zip(one.brdf + one.albedo + one.energy, other.brdf + other.albedo + other.energy):
            assert a.total.tobytes() == b.total.tobytes() and a.squares.tobytes() == b.squares.tobytes()


def test_an_error_while_units_trace_side_by_side_leaves_no_thread_at_work(monkeypatch):
    """The run's error (here its first unit's tally cannot be kept) ends it: what has not started
    is dropped, and when the error reaches the caller no trace or build is still under way."""
    data = spheres("direct", paths=4 * 40_000)
    data["run"]["realizations"] = 4  # 8 units of 40 000 paths, two waves each on one thread
    plan = Plan.from_config(config.validate(data), threads=2)
    assert executors.side_by_side(plan, len(plan.units))
    started, ended, lock = [], [], threading.Lock()

    def counted(function, kind):
        def run(*args, **kwargs):
            with lock:
                started.append(kind)
            try:
                return function(*args, **kwargs)
            finally:
                with lock:
                    ended.append(kind)
        return run

    build = executors.realization_builder
    monkeypatch.setattr(executors, "realization_builder", lambda plan, threads: counted(build(plan, threads), "build"))
    trace_unit = SurfaceTracer.trace
    monkeypatch.setattr(SurfaceTracer, "trace", counted(trace_unit, "trace"))

    def emit(unit, tally, info):
        raise OSError("no space left on device")

    with pytest.raises(OSError):
        executors.trace_units(plan, plan.units, emit)
    with lock:
        assert sorted(started) == sorted(ended) and started.count("trace") < len(plan.units)


def test_the_rows_two_chunks_write_share_no_cache_line():
    """What two threads write on every event (path rows, counts, lost energy) lies a cache line
    apart from chunk to chunk, so that neither invalidates the other's lines."""
    from microsim.tracer.estimators import DEFAULT, build
    from microsim.tracer.sensor import Sensor

    work = scheduler.workspace(8, build(DEFAULT, Sensor.build(100)), albedos=3)

    def lines(array, rows):  # the cache lines row span (start, stop) of array covers
        first = array[rows[0]].ctypes.data if array.ndim > 1 else array[rows[0]:].ctypes.data
        last = (array[rows[1] - 1].ctypes.data + array[rows[1] - 1].nbytes if array.ndim > 1
                else array[rows[1] - 1:].ctypes.data + array.itemsize)
        return set(range(first // 64, (last - 1) // 64 + 1))

    for j in range(7):
        for array in (work.counts, work.energy):
            assert not lines(array, (j, j + 1)) & lines(array, (j + 1, j + 2))
            assert array[j].flags.c_contiguous and not array[j].any()
        slots = scheduler.ROW_STRIDE * j, scheduler.ROW_STRIDE * j + scheduler.SLOTS
        after = scheduler.ROW_STRIDE * (j + 1), scheduler.ROW_STRIDE * (j + 1) + scheduler.SLOTS
        for array in (*work.paths, work.rays.end, work.queries):
            assert not lines(array, slots) & lines(array, after)


#: in a process of its own (a forked worker that waits on a pool thread it does not have would hang
#: the suite): two runs on two threads start no thread for the second, and workers forked after it
#: trace on two threads of their own, the same table bit for bit
ONE_POOL = """
import threading
from microsim import config
from microsim.testing import trace
cfg = config.validate({"scene": {"kind": "halfspace_medium", "phase": "isotropic"},
                       "material": {"kind": "lambert", "albedo": 0.8}, "illumination": {"theta_i_deg": [0.0, 60.0]},
                       "sensor": {"cells": 24}, "run": {"paths": 160_000, "realizations": 4, "seed": 7}})
first = trace(cfg, threads=2)
started, start = [], threading.Thread.start
threading.Thread.start = lambda thread: (started.append(thread.name), start(thread))[1]
second = trace(cfg, threads=2)
threading.Thread.start = start
assert not started, started
forked = trace(cfg, workers=2, threads=2)
for other in (second, forked):
    for a, b in zip(first.brdf + first.albedo, other.brdf + other.albedo):
        assert a.total.tobytes() == b.total.tobytes() and a.squares.tobytes() == b.squares.tobytes()
print("ok")
"""


def test_threads_share_one_pool_for_the_process_and_a_forked_worker_starts_its_own():
    """A run's units trace on one pool of threads that lives with the process (starting threads
    for each unit cost 6 % of a two-thread run), and a worker forked after it does not wait on a
    thread it has not got."""
    done = subprocess.run([sys.executable, "-c", ONE_POOL], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr[-2000:]


def unavailable(*args):
    raise embree.EmbreeUnavailable("no library here")


def test_auto_falls_back_to_embreex_when_the_binding_cannot_load(monkeypatch):
    monkeypatch.setattr(embree, "load", unavailable)
    monkeypatch.setattr(embree, "available", unavailable)
    plan = Plan.from_config(config.validate(spheres("auto", subdivisions=1)), threads=2)
    assert plan.backend == "embreex" and plan.threads == 1
    assert plan.backend_note == ("the direct backend is unavailable (no library here); "
                                 "one thread (the embreex backend has no threads)")
    exact = Plan.from_config(config.validate(spheres("auto", intersector="embree")), workers=2)
    assert exact.scene["sphere_model"] == "icosphere" and exact.scene["max_mesh_error"] <= 0.01
    assert "exact spheres traced as icospheres within mesh_error 0.01" in exact.backend_note
    walked = Plan.from_config(config.validate(spheres("auto")))  # the sphere grid needs no Embree
    assert (walked.scene["sphere_model"], walked.scene["intersector"]) == ("exact", "grid")
    assert "icospheres" not in walked.backend_note
    with pytest.raises(PlanError, match="^run.backend = 'direct': no library here$"):
        Plan.from_config(config.validate(spheres("direct", subdivisions=1)))


def test_a_fallback_run_says_why_in_the_table_and_on_the_terminal(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(embree, "load", unavailable)
    monkeypatch.setattr(embree, "available", unavailable)
    path = tmp_path / "c.toml"
    path.write_text('[scene]\nkind = "poisson_spheres"\nvolume_fraction = 0.3\ntile = 8.0\ndepth = 3.0\n'
                    'intersector = "embree"\n[material]\nkind = "lambert"\nalbedo = 0.5\n'
                    '[illumination]\ntheta_i_deg = 0.0\n[run]\npaths = 400\nrealizations = 2\n')
    out = tmp_path / "t.h5"
    assert main(["run", str(path), "--out", str(out)]) == 0
    assert "note: the direct backend is unavailable (no library here); exact spheres" in capsys.readouterr().out
    table = tables.load(out)
    assert table.attrs["backend"] == "embreex" and "no library here" in table.attrs["backend_fallback"]
    assert table.scene["sphere_model"] == "icosphere"


def test_threads_on_the_embreex_backend_are_refused_in_one_line(tmp_path, capsys):
    path = tmp_path / "c.toml"
    path.write_text('[scene]\nkind = "plane"\n[material]\nkind = "absorber"\n'
                    '[illumination]\ntheta_i_deg = 0.0\n[run]\npaths = 100\n')
    assert main(["run", str(path), "--backend", "embreex", "--threads", "2", "--out", str(tmp_path / "t.h5")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--threads 2: the embreex backend traces on one thread" in err[0]
    assert not (tmp_path / "t.h5").exists()


def test_a_library_without_embree_symbols_is_unavailable_not_a_traceback(monkeypatch):
    tbb = next(embree.library_path().parent.glob("libtbb*.so*"))
    monkeypatch.setattr(embree, "library_path", lambda: tbb)
    embree._open.cache_clear()
    try:
        with pytest.raises(embree.EmbreeUnavailable, match="^cannot load the Embree library: .*rtcNewDevice"):
            embree.available()
    finally:
        embree._open.cache_clear()


def test_kernels_compile_in_a_fresh_process_before_the_library_is_used():
    """The runner compiles before it forks workers, before any scene: the direct kernel links to
    rtcIntersect1 by name, so compiling must load the library itself (it segfaulted without)."""
    code = ("from microsim.tracer.integrators.surface import SurfaceTracer; from microsim.tracer.sensor import Sensor; "
            "SurfaceTracer.compile(Sensor.build(20))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
