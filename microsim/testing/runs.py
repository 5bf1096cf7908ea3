"""The entry points through which tests and benchmarks trace a config in memory.

Contract: :func:`trace` (one albedo) and :func:`trace_albedos` (one or several) take a config
(validated, or a dictionary as a TOML config parses, validated here) and return the run's
``Result`` objects (estimates, energy, counts; no table written), as the run of ``microsim run``
with the same options would compute them; :func:`trace_realizations` returns the plan and
every realization's estimates instead of their mean. Each makes one
:class:`microsim.run.runner.Run`, as the session does, without its files: tests and benchmarks
call these, never the runner itself, so that the runner may change shape behind them. A run
that cannot be traced raises ``microsim.run.plan.PlanError`` (one line).
"""

from __future__ import annotations

from microsim.run.plan import PlanError, albedos_of
from microsim.run.runner import Run


def validated(config):
    """``config`` validated (a dictionary as a TOML config parses), or as it is."""
    if isinstance(config, dict):
        from microsim.config import validate

        return validate(config)
    return config


def trace(config, workers: int = 1, threads: int = 1, **options):
    """The Result of a config of one albedo on ``workers`` processes of ``threads`` threads;
    ``options``: ``progress``, ``executor``, ``scheduler``, ``store`` (a unit store: its units
    are taken, the others traced and kept)."""
    config = validated(config)
    if albedos := albedos_of(config):
        raise PlanError(f"material.albedo = {list(albedos)}: several albedos make several tables (trace_albedos)")
    return trace_albedos(config, workers, threads, **options)[0]


def trace_albedos(config, workers: int = 1, threads: int = 1, progress=None, executor: str = "local",
                  scheduler: str | None = None, store=None) -> list:
    """One Result per albedo of a config of one albedo or several (conventions §4), in the order
    of ``material.albedo``, from one set of paths; the run's memory checked where it traces on
    this machine; ``options`` as :func:`trace`'s."""
    run = Run.of(validated(config), threads, workers)
    if scheduler is None:  # on this machine (a cluster's workers are elsewhere)
        run.check_memory(workers, spawned=executor == "dask")
    return run.trace(workers, progress, executor, scheduler, store)


def trace_realizations(config, workers: int = 1) -> tuple:
    """(plan, {estimate name: array (realizations, incidences, ...)}) of a config of one albedo,
    traced on the local executor: every realization's estimates, for statistics a table's mean
    and standard error do not give."""
    run = Run.of(validated(config), workers=workers)
    return run.plan, run.trace_realizations(workers)
