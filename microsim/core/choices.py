"""The names a user chooses among, one list each, and the ranges of the run options: the
command line's choices, the config schema, the session and the runner read them from here
(numbers and names only: ``--help`` imports no numba).
``tests/test_choices.py`` checks that the modules that implement them implement exactly these."""

#: how Embree is called (``run.backend``, ``--backend``): the modules of
#: microsim.tracer.integrators.surface.BACKENDS
BACKENDS = ("direct", "embreex")
#: ``run.backend`` and ``--backend`` accept these: "auto" is direct where its binding loads
BACKEND_CHOICES = ("auto", *BACKENDS)
#: where units are traced (``--executor``): the functions of microsim.run.runner.EXECUTORS
EXECUTORS = ("local", "dask")
#: processes a run may trace on (``--workers``)
MAX_WORKERS = 256
#: threads a process may run (``--threads``: Python threads, each tracing in a numba call without the GIL)
MAX_THREADS = 256
