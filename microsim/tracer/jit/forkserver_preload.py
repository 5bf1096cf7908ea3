"""Imported first by multiprocessing's fork server as it starts: SIGINT ignored there, and so
in every process it forks, the workers of a local Dask cluster (:func:`microsim.run.executors.dask`).

The server starts with SIGINT blocked (:func:`microsim.run.executors._start_fork_server`), so that a
Ctrl-C before this import waits; ignoring SIGINT discards it, and only then is it unblocked.
The server gives each child the disposition it had once its preload modules were imported. A
terminal's Ctrl-C goes to the whole process group, and every worker printed a
KeyboardInterrupt traceback (67 lines); the main process alone decides, and closes the cluster.
"""

import signal

signal.signal(signal.SIGINT, signal.SIG_IGN)
signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
