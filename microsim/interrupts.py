"""Where SIGINT goes: to the main thread of microsim's main process, and nowhere else.

A terminal sends Ctrl-C to its whole foreground process group, and the kernel hands a signal
sent to a process to any of its threads that does not block it. The main process alone decides
what a stop means (:mod:`microsim.cli`): its helper threads block SIGINT, and the processes of a
local Dask cluster ignore it (each of them printed a KeyboardInterrupt traceback: 67 lines).
"""

from __future__ import annotations

import contextlib
import signal
import threading


@contextlib.contextmanager
def blocked_in_new_threads():
    """Threads started within the block never take SIGINT (they inherit this thread's mask);
    a SIGINT that comes meanwhile waits, and reaches this thread when the block ends."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


@contextlib.contextmanager
def ignored_by_new_processes():
    """Processes started within the block ignore SIGINT for life; a SIGINT that comes meanwhile
    reaches this thread when the block ends.

    Being ignored is what a signal's disposition keeps through exec (multiprocessing's spawn
    clears the signal mask), and Python leaves an ignored SIGINT ignored: so SIGINT is ignored
    within the block. It is also blocked in this thread: Linux never discards a signal that the
    main thread blocks, whatever its disposition, and the threads started within the block
    inherit the mask; so the SIGINT stays pending until the block ends, unless a thread started
    before the block, without the mask, takes it (and, the signal being ignored, loses it)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    with blocked_in_new_threads():
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            yield
        finally:
            signal.signal(signal.SIGINT, previous)
