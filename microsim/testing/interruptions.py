"""Runs in processes of their own, stopped and killed as a user, a shell or the system would.

Contract: ``RUN`` is a run of ``UNITS`` units, each long enough (2 560 000 paths an incidence
over 16 realizations) that a test can stop it between units; :func:`start` starts ``microsim
run`` on a config in a new process; :func:`saved` counts the units its store kept so far;
:func:`wait_for_units` waits for that many (failing if the run ends first or keeps none);
:func:`kill_at_half` SIGKILLs it once half are kept; :func:`interrupt_group` sends Ctrl-C's
SIGINT to a command's whole process group once a condition holds (:func:`wait_until`) and
returns its status and stderr. Every process started is killed on the way out.
"""

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from microsim.run import unit_store
from microsim.testing.configs import SPHERES

#: the small spheres of microsim.testing.configs, with units long enough to be stopped between
RUN = SPHERES.replace('name = "small"', 'name = "resumable"').replace("paths = 20_000", "paths = 2_560_000") \
    .replace("realizations = 4", "realizations = 16")
assert "paths = 2_560_000" in RUN and "realizations = 16" in RUN
UNITS = 32  # 16 realizations x 2 incidences


def saved(out: Path) -> int:
    """Finished units in the store of the run writing ``out``."""
    return len(list(unit_store.store_path(out).glob("r*_i*.npz")))


def start(config: Path, out: Path, *flags) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "microsim", "run", str(config), "--out", str(out), *flags],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def wait_for_units(process, out: Path, count: int, seconds: float = 120) -> None:
    end = time.monotonic() + seconds
    while saved(out) < count:
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < end, "the run kept no unit"
        time.sleep(0.01)


def kill_at_half(process, out: Path) -> None:
    """SIGKILL the run writing ``out`` once it kept half its units; its workers die with it
    (PR_SET_PDEATHSIG), so nothing more is saved."""
    try:
        wait_for_units(process, out, UNITS // 2)
        process.send_signal(signal.SIGKILL)
        assert process.wait(timeout=10) == -signal.SIGKILL
    finally:
        process.kill()
    assert not out.exists()
    time.sleep(0.5)


def wait_until(condition, seconds: float) -> bool:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.1)
    return condition()


def interrupt_group(command: list[str], cwd: Path, when) -> tuple[int, str]:
    """Start ``command`` as a terminal's foreground job (a process group of its own, default
    dispositions), send SIGINT to the whole group as Ctrl-C does once ``when(process)`` holds,
    and return its status and stderr. Whatever is left of the group is killed."""
    def dispositions():
        for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            signal.signal(signum, signal.SIG_DFL)

    process = subprocess.Popen(command, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, cwd=cwd,
                               start_new_session=True, preexec_fn=dispositions)
    try:
        assert wait_until(lambda: when(process), 120), "the moment to interrupt never came"
        os.killpg(process.pid, signal.SIGINT)
        status = process.wait(timeout=60)
        return status, process.communicate(timeout=30)[1]
    finally:
        with contextlib.suppress(OSError):
            os.killpg(process.pid, signal.SIGKILL)
