"""The Dask executor: on a LocalCluster of 2 workers the
table is bit-identical to --workers 2; with one worker killed mid-run it still is, and only the
tasks that worker held are traced again."""

import os
import signal
import socket
import subprocess
import sys
import time
from collections import Counter, defaultdict

import pytest
from distributed import LocalCluster
from distributed.diagnostics.plugin import SchedulerPlugin

from microsim import config as config_module
from microsim import tables
from microsim.cli import main
from microsim.run import executors, unit_store
from microsim.run.plan import Plan
from microsim.testing import trace
from microsim.testing.interruptions import RUN, wait_for_units
from microsim.testing.tables import same_table

SMALL = RUN.replace("paths = 2_560_000", "paths = 640_000")


class Assignments(SchedulerPlugin):
    """Every worker a task was sent to, by worker address: a task the scheduler sends to a
    worker after another's processing list was read is that worker's too."""

    def __init__(self, scheduler):
        self.scheduler, self.sent = scheduler, defaultdict(set)

    def transition(self, key, start, finish, *args, **kwargs):
        task = self.scheduler.tasks.get(key)
        if finish == "processing" and task is not None and task.processing_on is not None:
            self.sent[task.processing_on.address].add(key)


@pytest.mark.slow
def test_dask_on_a_local_cluster_is_bit_identical_to_local_workers(tmp_path, capsys):
    config = tmp_path / "run.toml"
    config.write_text(SMALL)
    assert main(["run", str(config), "--out", str(tmp_path / "local.h5"), "--workers", "2"]) == 0
    assert main(["run", str(config), "--out", str(tmp_path / "dask.h5"), "--workers", "2", "--executor", "dask"]) == 0
    assert "dask LocalCluster of 2 worker(s)" in capsys.readouterr().out
    assert same_table(tmp_path / "local.h5", tmp_path / "dask.h5")


@pytest.mark.slow
def test_a_worker_killed_mid_run_costs_only_its_tasks(tmp_path):
    config = tmp_path / "run.toml"
    config.write_text(SMALL)
    cfg = config_module.load(config)
    assert main(["run", str(config), "--out", str(tmp_path / "local.h5"), "--workers", "2"]) == 0
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        pids = {nanny.worker_address: nanny.process.pid for nanny in cluster.workers.values()}
        assignments = Assignments(cluster.scheduler)
        cluster.scheduler.add_plugin(assignments)
        lost, emitted, killed = set(), [], []

        def kill_one_worker(unit, paths, resumed):
            emitted.append(unit)
            if not lost:  # at the first unit back: kill a worker that is tracing
                victim = next(ws for ws in cluster.scheduler.workers.values() if ws.processing)
                lost.update(task.key for task in victim.processing)
                killed.append((pids[victim.address], victim.address))
                os.kill(killed[0][0], signal.SIGKILL)

        result = trace(cfg, workers=2, progress=kill_one_worker, executor="dask",
                            scheduler=cluster.scheduler_address)
        starts = Counter(t.key for t in cluster.scheduler.transition_log if t.finish == "processing")

        def alive():
            return {nanny.process.pid for nanny in cluster.workers.values() if nanny.process is not None}

        deadline = time.monotonic() + 60  # the run can end before the nanny has started the new worker
        while len(alive()) < 2 and time.monotonic() < deadline:
            time.sleep(0.1)
        replaced = alive()
    tables.write(tmp_path / "dask.h5", result, cfg)
    assert lost and killed[0][0] not in replaced and len(replaced) == 2  # the nanny started a new worker
    retried = {key for key, count in starts.items() if count > 1}
    held = assignments.sent[killed[0][1]]  # what it was tracing, and what was sent to it before it was seen dead
    assert retried and lost <= held and retried <= held, (retried, held)
    assert sorted(emitted) == sorted(Plan.from_config(cfg).units)  # every unit once
    assert same_table(tmp_path / "local.h5", tmp_path / "dask.h5")


@pytest.mark.parametrize("address, message", [
    ("foo://h:1", "expected a Dask scheduler address"),
    ("ucx://h:1", "expected a Dask scheduler address"),
    ("tcp://127.0.0.1:99999", "expected a Dask scheduler address"),
    ("tcp://127.0.0.1:9", "cannot reach a Dask scheduler there"),  # nothing listens
    ("tls://127.0.0.1:9", "cannot reach a Dask scheduler there"),  # no TLS configuration
])
def test_a_bad_or_unreachable_scheduler_is_refused_in_one_line(address, message, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(executors, "SCHEDULER_TIMEOUT", "2s")
    config = tmp_path / "run.toml"
    config.write_text(SMALL)
    assert main(["run", str(config), "--out", str(tmp_path / "t.h5"), "--executor", "dask", "--scheduler", address]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and message in err[0] and address in err[0], err
    assert [p.name for p in tmp_path.iterdir()] == ["run.toml"]


def test_a_lost_cluster_ends_the_run_in_one_line_keeping_its_units(tmp_path):
    """The scheduler (a process of its own, as on a cluster) dies mid-run: one line on stderr,
    exit 1, the finished units kept for --resume."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    config = tmp_path / "run.toml"
    config.write_text(RUN.replace("paths = 2_560_000", "paths = 40_000_000"))
    out = tmp_path / "t.h5"
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    scheduler = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                  "--port", str(port), "--no-dashboard"], **quiet)
    worker = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1",
                               "--no-dashboard"], **quiet)
    run = None
    try:
        run = subprocess.Popen([sys.executable, "-m", "microsim", "run", str(config), "--out", str(out),
                                "--executor", "dask", "--scheduler", address], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
        wait_for_units(run, out, 2)
        scheduler.kill()
        status = run.wait(timeout=120)
        stderr = run.communicate()[1]
    finally:
        for process in (scheduler, worker, run):
            if process is not None:
                process.kill()
                process.wait()
    kept = len(list(unit_store.store_path(out).glob("r*.npz")))
    lines = stderr.splitlines()
    assert status == 1 and len(lines) == 1, stderr
    assert lines[0].startswith("microsim: error: the Dask cluster was lost (")
    assert lines[0].endswith(f"; {kept} of 32 units kept in {unit_store.store_path(out)} (rerun with --resume to "
                             "finish)") and kept >= 2
    assert not out.exists()
