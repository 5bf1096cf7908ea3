"""Resumable runs: finished units are kept in <table>.partial as
they end; a run killed by SIGKILL, or stopped by SIGTERM, and then resumed writes a table bit-
identical to an uninterrupted run, tracing only the units that were missing (counted); a
resume of another config is refused in one line; kept units are never discarded unasked."""

import os
import re
import signal
import sys
import time
from pathlib import Path

import pytest

from microsim import config as config_module
from microsim.cli import main
from microsim.run import memory, unit_store
from microsim.run.plan import Plan
from microsim.testing import trace
from microsim.testing.interruptions import RUN, UNITS, kill_at_half, saved, start, wait_for_units
from microsim.testing.tables import same_table

RESUMED = re.compile(r"(\d+) of (\d+) units resumed, (\d+) traced")


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    """The table of the run traced at once (on 2 workers: bit-identical to 1, test_cli_run)."""
    folder = tmp_path_factory.mktemp("whole")
    config = folder / "run.toml"
    config.write_text(RUN)
    out = folder / "whole.h5"
    assert main(["run", str(config), "--out", str(out), "--workers", "2"]) == 0
    assert not unit_store.store_path(out).exists(), "the units outlived the finished table"
    return out


def resume(config: Path, out: Path, capsys, *flags) -> tuple[int, int]:
    """Resume the run into ``out``; (units resumed, units traced) as the run line reports them."""
    before = saved(out)
    assert 0 < before < UNITS
    capsys.readouterr()
    assert main(["run", str(config), "--out", str(out), "--resume", *flags]) == 0
    resumed, total, traced = map(int, RESUMED.search(capsys.readouterr().out).groups())
    assert (resumed, total, traced) == (before, UNITS, UNITS - before)
    assert not unit_store.store_path(out).exists()
    return resumed, traced


@pytest.mark.slow
def test_a_run_killed_at_half_its_units_resumes_bit_identical(tmp_path, uninterrupted, capsys):
    config = tmp_path / "run.toml"
    config.write_text(RUN)
    out = tmp_path / "killed.h5"
    kill_at_half(start(config, out, "--workers", "2"), out)
    resumed, traced = resume(config, out, capsys)
    assert UNITS // 2 <= resumed < UNITS and resumed + traced == UNITS
    assert same_table(out, uninterrupted)


@pytest.mark.slow
def test_a_run_stopped_by_sigterm_keeps_its_units_and_resumes_bit_identical(tmp_path, uninterrupted, capsys):
    config = tmp_path / "run.toml"
    config.write_text(RUN)
    out = tmp_path / "stopped.h5"
    process = start(config, out)
    try:
        wait_for_units(process, out, 5)
        process.send_signal(signal.SIGTERM)
        status = process.wait(timeout=15)
        stderr = process.communicate(timeout=10)[1]
    finally:
        process.kill()
    kept = saved(out)
    assert status == -signal.SIGTERM and not out.exists()
    assert stderr.splitlines() == [f"microsim: error: stopped by SIGTERM; no table written; {kept} of {UNITS} units "
                                   f"kept in {unit_store.store_path(out)} (rerun with --resume to finish)"]
    resume(config, out, capsys, "--threads", "2")
    assert same_table(out, uninterrupted)


def test_units_are_kept_only_for_the_same_run(tmp_path, capsys):
    """Changed config: refused in one line, units kept. No --resume: refused, units kept.
    --force: discarded and traced afresh."""
    config = tmp_path / "run.toml"
    config.write_text(RUN.replace("paths = 2_560_000", "paths = 3200"))
    out = tmp_path / "t.h5"
    plan = Plan.from_config(config_module.load(config))
    store = unit_store.UnitStore.open(unit_store.store_path(out), plan, resume=False)
    trace(config_module.load(config), store=store)  # every unit kept, no table
    store.release()  # as a run that died
    files = sorted(p.name for p in store.directory.iterdir())
    assert len(files) == UNITS + 1

    capsys.readouterr()
    assert main(["run", str(config), "--out", str(out), "--resume", "--paths", "6400"]) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"microsim: error: --resume: {store.directory} holds units of another run (run.paths: 3200 -> 6400); rerun "
        "with the config they came from, or pass --force to discard them"]
    assert main(["run", str(config), "--out", str(out)]) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"microsim: error: {store.directory} holds {UNITS} finished units of an interrupted run: pass --resume to "
        "continue it, or --force to discard them"]
    assert sorted(p.name for p in store.directory.iterdir()) == files and not out.exists()

    assert main(["run", str(config), "--out", str(out), "--resume"]) == 0
    assert RESUMED.search(capsys.readouterr().out).groups() == (str(UNITS), str(UNITS), "0")
    fresh = tmp_path / "fresh.h5"
    assert main(["run", str(config), "--out", str(fresh)]) == 0
    assert same_table(out, fresh)

    store = unit_store.UnitStore.open(unit_store.store_path(out), plan, resume=False)
    trace(config_module.load(config), store=store)
    store.release()
    assert main(["run", str(config), "--out", str(out), "--force"]) == 0
    assert "resumed" not in capsys.readouterr().out and not store.directory.exists()


def test_a_damaged_unit_file_is_never_taken(tmp_path):
    """Units are written under a temporary name and renamed: a half-written file is not a unit."""
    path = tmp_path / "run.toml"
    path.write_text(RUN)
    plan = Plan.from_config(config_module.load(path))
    store = unit_store.UnitStore.open(tmp_path / "units", plan, resume=False)
    (store.directory / ".r0_i0.npz.tmp").write_bytes(b"half a unit")
    assert store.saved_units() == []


def test_progress_counts_resumed_units_as_done_and_times_only_the_traced(tmp_path, monkeypatch):
    """Resumed units count as done but not in the rate, nor does the first traced unit (it carries
    the start); seconds numba spent compiling while a unit traced are not in the rate either,
    and the line says so while numba compiles."""
    from types import SimpleNamespace

    from microsim.app import progress as progress_module

    path = tmp_path / "run.toml"
    path.write_text(RUN)
    plan = Plan.from_config(config_module.load(path))
    clock = [100.0]
    monkeypatch.setattr(progress_module, "time", SimpleNamespace(monotonic=lambda: clock[0]))
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    watch = SimpleNamespace(seconds=0.0)
    progress = progress_module.ProgressBar()
    progress.start(plan, compile_seconds=20)
    try:
        progress.compiling()
        task = progress.bar.tasks[0]
        assert (task.description, task.fields["status"]) == ("compiling", "the tracer, for this machine (once; about 20 s)")
        progress.tracing(watch)
        for unit in plan.units[:3]:
            progress.unit(unit, plan.paths_per_realization, True)
        assert task.fields["status"].endswith("starting")  # no rate from resumed units
        clock[0] += 30.0  # the first traced unit carries the start: not in the rate
        progress.unit(plan.units[3], plan.paths_per_realization, False)
        assert task.fields["status"].endswith("starting")
        clock[0] += 2.0 + 7.0  # the next unit traced in 2 s, and 7 s of compiling meanwhile
        watch.seconds = 7.0
        progress.unit(plan.units[4], plan.paths_per_realization, False)
        status = task.fields["status"]
    finally:
        progress.stop()
    assert task.description == "tracing"
    assert status == (f"5/{UNITS} units, {5 * plan.paths_per_realization // 2:,} of {plan.paths:,} paths per "
                      f"incidence, {2.0 * (UNITS - 5):.0f} s left")


def kept_units(config: Path, out: Path) -> list[str]:
    """Trace every unit of ``config`` into the store of ``out`` and stop there, as a run killed
    just before writing its table; the store's file names."""
    plan = Plan.from_config(config_module.load(config))
    store = unit_store.UnitStore.open(unit_store.store_path(out), plan, resume=False)
    trace(config_module.load(config), store=store)
    store.release()
    return sorted(p.name for p in store.directory.iterdir())


def small_run(tmp_path) -> Path:
    config = tmp_path / "run.toml"
    config.write_text(RUN.replace("paths = 2_560_000", "paths = 3200"))
    return config


def test_a_refused_resume_keeps_every_unit(tmp_path, capsys, monkeypatch):
    """Refusals (memory, a store in use by another run) come before the store is touched."""
    config, out = small_run(tmp_path), tmp_path / "t.h5"
    files = kept_units(config, out)
    monkeypatch.setattr(memory, "available_memory", lambda: 2**20)
    capsys.readouterr()
    assert main(["run", str(config), "--out", str(out), "--resume"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "GiB are free" in err[0]
    monkeypatch.undo()
    plan = Plan.from_config(config_module.load(config))
    holder = unit_store.UnitStore.open(unit_store.store_path(out), plan, resume=True)  # another run
    try:
        assert main(["run", str(config), "--out", str(out), "--resume"]) == 2
        assert capsys.readouterr().err.splitlines() == [
            f"microsim: error: {holder.directory} is in use by another run writing the same table; wait for it to "
            "end, or give this one another --out"]
    finally:
        holder.release()
    assert sorted(p.name for p in unit_store.store_path(out).iterdir()) == files and not out.exists()


def test_damaged_unit_files_are_traced_again(tmp_path, capsys):
    """A unit file cut short (a machine that crashed before the disk had it) is dropped and its
    unit traced again; the table is still the uninterrupted one."""
    config, out = small_run(tmp_path), tmp_path / "t.h5"
    files = [name for name in kept_units(config, out) if name.endswith(".npz")]
    store = unit_store.store_path(out)
    (store / files[0]).write_bytes(b"")
    (store / files[1]).write_bytes((store / files[1]).read_bytes()[:500])
    (store / f".{files[2]}.tmp").write_bytes(b"half a unit")
    capsys.readouterr()
    assert main(["run", str(config), "--out", str(out), "--resume"]) == 0
    assert RESUMED.search(capsys.readouterr().out).groups() == (str(UNITS - 2), str(UNITS), "2")
    fresh = tmp_path / "fresh.h5"
    assert main(["run", str(config), "--out", str(fresh)]) == 0
    assert same_table(out, fresh) and not store.exists()


def test_a_signal_while_the_tables_are_written_waits_for_them():
    """Once tracing is over a signal no longer interrupts: the tables are written and the store
    cleared first, then the run stops saying so (the message must not claim no table)."""
    from microsim.core import interrupts

    events = []
    with pytest.raises(interrupts.Stopped) as stopped:
        with interrupts.StopOnSignals() as guard:
            with guard.hold():
                os.kill(os.getpid(), signal.SIGTERM)
                time.sleep(0.05)  # the handler runs here, and must not raise
                events.append("tables written")
    assert events == ["tables written"]
    assert stopped.value.message == "stopped by SIGTERM once its tables were written"
    assert stopped.value.exit_code == 128 + signal.SIGTERM


def test_a_full_disk_ends_the_run_in_one_line_keeping_its_units(tmp_path, capsys, monkeypatch):
    """ENOSPC in unit_store.save ends the run in one line, keeping the units saved and leaving no
    .tmp file."""
    import errno

    import numpy as np

    config = tmp_path / "run.toml"
    config.write_text(RUN.replace("paths = 2_560_000", "paths = 3200"))
    out = tmp_path / "t.h5"
    real_savez, calls = np.savez, []

    def savez_until_full(handle, **arrays):
        calls.append(1)
        if len(calls) > 3:
            handle.write(b"partial")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        real_savez(handle, **arrays)

    monkeypatch.setattr(unit_store.np, "savez", savez_until_full)
    assert main(["run", str(config), "--out", str(out)]) == 1
    lines = capsys.readouterr().err.splitlines()
    store = unit_store.store_path(out)
    assert len(lines) == 1 and "No space left on device" in lines[0] and "MB free" in lines[0], lines
    assert lines[0].endswith(f"; 3 of {UNITS} units kept in {store} (rerun with --resume to finish)"), lines[0]
    assert not out.exists() and not list(store.glob(".*.tmp")) and len(list(store.glob("r*.npz"))) == 3


def test_a_table_that_cannot_be_written_ends_the_run_in_one_line_keeping_every_unit(tmp_path, capsys, monkeypatch):
    """A full disk while the table is written (after every unit was traced): one line naming the
    table, the reason and the space left, exit 1, every unit kept for --resume, no temporary."""
    import errno

    import h5py

    config = tmp_path / "run.toml"
    config.write_text(RUN.replace("paths = 2_560_000", "paths = 3200"))
    out = tmp_path / "t.h5"

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(h5py.Dataset, "attrs", property(full))
    assert main(["run", str(config), "--out", str(out)]) == 1
    lines = capsys.readouterr().err.splitlines()
    store = unit_store.store_path(out)
    assert len(lines) == 1 and lines[0].startswith(f"microsim: error: cannot write the table {out}: No space left on "
                                                   "device, "), lines
    assert lines[0].endswith(f" MB free there; {UNITS} of {UNITS} units kept in {store} (rerun with --resume to finish)")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.toml", store.name]
    monkeypatch.undo()
    assert main(["run", str(config), "--out", str(out), "--resume"]) == 0
    assert h5py.is_hdf5(out)
