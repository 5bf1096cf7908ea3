"""Stop signals: what SIGINT, SIGTERM and SIGHUP do to a run, and where they go.

While a run traces, the first stop signal raises :class:`Stopped` in the main thread (the
runner's clean-up then kills its workers) and later ones are ignored while it stops; once
tracing is over and the tables are being written, a signal is only noted, and raises when they
are written (:class:`StopOnSignals`). A signal that was ignored when microsim started (nohup, a
background job) stays ignored; outside the main thread nothing changes.

A terminal sends Ctrl-C to its whole foreground process group, and the kernel hands a signal
sent to a process to any of its threads that does not block it. The main process alone decides
what a stop means: its helper threads block SIGINT, and the processes of a local Dask cluster
ignore it (:mod:`microsim.tracer.jit.forkserver_preload`; each of them printed a KeyboardInterrupt
traceback: 67 lines).
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading

#: signals that stop a run cleanly (its workers killed, no table written)
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class Stopped(Exception):
    """A run stopped by a signal; ``exit_code`` is 128 + its number, as a shell reports it."""

    def __init__(self, signum: int, message: str = "stopped by {name}; no table written"):
        self.signum = signum
        self.exit_code = 128 + signum
        self.message = message.format(name=signal.Signals(signum).name)
        super().__init__(self.message)

    def __str__(self) -> str:
        return self.message

    def add_kept(self, text: str) -> None:
        """Append ``text`` (what was kept for a resume) to the one line."""
        self.message += text


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


class StopOnSignals:
    """Within ``with StopOnSignals() as guard:``, the first stop signal raises :class:`Stopped`
    (in the main thread, between bytecodes); later ones are ignored while it stops. Within
    ``with guard.hold():`` (writing the tables once tracing is over) a signal is only noted, and
    raises :class:`Stopped` when the block ends, saying the work was done.

    ``once_done``: if the block ends without an error, the stop signals are handed to it
    (:class:`IgnoredOnceDone`) instead of being restored: the work is done, and a signal until
    the caller has reported it must not turn a finished run into a failed one."""

    def __init__(self, once_done: "IgnoredOnceDone | None" = None):
        self.once_done = once_done
        self.stopping: list[int] = []
        self.holding = 0
        self.previous: dict = {}

    def _stop(self, signum, frame):
        if not self.stopping:
            self.stopping.append(signum)
            if not self.holding:
                raise Stopped(signum)

    def __enter__(self) -> "StopOnSignals":
        if _main_thread():
            self.previous = {signum: signal.getsignal(signum) for signum in STOP_SIGNALS}
            for signum, handler in self.previous.items():
                if handler is not signal.SIG_IGN:
                    signal.signal(signum, self._stop)
        return self

    @contextlib.contextmanager
    def hold(self):
        """Within the block a stop signal is only noted; it raises when the block ends."""
        self.holding += 1
        try:
            yield
        finally:
            self.holding -= 1
        if self.stopping:
            raise Stopped(self.stopping[0], "stopped by {name} once its tables were written")

    def __exit__(self, kind, error, trace) -> bool:
        if kind is None and self.once_done is not None:
            self.once_done.take(self.previous)
        else:
            restore(self.previous)
        return False


class IgnoredOnceDone:
    """``with IgnoredOnceDone() as done:`` around a run and its report: from the moment a
    :class:`StopOnSignals` given ``done`` ends cleanly, stop signals are ignored until this block
    ends, and then the handlers it replaced are back."""

    def __init__(self):
        self.saved: dict = {}

    def take(self, handlers: dict) -> None:
        """Ignore the stop signals whose handlers are ``handlers``; restore those on exit (the
        first handlers given for a signal, when several runs hand theirs over)."""
        for signum, handler in handlers.items():
            self.saved.setdefault(signum, handler)
            signal.signal(signum, signal.SIG_IGN)

    def __enter__(self) -> "IgnoredOnceDone":
        return self

    def __exit__(self, *exc) -> bool:
        restore(self.saved)
        self.saved = {}
        return False


def restore(handlers: dict) -> None:
    """Put back signal handlers by signal (those :func:`die_on_stop_signals` replaced)."""
    for signum, handler in handlers.items():
        signal.signal(signum, handler)


def die_on_stop_signals() -> dict:
    """Have each stop signal that is in its default disposition (Python's KeyboardInterrupt for
    SIGINT) print one line and end the process; returns the handlers replaced (give them to
    :func:`restore`). Nothing outside the main thread, and nothing for a signal that is ignored
    or that a caller handles. For the time a command does no run: there is nothing to clean up,
    and an exception raised from a handler could be swallowed (by a ctypes callback of numba's
    compiler, seen to let a run go on to its end)."""
    if not _main_thread():
        return {}
    defaults = {signal.SIGINT: signal.default_int_handler, signal.SIGTERM: signal.SIG_DFL,
                signal.SIGHUP: signal.SIG_DFL}
    installed = {}
    for signum, default in defaults.items():
        if signal.getsignal(signum) is default:
            installed[signum] = signal.signal(signum, _stop_now)
    return installed


#: temporary files to remove before a stop signal ends the process at once (:func:`remove_on_stop`)
_PENDING: set = set()


@contextlib.contextmanager
def remove_on_stop():
    """``with remove_on_stop() as made:``, ``path = made(create)`` calls ``create()`` (which makes
    a file and returns its path) with the stop signals held, so that no signal falls between the
    file's making and its noting; until the block ends, a stop signal that ends the process at
    once (:func:`die_on_stop_signals`) removes the file first. (One that raises, as
    :class:`StopOnSignals` does, unwinds to the caller's own clean-up.)"""
    noted = []

    def made(create):
        held = signal.pthread_sigmask(signal.SIG_BLOCK, set(STOP_SIGNALS)) if _main_thread() else None
        try:
            path = create()
            noted.append(path)
            _PENDING.add(path)
        finally:
            if held is not None:
                signal.pthread_sigmask(signal.SIG_SETMASK, held)
        return path

    try:
        yield made
    finally:
        _PENDING.difference_update(noted)


def _stop_now(signum, frame):
    for path in list(_PENDING):
        with contextlib.suppress(OSError):
            os.unlink(path)
    if sys.stderr.isatty():  # a progress line may be drawn: clear it, and show the cursor it hid
        sys.stderr.write("\r\x1b[2K\x1b[?25h")
    sys.stderr.write(f"microsim: error: stopped by {signal.Signals(signum).name}\n")
    die_of(signum)


def die_of(signum: int) -> None:
    """End this process by ``signum`` with its default action, as a shell expects of a process
    that was stopped (status 128 + signum; a shell loop stops on Ctrl-C); nothing outside the
    main thread (a caller that runs microsim in a thread of its own keeps its process)."""
    if _main_thread():
        sys.stderr.flush()
        signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)


@contextlib.contextmanager
def blocked_in_new_threads():
    """Threads started within the block never take SIGINT (they inherit this thread's mask);
    a SIGINT that comes meanwhile waits, and reaches this thread when the block ends."""
    if not _main_thread():
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)

