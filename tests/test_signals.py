"""Stopping a run: a signal to the main process alone stops every worker, writes no table, says
so in one line and dies of the signal (as a shell expects); workers die with their parent even
when it is killed by SIGKILL; a signal ignored at start (nohup) stays ignored. Real
processes: the run is started with the CLI, signalled once it has installed its
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

from microsim.testing.interruptions import interrupt_group, wait_until

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


def tracing(out: Path) -> bool:
    """Whether the run of ``out`` traces: its unit store is open (just before the first unit;
    the CLI then stops on a signal cleanly, with its units kept)."""
    return Path(f"{out}.partial").is_dir()


def start_run(tmp_path, *options, ignore_hup=False):
    out = tmp_path / "stopped.h5"
    command = [sys.executable, "-m", "microsim", "run", str(RUN), "--paths", str(10**9), "--out", str(out), *options]

    def dispositions():
        """The run starts with default dispositions, whatever pytest inherited (a suite started
        by nohup or as a background job ignores SIGHUP, SIGINT and SIGQUIT); SIGHUP ignored as
        nohup does if asked."""
        for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT):
            signal.signal(signum, signal.SIG_DFL)
        if ignore_hup:
            signal.signal(signal.SIGHUP, signal.SIG_IGN)

    return subprocess.Popen(command, stderr=subprocess.PIPE, text=True, cwd=tmp_path, preexec_fn=dispositions), out


@pytest.mark.parametrize("name", ["SIGINT", "SIGTERM", "SIGHUP", "SIGKILL"])
def test_a_signal_to_the_main_process_stops_every_worker(tmp_path, name):
    signum = getattr(signal, name)
    process, out = start_run(tmp_path, "--workers", "2")
    workers = []
    try:
        assert wait_until(lambda: tracing(out) and len(children(process.pid)) >= 2, 120)
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
        assert wait_until(lambda: tracing(out), 120)
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
        assert wait_until(lambda: tracing(out), 120)
        process.send_signal(signal.SIGHUP)
        time.sleep(2.0)
        assert process.poll() is None, process.communicate()[1]
    finally:
        process.kill()


@pytest.mark.parametrize("name", ["SIGINT", "SIGTERM"])
def test_a_signal_once_the_table_is_written_leaves_a_finished_run_exiting_0(tmp_path, monkeypatch, capsys, name):
    """A signal just after "table written to" leaves the finished run to exit 0."""
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


def after(seconds: float):
    start = time.monotonic()
    return lambda process: time.monotonic() - start >= seconds


@pytest.mark.parametrize("moment", ["importing", "cluster starting", "tracing"])
def test_ctrl_c_to_a_dask_run_s_process_group_is_one_line_whenever_it_comes(tmp_path, moment):
    """Ctrl-C to the process group of a Dask run ends it in one line whenever it comes: no
    KeyboardInterrupt traceback of a Dask worker, nor, during the imports, of the main process."""
    pytest.importorskip("distributed")
    out = tmp_path / "stopped.h5"
    command = [sys.executable, "-m", "microsim", "run", str(RUN), "--paths", str(10**9), "--out", str(out),
               "--executor", "dask", "--workers", "2"]
    when = {"importing": after(0.3),
            "cluster starting": lambda process: len(children(process.pid)) >= 1,
            "tracing": lambda process: tracing(out) and after_tracing(out, 2.0)}[moment]
    status, stderr = interrupt_group(command, tmp_path, when)
    assert status == -signal.SIGINT
    assert len(stderr.splitlines()) == 1 and stderr.startswith("microsim: error: stopped by SIGINT"), stderr
    assert not out.exists()


def after_tracing(out: Path, seconds: float) -> bool:
    """Whether the run of ``out`` has traced for ``seconds`` (its unit store is that old)."""
    return time.time() - Path(f"{out}.partial").stat().st_mtime >= seconds


def test_ctrl_c_while_a_command_imports_is_one_line(tmp_path):
    command = [sys.executable, "-m", "microsim", "compare", str(tmp_path / "absent.h5"), "--model", "lambert"]
    status, stderr = interrupt_group(command, tmp_path, after(0.15))
    assert (status, stderr) == (-signal.SIGINT, "microsim: error: stopped by SIGINT\n")


def test_main_gives_the_caller_s_handlers_back_whatever_ends_it(tmp_path, monkeypatch, capsys):
    """main() replaces the default handlers of the stop signals with its own (one line, then the
    process dies of the signal); an exception it does not report (a model's own error) must not
    leave them behind in the caller's process."""
    from microsim import cli

    def broken(path):
        raise RuntimeError("a bug")

    monkeypatch.setattr("microsim.cli.analysis.load_table", broken)
    defaults = {signal.SIGINT: signal.default_int_handler, signal.SIGTERM: signal.SIG_DFL, signal.SIGHUP: signal.SIG_DFL}
    previous = {signum: signal.signal(signum, handler) for signum, handler in defaults.items()}
    try:
        with pytest.raises(RuntimeError, match="a bug"):
            cli.main(["compare", str(tmp_path / "t.h5"), "--model", "lambert", "--param", "albedo=0.5"])
        assert {signum: signal.getsignal(signum) for signum in defaults} == defaults
        assert cli.main(["models"]) == 0
        assert {signum: signal.getsignal(signum) for signum in defaults} == defaults
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
