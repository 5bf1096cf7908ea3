"""Run a config from Python with every guarantee of ``microsim run``.

:func:`run` reads a config (a TOML file, or its data as a dictionary), plans it once, checks
its memory once before any store is touched, traces it and writes its table (one per albedo
of an albedo list), or, for a config with ``[sweep]``, one table per point and the sweep's
``index.csv``. Finished units are kept in ``<table>.partial`` until the table is written, so a
run killed at any moment resumes with ``resume=True`` into a table bit-identical to an
uninterrupted one (:mod:`microsim.run.unit_store`). While it traces in the main thread, a stop
signal (SIGINT, SIGTERM, SIGHUP) stops the run and its workers and raises
:class:`~microsim.core.interrupts.Stopped`, whose one line says what was kept
(:mod:`microsim.core.interrupts`). Progress goes to a :class:`~microsim.app.progress.Progress`.

Errors are one line each: :class:`RunRefused` for input that cannot be traced (the command
line's exit status 2: nothing traced, nothing lost or overwritten), :class:`RunFailed` for a
run that could not finish (exit 1: what was kept is said), :class:`Stopped` for a signal.
``microsim run`` is this module's :func:`run` with its output printed (:mod:`microsim.cli`).
"""

from __future__ import annotations

import copy
import os
import re
import shutil
from dataclasses import dataclass
from pathlib import Path

from microsim.app.outcomes import PointOutcome, RunOutcome, SweepOutcome
from microsim.app.progress import Progress
from microsim.core import files
from microsim.core.choices import EXECUTORS, MAX_THREADS, MAX_WORKERS
from microsim.core.interrupts import IgnoredOnceDone, StopOnSignals, Stopped
from microsim.core.orders import RESULT_ALL_ORDERS

__all__ = ["run", "Options", "RunOutcome", "PointOutcome", "SweepOutcome", "RunRefused", "RunFailed", "Stopped",
           "IgnoredOnceDone"]

#: the options of :func:`run` that override the config's ``run.*`` keys
OVERRIDES = ("paths", "seed", "backend")
#: what a Dask scheduler's address looks like: [tcp|tls|ws|wss://]host:port
SCHEDULER_ADDRESS = re.compile(r"^((tcp|tls|ws|wss)://)?(?P<host>[A-Za-z0-9._\-\[\]:]+):(?P<port>\d{1,5})$")


class RunRefused(ValueError):
    """Input that cannot be traced: one line naming the key or option and what is accepted.
    Refused before anything is traced and before any table or kept unit is touched, but for
    what shows only while tracing (a Dask scheduler that cannot be reached, a table's name taken
    meanwhile: the line then says what was kept)."""


class RunFailed(RuntimeError):
    """A run that could not finish (a worker died, the disk is full, Embree cannot load): one
    line, ending with what was kept for ``resume=True``."""


@dataclass(frozen=True)
class Options:
    """How a run traces: the options shared by a run and every point of a sweep (the flags of
    ``microsim run`` of the same names)."""

    workers: int = 1
    threads: int = 1
    force: bool = False
    resume: bool = False
    executor: str = "local"
    scheduler: str | None = None

    def check(self) -> None:
        """RunRefused (one line) for an option out of its range."""
        for name, value, top in (("workers", self.workers, MAX_WORKERS), ("threads", self.threads, MAX_THREADS)):
            if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= top:
                raise RunRefused(f"--{name} {value!r}: expected an integer in [1, {top}]")
        if self.executor not in EXECUTORS:
            raise RunRefused(f"--executor {self.executor!r}: accepted: {', '.join(EXECUTORS)}")
        if self.scheduler is not None and not isinstance(self.scheduler, str):
            raise RunRefused(f"--scheduler {self.scheduler!r}: expected an address as text, e.g. tcp://10.0.0.5:8786")
        if self.scheduler is not None and self.executor != "dask":
            raise RunRefused("--scheduler: a Dask scheduler's address is taken with --executor dask only")
        if self.executor == "dask":
            _check_dask(self.scheduler)

    def where(self, plan) -> str:
        """Where the run traced, for its report."""
        if self.executor == "dask":
            return (f"dask at {self.scheduler}" if self.scheduler else
                    f"dask LocalCluster of {self.workers} worker(s)") + f" x {plan.threads} thread(s)"
        return f"{self.workers} worker(s) x {plan.threads} thread(s)"


def run(config, out=None, *, progress: Progress | None = None, on_point=None, once_done: IgnoredOnceDone | None = None,
        **options) -> RunOutcome | SweepOutcome:
    """Trace ``config`` and write its tables, as ``microsim run`` does.

    ``config``: a TOML file's path, or the config as a dictionary (as the TOML parses).
    ``out``: the table [default: ``<config file stem>.h5`` in the current directory]; for a
    config with ``[sweep]``, the directory of its tables [default: ``<config file stem>``]; a
    config given as a dictionary needs it. ``options`` are the flags of ``microsim run`` by
    name (None: not given): ``paths``, ``seed``, ``backend`` override ``run.*``; ``workers``
    processes of ``threads`` threads trace on the ``executor`` ("local" or "dask"; ``scheduler``:
    a Dask scheduler's address); ``force`` overwrites existing tables (and, without ``resume``,
    discards kept units); ``resume`` continues an interrupted run or sweep.
    ``progress`` hears of every step (:class:`~microsim.app.progress.Progress`; the command line's
    bar is :class:`~microsim.app.progress.ProgressBar`); ``on_point(PointOutcome)`` is called as each
    point of a sweep ends. ``once_done``: stop signals are ignored from the moment the last
    table is written until that block ends (the command line's report).

    Returns a :class:`RunOutcome` (a config without ``[sweep]``) or a :class:`SweepOutcome`.
    Raises :class:`RunRefused`, :class:`RunFailed` or :class:`Stopped` (one line each)."""
    from microsim import config as config_module
    from microsim.app import sweep

    unknown = sorted(set(options) - set(OVERRIDES) - set(Options.__dataclass_fields__))
    if unknown:
        raise RunRefused(f"{unknown[0]}: not an option of a run; accepted: "
                         f"{', '.join((*OVERRIDES, *Options.__dataclass_fields__))}")
    given = {key: value for key, value in options.items() if value is not None}
    overrides = {f"run.{key}": given.pop(key) for key in OVERRIDES if key in given}
    options = Options(**given)
    config_path = Path(config) if isinstance(config, (str, os.PathLike)) else None
    try:
        if config_path is not None:
            data = config_module.read(config_path, overrides)
        elif isinstance(config, dict):
            data = copy.deepcopy(config)
            for key, value in overrides.items():
                config_module.set_dotted(data, key, value)
        else:
            raise RunRefused(f"config: expected a TOML file's path or a dictionary, got {type(config).__name__}")
        points = sweep.points(data)
        validated = config_module.validate(data) if points is None else None
    except config_module.ConfigError as err:
        raise RunRefused(str(err)) from None
    options.check()
    if out is None and config_path is None:
        raise RunRefused("out: a config given as a dictionary needs the path of its table (or sweep directory)")
    progress = progress if progress is not None else Progress()
    if points is not None:
        directory = Path(out) if out is not None else Path(config_path.stem)
        return _run_sweep(points, directory, options, config_path, progress, on_point, once_done)
    out = Path(out) if out is not None else Path(f"{config_path.stem}.h5")
    if out.is_dir():
        raise RunRefused(f"--out: {out} is a directory; a config without [sweep] writes one table")
    run = _plan(validated, options)
    # a run of several albedos writes one table each, named from out with the albedo appended
    outs = [out.with_name(f"{out.stem}_albedo{albedo_text(c)}{out.suffix}") for c in run.plan.albedos] or [out]
    for path in outs:
        _refuse_input(path, config_path)
        _check_writable(path, options.force)
    _check_memory(run, options)
    store = _check_store(out, run, options)
    from microsim.geometry.periodic_tile import steepness_note

    if note := steepness_note(run.plan.scene):
        progress.note(note)
    return _trace(validated, run, outs, store, options, progress, once_done=once_done)


def albedo_text(albedo: float) -> str:
    """The albedo in a table's name: its shortest %g form where that reads back as the same number,
    else all its digits, so that distinct albedos name distinct tables (0.1 and 0.1000001)."""
    short = f"{albedo:g}"
    return short if float(short) == albedo else repr(float(albedo))


def _plan(config, options: Options, label: str = ""):
    """The run of a validated config, planned once (:class:`microsim.run.runner.Run`)."""
    from microsim.run import runner
    from microsim.run.plan import PlanError

    try:
        return runner.Run.of(config, options.threads, options.workers)
    except PlanError as err:
        raise RunRefused(f"{label}{err}") from None


def _check_memory(run, options: Options, label: str = "") -> None:
    """The one memory check of a run, on this machine (a cluster's workers are elsewhere)."""
    from microsim.run.plan import PlanError

    if options.scheduler is not None:
        return
    try:
        run.check_memory(options.workers, spawned=options.executor == "dask")
    except PlanError as err:
        raise RunRefused(f"{label}{err}") from None


def _check_store(table: Path, run, options: Options, label: str = ""):
    """The unit store of the run writing ``table``, checked once, before anything is compiled or
    traced (:meth:`microsim.run.unit_store.UnitStore.check`; :func:`_trace` takes it)."""
    from microsim.run import unit_store

    try:
        return unit_store.UnitStore.check(unit_store.store_path(table), run.plan, options.resume, options.force)
    except unit_store.StoreMismatch as err:
        raise RunRefused(f"{label}{err}") from None


def _run_sweep(points, out_dir: Path, options: Options, config_path: Path | None, progress: Progress, on_point,
               once_done) -> SweepOutcome:
    """Trace every point of a sweep into ``out_dir``: one table per point, named from its values,
    and ``index.csv`` (rewritten as each point ends: values, table, status, albedo per incidence).
    With resume, a point whose table is there (made from the same config) is kept as it is, and
    the point that was interrupted resumes from its units. Every point is planned and checked
    before anything is traced."""
    from microsim.app import sweep
    from microsim.run import unit_store

    for point in points:
        _refuse_input(out_dir / f"{point.name}.h5", config_path)
    if out_dir.exists() and not out_dir.is_dir():
        raise RunRefused(f"--out: {out_dir} is a file; a sweep writes its tables into a directory")
    if out_dir.is_dir() and any(out_dir.iterdir()) and not (options.force or options.resume):
        raise RunRefused(f"--out: directory {out_dir} is not empty; pass --resume to continue the sweep in it, or "
                         "--force to overwrite its tables")
    if why := files.refusal(out_dir, directory=True):
        raise RunRefused(why)
    runs, stores, kept = [], [], []
    for point in points:  # every refusal before anything is traced
        label = f"sweep point {point.name}: "
        path = out_dir / f"{point.name}.h5"
        run = _plan(point.config, options, label)
        kept.append(_finished_table(path, point) if options.resume else None)
        if kept[-1] is None:
            _check_memory(run, options, label)
        stores.append(_check_store(path, run, options, label) if kept[-1] is None else None)
        runs.append(run)
    out_dir.mkdir(parents=True, exist_ok=True)
    keys = list(points[0].values)
    rows = [{"point": p.name, **{k: p.values[k] for k in keys}, "table": f"{p.name}.h5", "status": "pending"}
            for p in points]
    for row, run, table in zip(rows, runs, kept):
        if table is not None:
            sweep.index_albedos(row, run.plan.theta_i, table.arrays["albedo"])
    sweep.write_index(out_dir, rows)
    outcome = SweepOutcome(out_dir)
    last_traced = max((n for n, table in enumerate(kept) if table is None), default=None)
    for n, (row, point, run, store, table) in enumerate(zip(rows, points, runs, stores, kept)):
        path = out_dir / row["table"]
        if table is not None:
            unit_store.UnitStore(unit_store.store_path(path), {}).clear()  # outlived its table
            done = PointOutcome(point, path, list(table.arrays["albedo"]))
        else:
            _check_writable(path, options.force)
            traced = _trace(point.config, run, [path], store, options, progress,
                            label=f"sweep point {point.name}: ", once_done=once_done if n == last_traced else None)
            result = traced.results[0]
            done = PointOutcome(point, path, [a.mean[RESULT_ALL_ORDERS] for a in result.albedo],
                                traced.albedo_summary(result), result.wall_time)
            sweep.index_albedos(row, run.plan.theta_i, done.albedo)
            sweep.write_index(out_dir, rows)
        outcome.points.append(done)
        if on_point is not None:
            on_point(done)
    return outcome


def _finished_table(path: Path, point):
    """A sweep point's table if it is there and was made from the point's config, None if it is
    not there; RunRefused if a table of another config holds its name."""
    from microsim import tables

    if not path.exists():
        return None
    try:
        table = tables.load(path)
    except (OSError, tables.TableError):
        table = None
    if table is None or table.attrs.get("config_toml") != tables.config_to_toml(point.config):
        raise RunRefused(f"--resume: {path} is not the table of sweep point {point.name} (another config, or "
                         "damaged); pass --force to overwrite it")
    return table


def _trace(config, run, outs, store, options: Options, progress: Progress, label: str = "",
           once_done=None) -> RunOutcome:
    """Trace a planned and checked run (its memory, its tables' names, its unit ``store``) and
    write its tables (one per albedo) to ``outs``; finished units are kept in the store until the
    tables are written. A failure or a signal says in its one line how many units were kept for
    resume; a refusal keeps them all.

    The tracer is compiled before the store is taken: a refusal costs no unit, and a signal while
    numba compiles ends the run with nothing to clean up."""
    from microsim import tables
    from microsim.run import executors, unit_store
    from microsim.run.plan import PlanError
    from microsim.tracer import embree
    from microsim.tracer.jit.compile_watch import CompileWatch

    plan = run.plan
    kept = store.saved_units()
    progress.start(plan, plan.tracer_class.COMPILE_SECONDS[plan.backend])
    try:
        with CompileWatch(progress.compiling) as watch:
            if options.scheduler is None and not (options.resume and len(kept) == len(plan.units)):
                run.compile()
            try:
                store.take()
            except unit_store.StoreMismatch as err:
                raise RunRefused(f"{label}{err}") from None
            with StopOnSignals(once_done) as guard:
                try:
                    progress.tracing(watch)
                    results = run.trace(options.workers, progress.unit, options.executor, options.scheduler, store)
                    with guard.hold():
                        refused = _write_tables(outs, results, config, options, store, plan, label)
                    if refused:  # after the hold: a signal that came meanwhile is said first
                        raise refused[0]
                except (embree.EmbreeUnavailable, executors.WorkerFailed, unit_store.UnitNotSaved) as err:
                    raise RunFailed(f"{label}{err}{_kept(store, plan)}") from None
                except (executors.SchedulerUnreachable, PlanError) as err:
                    raise RunRefused(f"{label}{err}{_kept(store, plan)}") from None
                except tables.TableExists as err:
                    raise RunRefused(f"--out: {err}") from None
                except Stopped as stop:
                    if store.directory.exists():
                        stop.add_kept(_kept(store, plan))
                    raise
                finally:
                    store.release()
    finally:
        progress.stop()
    return RunOutcome(config, plan, list(outs), results, watch.seconds, options)


def _write_tables(outs, results, config, options: Options, store, plan, label: str) -> list:
    """Write every table, then clear the store; a table whose name was taken meanwhile is kept
    under a fresh name, and the refusals (tables.TableExists) returned."""
    from microsim import tables

    refused = []
    for path, result in zip(outs, results, strict=True):
        try:
            tables.write(path, result, config, overwrite=options.force)
        except tables.TableExists as err:
            refused.append(err)
        except OSError as err:  # a full disk: the units stay for resume
            raise RunFailed(f"{label}cannot write the table {path}: {err.strerror or err}{_free_space(path)}"
                            f"{_kept(store, plan)}") from None
    store.clear()
    return refused


def _free_space(path: Path) -> str:
    """", N MB free there" of the file system of ``path``'s directory ("" if it cannot be read)."""
    try:
        return f", {shutil.disk_usage(path.parent if str(path.parent) else '.').free / 1e6:.1f} MB free there"
    except OSError:
        return ""


def _kept(store, plan) -> str:
    """What a stopped run leaves for resume, as the end of its one line (the store goes if empty)."""
    saved = len(store.saved_units())
    if not saved:
        store.clear()
        return ""
    return f"; {saved} of {len(plan.units)} units kept in {store.directory} (rerun with --resume to finish)"


def _check_dask(scheduler) -> None:
    """RunRefused unless dask.distributed imports and ``scheduler`` (if given) is an address."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise RunRefused("--executor dask: dask.distributed is not installed (install the extra dask: "
                         "pip install -e '.[dask]' in microsim's clone)") from None
    address = SCHEDULER_ADDRESS.match(scheduler) if scheduler is not None else None
    if scheduler is not None and (address is None or not 0 < int(address["port"]) < 65536):
        raise RunRefused(f"--scheduler {scheduler!r}: expected a Dask scheduler address [tcp|tls|ws|wss://]host:port "
                         "(port 1-65535), e.g. tcp://10.0.0.5:8786")


def _refuse_input(out: Path, config_path: Path | None) -> None:
    """RunRefused if the table ``out`` would replace the config it is traced from (force or not)."""
    if config_path is not None and files.same_file(out, config_path):
        raise RunRefused(f"--out: {out} is the config file {config_path}; give the table another name")


def _check_writable(out: Path, force: bool) -> None:
    if why := files.refusal(out, force=force):
        raise RunRefused(why)
