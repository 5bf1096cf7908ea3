"""Stopping a run: a signal to the main process alone stops every worker, writes no table, says
so in one line and dies of the signal (as a shell expects); workers die with their parent even
when it is killed by SIGKILL; a signal ignored at start (nohup) stays ignored (issue 9, defect
1). Real processes: the run is started with the CLI, signalled once it has installed its
handlers (its caught-signal mask in /proc) and its workers trace, and the process table is read
from /proc afterwards."""

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

RUN = Path(__file__).resolve().parent.parent / "runs" / "spheres_phi030.toml"
pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads the process table in /proc")


def children(pid: int) -> list[int]:
    """Processes whose parent is ``pid``."""
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = Path(f"/proc/{entry}/stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                found.append(int(entry))
    return found


def running(pid: int) -> bool:
    """Whether ``pid`` exists and is not a zombie."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def handles_sigterm(pid: int) -> bool:
    """Whether ``pid`` has a handler for SIGTERM (the CLI installs it just before tracing)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    caught = int(next(line.split()[1] for line in status.splitlines() if line.startswith("SigCgt:")), 16)
    return bool(caught >> (signal.SIGTERM - 1) & 1)


def start_run(tmp_path, *options, ignore_hup=False):
    out = tmp_path / "stopped.h5"
    command = [sys.executable, "-m", "microsim.cli", "run", str(RUN), "--paths", str(10**9), "--out", str(out), *options]

    def dispositions():
        """The run starts with default dispositions, whatever pytest inherited (a suite started
        by nohup or as a background job ignores SIGHUP, SIGINT and SIGQUIT); SIGHUP ignored as
        nohup does if asked."""
        for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT):
            signal.signal(signum, signal.SIG_DFL)
        if ignore_hup:
            signal.signal(signal.SIGHUP, signal.SIG_IGN)

    return subprocess.Popen(command, stderr=subprocess.PIPE, text=True, cwd=tmp_path, preexec_fn=dispositions), out


def wait_until(condition, seconds: float) -> bool:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.1)
    return condition()


@pytest.mark.parametrize("name", ["SIGINT", "SIGTERM", "SIGHUP", "SIGKILL"])
def test_a_signal_to_the_main_process_stops_every_worker(tmp_path, name):
    signum = getattr(signal, name)
    process, out = start_run(tmp_path, "--workers", "2")
    workers = []
    try:
        assert wait_until(lambda: handles_sigterm(process.pid) and len(children(process.pid)) >= 2, 120)
        workers = children(process.pid)
        time.sleep(1.0)  # tracing by now
        process.send_signal(signum)
        status = process.wait(timeout=15)
        assert wait_until(lambda: not any(running(pid) for pid in workers), 10), "a worker outlived the run"
        stderr = process.communicate(timeout=10)[1]  # EOF once no worker holds the pipe
    finally:
        for pid in [process.pid, *workers]:  # leave nothing running, whatever failed
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)
    assert not out.exists()
    # no unit of 10**9 / 32 paths ends in a second: nothing is kept but, after SIGKILL, the empty
    # unit store that no clean-up could remove (a later run takes it over: test_resume)
    left = [p.name for p in tmp_path.iterdir()]
    assert left == ([] if signum != signal.SIGKILL else ["stopped.h5.partial"]), "something was written"
    assert [p.name for p in tmp_path.glob("*.partial/*.npz")] == []
    assert status == -signum  # died of it: a shell reports 128 + signum
    if signum != signal.SIGKILL:
        assert stderr.splitlines() == [f"microsim: error: stopped by {name}; no table written"]


def test_a_run_on_threads_stops_on_sigterm(tmp_path):
    process, out = start_run(tmp_path, "--threads", "2")
    try:
        assert wait_until(lambda: handles_sigterm(process.pid), 120)
        time.sleep(1.0)
        process.send_signal(signal.SIGTERM)
        status = process.wait(timeout=15)
        stderr = process.communicate(timeout=10)[1]
    finally:
        process.kill()
    assert status == -signal.SIGTERM and stderr.splitlines() == ["microsim: error: stopped by SIGTERM; no table written"]
    assert list(tmp_path.iterdir()) == []


def test_a_signal_ignored_at_start_stays_ignored(tmp_path):
    """Under nohup a hangup must not stop the run."""
    process, out = start_run(tmp_path, "--threads", "2", ignore_hup=True)
    try:
        assert wait_until(lambda: handles_sigterm(process.pid), 120)
        process.send_signal(signal.SIGHUP)
        time.sleep(2.0)
        assert process.poll() is None, process.communicate()[1]
    finally:
        process.kill()


@pytest.mark.parametrize("name", ["SIGINT", "SIGTERM"])
def test_a_signal_once_the_table_is_written_leaves_a_finished_run_exiting_0(tmp_path, monkeypatch, capsys, name):
    """Issue 24, defect 8: SIGINT just after "table written to" made a finished run die of it."""
    import click

    from microsim import tables
    from microsim.cli import main

    real_echo = click.echo

    def echo_then_signal(message=None, *args, **kwargs):
        real_echo(message, *args, **kwargs)
        if str(message).startswith("table written to"):
            os.kill(os.getpid(), getattr(signal, name))
            time.sleep(0.1)  # the handler runs here, between bytecodes, if there is one

    def interrupted(signum, frame):  # in this process, a signal the command does not catch interrupts it
        raise KeyboardInterrupt

    monkeypatch.setattr(click, "echo", echo_then_signal)
    signum = getattr(signal, name)
    handler = signal.signal(signum, interrupted)
    try:
        out = tmp_path / "t.h5"
        assert main(["run", str(RUN), "--out", str(out), "--paths", "2000"]) == 0
        assert tables.load(out).arrays["albedo"].shape == (4,)
        assert signal.getsignal(signum) is interrupted  # the handlers are the caller's again
    finally:
        signal.signal(signum, handler)
