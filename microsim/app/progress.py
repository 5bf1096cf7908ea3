"""What a run tells as it goes: the hooks a session calls, the command line's progress bar, and
the status line of a fit.

:func:`microsim.app.session.run` calls a :class:`Progress` (every hook does nothing here: subclass
the ones you need) as each run (each point of a sweep) starts, while numba compiles its tracer,
as tracing begins and as each unit (realization x incidence) ends. :class:`ProgressBar` is the
command line's: a rich progress line on a terminal, nothing elsewhere.
"""

from __future__ import annotations

import contextlib
import sys
import time


class Progress:
    """The hooks of a run's progress; every one does nothing unless a subclass says otherwise."""

    def start(self, plan, compile_seconds: float) -> None:
        """A run of ``plan`` starts; compiling its tracer, if needed, takes about
        ``compile_seconds`` here (the tracer class's ``COMPILE_SECONDS``)."""

    def note(self, text: str) -> None:
        """Before the run: something its user should know now (why it will be slow)."""

    def compiling(self) -> None:
        """numba began compiling (called from the thread that compiles)."""

    def tracing(self, watch) -> None:
        """Tracing begins; ``watch.seconds`` is the time numba has spent compiling since the
        start (:class:`microsim.tracer.jit.compile_watch.CompileWatch`), not the run's time."""

    def unit(self, unit: tuple[int, int], paths: int, from_store: bool) -> None:
        """Unit ``unit`` = (realization, incidence) of ``paths`` paths ended, or was taken from
        the unit store of an interrupted run (``from_store``; those come first)."""

    def stop(self) -> None:
        """The run ended (or failed, or was stopped)."""


class ProgressBar(Progress):
    """A rich progress line on a terminal (stderr), nothing otherwise.

    While numba compiles the tracer it says so, with the time that takes here; then it counts
    units and paths per incidence, as ``--paths`` does. Its time left is the mean rate of the
    units traced since the first one ended, without the seconds spent compiling, applied to what
    is left: the first unit carries the start (forking workers, building their first scenes),
    which would make the first estimates several times the true time left
    (docs/developer/performance.md, 'The time left and the figures'); a mean rate is steadier
    than a recent one when units end in bursts, as they do with workers. Units taken from a
    resumed run's store count as done, not in the rate."""

    def __init__(self):
        self.bar = None

    def start(self, plan, compile_seconds: float) -> None:
        self.plan, self.compile_seconds = plan, compile_seconds
        self.task = self.watch = self.first = None
        self.done = self.traced = 0
        if sys.stderr.isatty():
            from rich.console import Console
            from rich.progress import BarColumn, TextColumn
            from rich.progress import Progress as RichProgress

            from microsim.core.interrupts import blocked_in_new_threads

            self.bar = RichProgress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.fields[status]}"),
                                    console=Console(stderr=True), transient=True)
            with blocked_in_new_threads():  # its refresh thread
                self.bar.start()
            units = len(plan.units)
            self.task = self.bar.add_task("tracing", total=units, status=f"0/{units} units")

    def note(self, text: str) -> None:
        sys.stderr.write(f"note: {text}\n")

    def compiling(self) -> None:
        if self.bar is not None:
            self.bar.update(self.task, description="compiling",
                            status=f"the tracer, for this machine (once; about {self.compile_seconds:.0f} s)")

    def tracing(self, watch) -> None:
        self.watch = watch
        if self.bar is not None:
            self.bar.update(self.task, description="tracing", status=f"0/{len(self.plan.units)} units")

    def unit(self, unit, paths, from_store) -> None:
        now, compiled = time.monotonic(), self.watch.seconds
        self.done += 1
        self.traced += not from_store
        if not from_store and self.first is None:
            self.first = (now, compiled)  # the first traced unit: the rate counts from here
        if self.bar is None:
            return
        units, plan = len(self.plan.units), self.plan
        elapsed = (now - self.first[0]) - (compiled - self.first[1]) if self.first else 0.0
        rate_units = self.traced - 1
        left = f"{elapsed * (units - self.done) / rate_units:.0f} s left" if rate_units > 0 else "starting"
        per_incidence = self.done * plan.paths_per_realization // plan.n_incidences
        self.bar.update(self.task, advance=1, description="tracing",
                        status=f"{self.done}/{units} units, {per_incidence:,} of {plan.paths:,} paths per "
                               f"incidence, {left}")

    def stop(self) -> None:
        if self.bar is not None:
            self.bar.stop()
            self.bar = None


@contextlib.contextmanager
def fit_status(name: str):
    """On a terminal, a status line that follows a fit (its evaluations, the parameters it tries,
    the time so far); yields the fit's ``progress`` callback (None elsewhere)."""
    if not sys.stderr.isatty():
        yield None
        return
    from rich.console import Console

    from microsim.core.interrupts import blocked_in_new_threads

    start = time.monotonic()
    with blocked_in_new_threads():  # the status line's refresh thread
        status = Console(stderr=True).status(f"fitting {name}")
        status.start()

    def progress(evaluations, values):
        tried = ", ".join(f"{key} = {value:.5g}" for key, value in values.items())
        status.update(f"fitting {name}: {evaluations} evaluations, at {tried} ({time.monotonic() - start:.0f} s)")

    try:
        yield progress
    finally:
        status.stop()
