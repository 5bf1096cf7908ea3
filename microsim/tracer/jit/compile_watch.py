"""The time numba spends compiling in this process, told as it starts and ends.

A first run on a new machine (or after any edit of microsim's sources, :mod:`kernel_cache`)
compiles its tracer's kernel before it traces (for seconds: each tracer's ``COMPILE_SECONDS``),
during which no unit ends. The command
line says so while it happens, and keeps that time out of the time left and out of paths/s. A
kernel loaded from numba's disk cache is not a compile and is not counted.
"""

from __future__ import annotations

import threading
import time


class CompileWatch:
    """Within ``with CompileWatch(on_start) as watch:``, ``watch.seconds`` is the wall time
    numba has spent compiling in this process (including a compile under way), and
    ``on_start()`` is called as each outermost compile begins (a kernel's callees compile
    within it). Thread-safe: kernels may first be called from tracing threads."""

    def __init__(self, on_start=None):
        self.on_start = on_start
        self._done = 0.0
        self._depth = 0
        self._since = 0.0
        self._lock = threading.Lock()
        self._listener = None

    @property
    def seconds(self) -> float:
        with self._lock:
            return self._done + (time.monotonic() - self._since if self._depth else 0.0)

    @property
    def compiling(self) -> bool:
        return self._depth > 0

    def __enter__(self) -> "CompileWatch":
        from numba.core import event

        watch = self

        class Listener(event.Listener):
            def on_start(self, ev):
                with watch._lock:
                    watch._depth += 1
                    first = watch._depth == 1
                    if first:
                        watch._since = time.monotonic()
                if first and watch.on_start is not None:
                    watch.on_start()

            def on_end(self, ev):
                with watch._lock:
                    watch._depth -= 1
                    if watch._depth == 0:
                        watch._done += time.monotonic() - watch._since

        self._listener = Listener()
        event.register("numba:compile", self._listener)
        return self

    def __exit__(self, *exc) -> bool:
        from numba.core import event

        event.unregister("numba:compile", self._listener)
        return False
