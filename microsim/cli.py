"""Command line (CONVENTIONS 7): ``microsim run``, ``microsim compare``, ``microsim models``.

Bad input of any kind (CONVENTIONS 9) ends with one line on stderr naming the key or flag and
what is accepted, exit status 2, no traceback, and no output file. A run keeps its finished
units in ``<table>.partial`` until its table is written (:mod:`microsim.unit_store`): a run
stopped by SIGINT, SIGTERM or SIGHUP stops its workers, writes no table, says in one line how
many units it kept for ``--resume`` and then dies of that signal (a shell reports 130, 143,
129; a shell loop stops on Ctrl-C as it should); one killed outright resumes the same way. A
signal that was ignored when microsim started (nohup, a background job) stays ignored.
"""

from __future__ import annotations

import contextlib
import csv
import math
import os
import re
import shutil
import signal
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import click

from .compare import ORDER_ROWS
from .choices import BACKEND_CHOICES, EXECUTORS
from .orders import RESULT_ALL_ORDERS

# The modules of the work itself (config and geometry, numba, h5py, the models) are imported by
# each command as it needs them: --help, `models` and a refused argument answer without them.

EXIT_BAD_INPUT = 2
#: what a Dask scheduler's address looks like: [tcp|tls|ws|wss://]host:port
SCHEDULER_ADDRESS = re.compile(r"^((tcp|tls|ws|wss)://)?(?P<host>[A-Za-z0-9._\-\[\]:]+):(?P<port>\d{1,5})$")
#: threads a process may run (Python threads, each tracing in a numba call without the GIL)
MAX_THREADS = 256


MODEL_HELP = ("analytic model: a name `microsim models` lists, or your own as module:Name or path.py:Name (a "
              "BRDFModel subclass, or a function f(wi, wo, **params) in 1/sr)")


class BadInput(click.ClickException):
    exit_code = EXIT_BAD_INPUT


#: signals that stop a run cleanly (its workers killed, no table written)
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class Stopped(click.ClickException):
    """A run stopped by a signal: exit status 128 + its number (:func:`main` then dies of it)."""

    def __init__(self, signum: int, message: str = "stopped by {name}; no table written"):
        super().__init__(message.format(name=signal.Signals(signum).name))
        self.signum = signum
        self.exit_code = 128 + signum

    def add_note(self, text: str) -> None:
        """Append ``text`` (what was kept) to the one line."""
        self.message += text


@dataclass(frozen=True)
class Options:
    """How ``microsim run`` traces: the flags shared by a run and every point of a sweep."""

    workers: int
    threads: int
    force: bool
    resume: bool
    executor: str
    scheduler: str | None


@contextlib.contextmanager
def _stop_on_signals(finishes_the_command: bool = False):
    """Within the block, the first of STOP_SIGNALS raises :class:`Stopped` (in the main thread,
    between bytecodes: the runner's clean-up then kills its workers); later ones are ignored while
    it stops. Signals ignored on entry stay ignored; outside the main thread nothing changes.

    Yields ``hold``: within ``with hold():`` (writing the tables once tracing is over) a signal is
    only noted, and raises :class:`Stopped` when the block ends, saying the work was done.
    ``finishes_the_command``: once the block ends without an error, the command's work is done,
    and stop signals are ignored until the command returns (its report printed, exit 0)."""
    stopping, holding = [], []

    @contextlib.contextmanager
    def hold():
        holding.append(True)
        try:
            yield
        finally:
            holding.pop()
        if stopping:
            raise Stopped(stopping[0], "stopped by {name} once its tables were written")

    if threading.current_thread() is not threading.main_thread():
        yield hold
        return

    def stop(signum, frame):
        if not stopping:
            stopping.append(signum)
            if not holding:
                raise Stopped(signum)

    previous = {signum: signal.getsignal(signum) for signum in STOP_SIGNALS}
    for signum, handler in previous.items():
        if handler is not signal.SIG_IGN:
            signal.signal(signum, stop)
    def restore():
        for signum, handler in previous.items():
            signal.signal(signum, handler)

    try:
        yield hold
    except BaseException:
        restore()
        raise
    if finishes_the_command:
        for signum in previous:
            signal.signal(signum, signal.SIG_IGN)
        click.get_current_context().call_on_close(restore)
    else:
        restore()


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="microsim")
def cli():
    """microsim: ground-truth BRDF tables from explicit random microgeometry."""


@cli.command()
@click.argument("config_path", metavar="CONFIG.toml", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--out", "out", type=click.Path(path_type=Path),
              help="table to write [default: <config file stem>.h5, in the current directory]; for a "
                   "config with [sweep], the directory of its tables [default: <config file stem>]")
@click.option("--workers", type=click.IntRange(1, 256), default=1, show_default=True, help="worker processes")
@click.option("--threads", type=click.IntRange(1, MAX_THREADS), default=1, show_default=True,
              help="threads per process, sharing one scene (direct backend)")
@click.option("--backend", type=click.Choice(BACKEND_CHOICES),
              help="how Embree is called (overrides run.backend)")
@click.option("--paths", type=click.IntRange(1, 10**12), help="paths per incidence (overrides run.paths)")
@click.option("--seed", type=click.IntRange(0, 2**63 - 1), help="random seed (overrides run.seed)")
@click.option("--force", is_flag=True, help="overwrite an existing table (and, without --resume, discard the units "
                                           "an interrupted run kept)")
@click.option("--resume", is_flag=True, help="continue an interrupted run from the units it kept in <table>.partial")
@click.option("--executor", type=click.Choice(list(EXECUTORS)), default="local", show_default=True,
              help="local: this process or --workers forked processes; dask: tasks on a dask.distributed "
                   "cluster (a LocalCluster of --workers processes without --scheduler)")
@click.option("--scheduler", metavar="ADDRESS", help="address of a Dask scheduler, e.g. tcp://10.0.0.5:8786 "
                                                      "(with --executor dask)")
def run(config_path, **flags):
    """Trace CONFIG.toml and write its HDF5 table."""
    from . import config as config_module
    from . import runner, sweep, unit_store

    out, workers, threads, executor, scheduler = (flags[k] for k in ("out", "workers", "threads", "executor",
                                                                      "scheduler"))
    overrides = {f"run.{key}": flags[key] for key in ("paths", "seed", "backend") if flags[key] is not None}
    try:
        data = config_module.read(config_path, overrides)
        points = sweep.points(data)
        config = config_module.validate(data) if points is None else None
    except config_module.ConfigError as err:
        raise BadInput(str(err)) from None
    if scheduler is not None and executor != "dask":
        raise BadInput("--scheduler: a Dask scheduler's address is taken with --executor dask only")
    if executor == "dask":
        _check_dask(scheduler)
    options = Options(workers, threads, flags["force"], flags["resume"], executor, scheduler)
    if points is not None:
        _run_sweep(points, out if out is not None else Path(config_path.stem), options, config_path)
        return
    out = out if out is not None else Path(f"{config_path.stem}.h5")
    if out.is_dir():
        raise BadInput(f"--out: {out} is a directory; a config without [sweep] writes one table")
    try:
        plan = runner.Plan.from_config(config, threads, workers)
    except runner.PlanError as err:
        raise BadInput(str(err)) from None
    # a run of several albedos writes one table each, named from --out with the albedo appended
    outs = [out.with_name(f"{out.stem}_albedo{albedo_text(c)}{out.suffix}") for c in plan.albedos] or [out]
    for path in outs:
        _refuse_input(path, config_path)
    results, compiling = _trace(config, plan, outs, unit_store.store_path(out), options, finishes_the_command=True)
    summaries = [_albedo_summary(plan, result) for result in results]
    traced = plan.paths * plan.n_incidences * results[0].units_traced / len(plan.units)
    timing = (f"{results[0].wall_time:.1f} s, {traced / results[0].wall_time:.3g} paths/s, {_where(plan, options)}, "
              f"backend {plan.backend}")
    if results[0].units_resumed:
        timing += f"; {results[0].units_resumed} of {len(plan.units)} units resumed, {results[0].units_traced} traced"
    if len(results) == 1:
        click.echo(f"albedo {summaries[0]} | {timing}")
    else:
        for path, result, summary in zip(outs, results, summaries):
            click.echo(f"material albedo {result.albedo_value:g}: albedo {summary} -> {path}")
        click.echo(f"{len(results)} albedos from one run of {plan.paths:,} paths an incidence: {timing}")
    for line in _run_notes(config, plan, results, compiling):
        click.echo(line)
    click.echo(f"table written to {out}" if len(outs) == 1 else f"{len(outs)} tables written")


@cli.command()
@click.argument("table_path", metavar="TABLE.h5", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--model", "model_name", required=True, help=MODEL_HELP)
@click.option("--param", "params", multiple=True, metavar="KEY=VALUE", help="model parameter, repeatable")
@click.option("--order", type=click.Choice(list(ORDER_ROWS)), default="all", show_default=True,
              help="compare with one scattering order of the table, orders 1 and 2 together (1+2, the "
                   "f2 of two-bounce models), or the part of order 1 that the base scattered (1-base; "
                   "scenes with a base)")
@click.option("--json", "as_json", is_flag=True, help="print one JSON object")
@click.option("--plot", "plot_dir", type=click.Path(file_okay=False, path_type=Path),
              help="write PNG figures (polar maps, plane of incidence) into this directory")
def compare(table_path, model_name, params, order, as_json, plot_dir):
    """Average a model over the cells of TABLE.h5 and report how far it is from the simulation."""
    from . import compare as compare_module

    values = _model_parameters(params)
    _check_plot_dir(plot_dir)
    cls = _model_class(model_name)
    with _user_model_errors(model_name):
        try:
            model = cls(**values)
        except ValueError as err:
            raise BadInput(f"--model {model_name}: {err}") from None
    table = _load_table(table_path)
    with _user_model_errors(model_name):
        try:
            result = compare_module.compare(table, model, order)
        except ValueError as err:  # NaN or infinity in the model's values (the message names it)
            raise BadInput(str(err)) from None
    _report(result, table, f"{model!r} vs {table_path}", as_json, plot_dir, result.as_dict())


@cli.command()
@click.argument("table_path", metavar="TABLE.h5", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--model", "model_name", required=True, help=MODEL_HELP)
@click.option("--free", "free", multiple=True, metavar="KEY", help="parameter to fit, repeatable")
@click.option("--param", "params", multiple=True, metavar="KEY=VALUE",
              help="fixed model parameter, or the starting value of a free one; repeatable")
@click.option("--order", type=click.Choice(list(ORDER_ROWS)), default="all", show_default=True,
              help="fit one scattering order of the table (as for compare)")
@click.option("--json", "as_json", is_flag=True, help="print one JSON object: compare's, with a key fit")
@click.option("--plot", "plot_dir", type=click.Path(file_okay=False, path_type=Path),
              help="write PNG figures of the best fit into this directory")
def fit(table_path, model_name, free, params, order, as_json, plot_dir):
    """Fit model parameters to TABLE.h5 (weighted least squares on cell averages); report them with
    standard errors, chi-square per degree of freedom and compare's figures for the best fit."""
    from . import fit as fit_module

    cls = _model_class(model_name)
    values = _model_parameters(params)
    _check_plot_dir(plot_dir)
    table = _load_table(table_path)
    with _user_model_errors(model_name), _fit_status(cls.name) as status:
        try:
            result = fit_module.fit(table, cls, list(free), values, order, progress=status)
        except ValueError as err:
            message = " ".join(str(err).split())
            raise BadInput(message if message.startswith(("--", "table")) else f"--model {model_name}: {message}") from None
    fitted = ", ".join(f"{k} = {v:.6g} +- {e:.2g}" for k, (v, e) in result.free.items())
    header = (f"fit of {cls.name} to {table_path}: {fitted}; chi^2 / dof = {result.chi2_per_dof:.3g} "
              f"({result.dof:.1f} dof, {result.evaluations} evaluations)\nbest fit")
    _report(result.comparison, table, header, as_json, plot_dir, result.as_dict())


@contextlib.contextmanager
def _fit_status(name: str):
    """On a terminal, a status line that follows a fit (its evaluations, the parameters it tries,
    the time so far); yields the fit's ``progress`` callback (None elsewhere)."""
    if not sys.stderr.isatty():
        yield None
        return
    from rich.console import Console

    from .interrupts import blocked_in_new_threads

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


def _model_class(text: str):
    """The model class ``--model`` names (a registered model, module:Name or path.py:Name), or
    BadInput in one line."""
    from .models import user_models

    try:
        return user_models.load(text)
    except ValueError as err:  # an unknown name, or a user model that does not load
        message = str(err)
        raise BadInput(f"--model: {message}" if message.startswith("unknown model") else f"--model {text}: {message}") \
            from None


@contextlib.contextmanager
def _user_model_errors(text: str):
    """A user's model (``--model`` module:Name or path.py:Name) that raises while it is
    evaluated ends in one line naming it, as a bad input; the registered models' errors are
    microsim's own and keep their traceback."""
    if ":" not in text:
        yield
        return
    try:
        yield
    except click.ClickException:
        raise
    except Exception as err:  # noqa: BLE001 - the user's code
        raise BadInput(f"--model {text}: evaluating it raised {type(err).__name__}: {' '.join(str(err).split())}") \
            from None


#: compare's verdict, by its JSON value
VERDICTS = {True: "consistent", False: "inconsistent", None: "n/a"}


def _model_parameters(params) -> dict:
    """--param KEY=VALUE items as a dictionary (values as text; the model checks them)."""
    values = {}
    for item in params:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise BadInput(f"--param {item!r}: expected KEY=VALUE")
        values[key.strip()] = value.strip()
    return values


def _check_plot_dir(plot_dir) -> None:
    """BadInput unless the figures' directory ``plot_dir`` exists and is writable or can be made
    (checked before the work: a comparison or a fit can take minutes)."""
    if plot_dir is None:
        return
    existing = plot_dir
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise BadInput(f"--plot: {existing} is a file; give a directory for the figures")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise BadInput(f"--plot: directory {existing} is not writable")


def _load_table(table_path):
    """The table at ``table_path``, or BadInput in one line."""
    from . import tables

    try:
        return tables.load(table_path)
    except FileNotFoundError:
        raise BadInput(f"TABLE.h5: {table_path} not found") from None
    except tables.TableError as err:
        raise BadInput(f"TABLE.h5: {table_path}: {err}") from None
    except OSError as err:
        raise BadInput(f"TABLE.h5: {table_path} is not a microsim table ({err})") from None


def _report(result, table, title, as_json, plot_dir, json_object) -> None:
    """compare's per-incidence and overall figures (or ``json_object``), and its figures."""
    import json

    from . import compare as compare_module

    if plot_dir is not None:
        from . import plots

        written = plots.write_all(result, table.sensor, plot_dir, table.path.name)
    if as_json:
        click.echo(json.dumps(json_object))
    else:
        click.echo(f"{title} (order {result.order}; cells with signal: table > "
                   f"{compare_module.SIGNAL_TO_NOISE:g} standard errors; chi^2 per cell: 1 expected for the model "
                   f"of the table, {100 * (1 - compare_module.CHI2_OUTSIDE):g} % two-sided bounds; consistent: "
                   "within them, and the albedo's z^2 within its bound)")
        click.echo(f"{'theta_i':>8} {'phi_i':>6} {'cells':>6} {'med|rel|':>9} {'rel rmse':>9} {'max|z|':>7} "
                   f"{'chi2/cell':>9} {'bounds':>14} {'albedo z^2':>10} {'bound':>6}  {'verdict':<12} {'albedo model':>12} "
                   f"{'albedo sim':>16}")
        rows = result.as_dict()
        for row in [*rows["per_incidence"], rows["overall"]]:
            where = (f"{row['theta_i_deg']:8.1f} {row['phi_i_deg']:6.1f}" if "theta_i_deg" in row
                     else f"{'overall':>8} {'':>6}")
            low, high = row["chi2_bounds"]
            albedos = (f" {row['albedo_model']:12.4f} {row['albedo_sim']:9.4f}+-{row['albedo_sim_stderr']:.4f}"
                       if "albedo_sim_stderr" in row else "")
            click.echo(f"{where} {row['cells_with_signal']:6d} {row['median_abs_rel_err']:9.4f} {row['rel_rmse']:9.4f} "
                       f"{row['max_abs_z']:7.2f} {row['chi2_per_cell']:9.3f} {f'[{low:.3f}, {high:.3f}]':>14} "
                       f"{row['albedo_z2']:10.3g} {row['albedo_z2_bound']:6.2f}  "
                       f"{VERDICTS[row['consistent']]:<12}{albedos}")
    if plot_dir is not None and not as_json:
        click.echo(f"{len(written)} figures written to {plot_dir}")


@cli.command("models")
def list_models():
    """List the analytic models, their parameters with accepted values, and their references."""
    from . import models

    classes = [models.get(name) for name in models.available()]
    rows = [(p.name, p.describe(), p.default_text()) for cls in classes for p in cls.params]
    widths = [max(len(row[k]) for row in rows) for k in range(3)]
    for name, cls in zip(models.available(), classes):
        click.echo(f"{name}: {cls.reference}")
        if not cls.reciprocal:
            click.echo(f"    (not reciprocal: {cls.nonreciprocal_reason})")
        for p in cls.params:
            cells = (p.name, p.describe(), p.default_text())
            click.echo("    " + "  ".join(f"{c:<{w}}" for c, w in zip(cells, widths)) + f"  {p.doc}")


def _run_sweep(points, out_dir: Path, options: Options, config_path: Path) -> None:
    """Trace every point of a sweep into ``out_dir``: one table per point, named from its values,
    and ``index.csv`` (rewritten as each point ends: values, table, status, albedo per incidence).
    With --resume, a point whose table is there (made from the same config) is kept as it is,
    and the point that was interrupted resumes from its units."""
    from . import runner, sweep, unit_store

    for point in points:
        _refuse_input(out_dir / f"{point.name}.h5", config_path)
    if out_dir.exists() and not out_dir.is_dir():
        raise BadInput(f"--out: {out_dir} is a file; a sweep writes its tables into a directory")
    if out_dir.is_dir() and any(out_dir.iterdir()) and not (options.force or options.resume):
        raise BadInput(f"--out: directory {out_dir} is not empty; pass --resume to continue the sweep in it, or "
                       "--force to overwrite its tables")
    parent = out_dir.parent if str(out_dir.parent) else Path(".")
    if not parent.is_dir() or not os.access(parent, os.W_OK):
        raise BadInput(f"--out: directory {parent} does not exist or is not writable")
    plans, kept = [], []
    for point in points:  # every refusal before anything is traced
        path = out_dir / f"{point.name}.h5"
        try:
            plan = runner.Plan.from_config(point.config, options.threads, options.workers)
            kept.append(_finished_table(path, point) if options.resume else None)
            if kept[-1] is None:
                if options.scheduler is None:
                    runner.check_memory(plan, plan.build_sensor(), options.workers, spawned=options.executor == "dask")
                unit_store.UnitStore.check(unit_store.store_path(path), plan, options.resume, options.force)
        except (runner.PlanError, unit_store.StoreMismatch) as err:
            raise BadInput(f"sweep point {point.name}: {err}") from None
        plans.append(plan)
    out_dir.mkdir(exist_ok=True)
    keys = list(points[0].values)
    rows = [{"point": p.name, **{k: p.values[k] for k in keys}, "table": f"{p.name}.h5", "status": "pending"}
            for p in points]
    for row, plan, table in zip(rows, plans, kept):
        if table is not None:
            _index_albedos(row, plan, table.arrays["albedo"])
    _write_index(out_dir, rows)
    for row, point, plan, table in zip(rows, points, plans, kept):
        if table is not None:
            unit_store.UnitStore(unit_store.store_path(out_dir / row["table"]), {}).clear()  # outlived its table
            click.echo(f"{point.name}: kept (its table was finished)")
            continue
        path = out_dir / row["table"]
        result = _trace(point.config, plan, [path], unit_store.store_path(path), options,
                        label=f"sweep point {point.name}: ", finishes_the_command=point is points[-1])[0][0]
        _index_albedos(row, plan, [a.mean[RESULT_ALL_ORDERS] for a in result.albedo])
        _write_index(out_dir, rows)
        click.echo(f"{point.name}: albedo {_albedo_summary(plan, result)} | {result.wall_time:.1f} s")
    click.echo(f"{len(points)} tables and {sweep.INDEX} written to {out_dir}")


def _finished_table(path: Path, point):
    """A sweep point's table if it is there and was made from the point's config, None if it is
    not there; BadInput if a table of another config holds its name."""
    from . import tables

    if not path.exists():
        return None
    try:
        table = tables.load(path)
    except (OSError, tables.TableError):
        table = None
    if table is None or table.attrs.get("config_toml") != tables.config_to_toml(point.config):
        raise BadInput(f"--resume: {path} is not the table of sweep point {point.name} (another config, or "
                       "damaged); pass --force to overwrite it")
    return table


def _index_albedos(row: dict, plan, albedos) -> None:
    row["status"] = "done"
    for t, a in zip(plan.theta_i, albedos):
        row[f"albedo_theta{math.degrees(t):g}"] = f"{a:.6g}"


def _trace(config, plan, outs, directory: Path, options: Options, label: str = "", finishes_the_command=False):
    """Trace a planned config and write its tables (one per albedo) to ``outs`` (``finishes_the_command``:
    then ignore stop signals until the command returns, :func:`_stop_on_signals`); finished units
    are kept in the unit store ``directory`` until the tables are written. A failure or a signal
    says in its one line how many units were kept for --resume; a refusal keeps them all.

    The tracer is compiled first (said on the progress line while it lasts), before the store is
    touched: a signal then ends the command at once, with nothing to clean up. Returns the
    results and the seconds of compiling, which the caller reports apart from the tracing."""
    from . import embree, executors, runner, tables, unit_store
    from .compile_watch import CompileWatch

    for path in outs:
        _check_writable(path, options.force)
    try:
        if options.scheduler is None:  # before the store is touched: a refusal must not cost a unit
            runner.check_memory(plan, plan.build_sensor(), options.workers, spawned=options.executor == "dask")
        kept = unit_store.UnitStore.check(directory, plan, options.resume, options.force).saved_units()
    except (runner.PlanError, unit_store.StoreMismatch) as err:
        raise BadInput(f"{label}{err}") from None
    progress = _Progress(plan, plan.tracer_class.COMPILE_SECONDS[plan.backend])
    with progress, CompileWatch(progress.compiling) as watch:
        if options.scheduler is None and not (options.resume and len(kept) == len(plan.units)):
            runner.compile_tracer(plan)
        try:
            store = unit_store.UnitStore.open(directory, plan, options.resume, options.force)
        except unit_store.StoreMismatch as err:
            raise BadInput(f"{label}{err}") from None
        with _stop_on_signals(finishes_the_command) as hold:
            try:
                progress.begin(watch)
                results = runner.run_albedos(config, options.workers, options.threads, progress.advance,
                                             options.executor, options.scheduler, store)
                with hold():
                    refused = []  # a table whose name was taken meanwhile is kept under a fresh name: write them all
                    for path, result in zip(outs, results):
                        try:
                            tables.write(path, result, config, overwrite=options.force)
                        except tables.TableExists as err:
                            refused.append(err)
                        except OSError as err:  # a full disk: the units stay for --resume
                            raise click.ClickException(f"{label}cannot write the table {path}: "
                                                       f"{err.strerror or err}{_free_space(path)}"
                                                       f"{_kept(store, plan)}") from None
                    store.clear()
                if refused:
                    raise refused[0]
            except (embree.EmbreeUnavailable, executors.WorkerFailed, unit_store.UnitNotSaved) as err:  # one line each
                raise click.ClickException(f"{label}{err}{_kept(store, plan)}") from None
            except (executors.SchedulerUnreachable, runner.PlanError) as err:
                raise BadInput(f"{label}{err}{_kept(store, plan)}") from None
            except tables.TableExists as err:
                raise BadInput(f"--out: {err}") from None
            except Stopped as stop:
                if store.directory.exists():
                    stop.add_note(_kept(store, plan))
                raise
            finally:
                store.release()
    return results, watch.seconds


def _free_space(path: Path) -> str:
    """", N MB free there" of the file system of ``path``'s directory ("" if it cannot be read)."""
    try:
        return f", {shutil.disk_usage(path.parent if str(path.parent) else '.').free / 1e6:.1f} MB free there"
    except OSError:
        return ""


def _kept(store, plan) -> str:
    """What a stopped run leaves for --resume, as the end of its one line (the store goes if empty)."""
    saved = len(store.saved_units())
    if not saved:
        store.clear()
        return ""
    return f"; {saved} of {len(plan.units)} units kept in {store.directory} (rerun with --resume to finish)"


#: compiling shorter than this is not worth a line
COMPILE_NOTE_SECONDS = 0.5


def _run_notes(config, plan, results, compiling: float) -> list[str]:
    """The lines after a run's albedos: compiling, paths rounded up, energy that left the
    albedo beyond its error, the backend's substitutions."""
    notes = []
    if compiling >= COMPILE_NOTE_SECONDS:
        notes.append(f"compiled the tracer in {compiling:.1f} s (not in the time above; once for this machine and "
                     "these sources, then loaded from numba's cache)")
    if plan.paths != config.run.paths:
        notes.append(f"paths: {plan.paths:,} an incidence traced for the {config.run.paths:,} asked: "
                     f"{plan.realizations} realizations of {plan.paths_per_realization:,} (run.paths rounded up to a "
                     "multiple of run.realizations)")
    for result in results:
        notes.extend(_energy_notes(plan, result))
    if plan.backend_note:
        notes.append(f"note: {plan.backend_note}")
    return notes


#: why energy leaves a run without reaching the sensor, by energy/ dataset
ENERGY_CAUSES = {"transmitted": "left through the bottom of the scene (a deeper scene, or a base, keeps it)",
                 "truncated": "cut when paths reached run.max_order or the tracer's limit of interactions"}


def _energy_notes(plan, result) -> list[str]:
    """One line for each kind of lost energy (transmitted, truncated) that exceeds the albedo's
    standard error at some incidence: there the albedo is short of the scene's by more than
    its noise (the table's energy/ datasets hold every incidence)."""
    from .tally import ENERGY_NAMES

    lines = []
    for name, cause in ENERGY_CAUSES.items():
        j = ENERGY_NAMES.index(name)
        lost = [(t, energy.mean[j]) for t, energy, albedo in zip(plan.theta_i, result.energy, result.albedo)
                if energy.mean[j] > albedo.stderr[RESULT_ALL_ORDERS]]
        if lost:
            where = ", ".join(f"{math.degrees(t):g}deg {value:.4f}" for t, value in lost)
            albedo = f"material albedo {result.albedo_value:g}: " if result.albedo_value is not None else ""
            lines.append(f"{albedo}energy {name}, beyond the albedo's standard error: {where} ({cause})")
    return lines


def _where(plan, options: Options) -> str:
    if options.executor == "dask":
        return (f"dask at {options.scheduler}" if options.scheduler else
                f"dask LocalCluster of {options.workers} worker(s)") + f" x {plan.threads} thread(s)"
    return f"{options.workers} worker(s) x {plan.threads} thread(s)"


def _check_dask(scheduler) -> None:
    """BadInput unless dask.distributed imports and ``scheduler`` (if given) is an address."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise BadInput("--executor dask: dask.distributed is not installed (pip install 'microsim[dask]')") from None
    address = SCHEDULER_ADDRESS.match(scheduler) if scheduler is not None else None
    if scheduler is not None and (address is None or not 0 < int(address["port"]) < 65536):
        raise BadInput(f"--scheduler {scheduler!r}: expected a Dask scheduler address [tcp|tls|ws|wss://]host:port "
                       "(port 1-65535), e.g. tcp://10.0.0.5:8786")


def _albedo_summary(plan, result) -> str:
    """The albedo of every incidence with its standard error, named by theta_i (and phi_i where
    the incidences pair their azimuths)."""
    azimuths = len(set(plan.phi_i.tolist())) > 1
    return ", ".join(
        f"{math.degrees(t):g}{f'/{math.degrees(p):g}' if azimuths else ''}deg "
        f"{a.mean[RESULT_ALL_ORDERS]:.4f}+-{a.stderr[RESULT_ALL_ORDERS]:.4f}"
        for t, p, a in zip(plan.theta_i, plan.phi_i, result.albedo))


def _write_index(out_dir: Path, rows) -> None:
    """index.csv of a sweep, replaced atomically."""
    from . import sweep

    columns = list(dict.fromkeys(key for row in rows for key in row))
    tmp = out_dir / f".{sweep.INDEX}.tmp"
    with open(tmp, "w", newline="") as handle:
        writer = csv.DictWriter(handle, columns, restval="")
        writer.writeheader()
        writer.writerows(rows)
    os.replace(tmp, out_dir / sweep.INDEX)


def albedo_text(albedo: float) -> str:
    """The albedo in a table's name: its shortest %g form where that reads back as the same number,
    else all its digits, so that distinct albedos name distinct tables (0.1 and 0.1000001)."""
    short = f"{albedo:g}"
    return short if float(short) == albedo else repr(float(albedo))


def _refuse_input(out: Path, config_path: Path) -> None:
    """BadInput if the table ``out`` would replace the config it is traced from (--force or not)."""
    same = out.resolve() == config_path.resolve() or (out.exists() and os.path.samefile(out, config_path))
    if same:
        raise BadInput(f"--out: {out} is the config file {config_path}; give the table another name")


def _check_writable(out: Path, force: bool) -> None:
    if out.exists() and not force:
        raise BadInput(f"--out: {out} exists; pass --force to overwrite it")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise BadInput(f"--out: directory {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise BadInput(f"--out: directory {parent} is not writable")


class _Progress:
    """A rich progress line on a terminal, nothing otherwise.

    While numba compiles the tracer it says so, with the time that takes here
    (``COMPILE_SECONDS`` of the tracer class); then it counts units (realization x incidence) and
    paths per incidence, as ``--paths`` does. Its time left is the mean rate of the units traced
    since the first one ended, without the seconds spent compiling (``watch``), applied to what
    is left: the first unit carries the start (forking workers, building their first scenes),
    which made the first estimates of a run on 2 workers 4.4 times the true time left (measured
    by benchmarks/first_run.py); a mean rate is steadier than a recent one when units end in
    bursts, as they do with workers. Units taken from a resumed run's store count as done, not
    in the rate."""

    def __init__(self, plan, compile_seconds: float):
        self.plan, self.compile_seconds = plan, compile_seconds
        self.bar = self.task = self.watch = self.start = None
        self.done = self.traced = 0

    def __enter__(self):
        if sys.stderr.isatty():
            from rich.console import Console
            from rich.progress import BarColumn, Progress, TextColumn

            from .interrupts import blocked_in_new_threads

            self.bar = Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.fields[status]}"),
                                console=Console(stderr=True), transient=True)
            with blocked_in_new_threads():  # its refresh thread
                self.bar.start()
            units = len(self.plan.units)
            self.task = self.bar.add_task("tracing", total=units, status=f"0/{units} units")
        return self

    def compiling(self) -> None:
        """numba began compiling (called from the thread that compiles)."""
        if self.bar is not None:
            self.bar.update(self.task, description="compiling",
                            status=f"the tracer, for this machine (once; about {self.compile_seconds:.0f} s)")

    def begin(self, watch) -> None:
        """Tracing begins: the rate leaves out what ``watch`` sees compiled."""
        self.watch = watch
        if self.bar is not None:
            self.bar.update(self.task, description="tracing", status=f"0/{len(self.plan.units)} units")

    def advance(self, unit, paths, from_store) -> None:
        """A unit ended (or was taken from the store, ``from_store``)."""
        now, compiled = time.monotonic(), self.watch.seconds
        self.done += 1
        self.traced += not from_store
        if not from_store and self.start is None:
            self.start = (now, compiled)  # the first traced unit: the rate counts from here
        if self.bar is None:
            return
        units, plan = len(self.plan.units), self.plan
        elapsed = (now - self.start[0]) - (compiled - self.start[1]) if self.start else 0.0
        rate_units = self.traced - 1
        left = f"{elapsed * (units - self.done) / rate_units:.0f} s left" if rate_units > 0 else "starting"
        per_incidence = self.done * plan.paths_per_realization // plan.n_incidences
        self.bar.update(self.task, advance=1, description="tracing",
                        status=f"{self.done}/{units} units, {per_incidence:,} of {plan.paths:,} paths per "
                               f"incidence, {left}")

    def __exit__(self, *exc):
        if self.bar is not None:
            self.bar.stop()
        return False


def main(argv=None) -> int:
    """Entry point of the ``microsim`` command: 0, or the exit status of its one-line error.

    A stop signal (SIGINT, SIGTERM, SIGHUP) ends the command in one line whenever it comes, and
    the process then dies of it. While a run traces and writes its tables, :func:`_stop_on_signals`
    stops it cleanly; at any other time there is nothing to clean up, and the process dies at
    once: an exception raised from the handler could be swallowed (by a ctypes callback of
    numba's compiler, seen to let a run go on to its end). Where a caller of ``main`` left SIGINT
    to Python's KeyboardInterrupt, it is reported in the same line and ``main`` returns 130. The
    handlers are the caller's again when ``main`` returns or raises."""
    installed = _die_on_stop_signals()
    try:
        cli.main(args=argv, prog_name="microsim", standalone_mode=False)
    except (KeyboardInterrupt, click.exceptions.Abort):
        click.echo("microsim: error: stopped by SIGINT", err=True)
        return 128 + signal.SIGINT
    except click.ClickException as err:
        _restore(installed)
        message = err.format_message().replace("\n", " ")
        click.echo(f"microsim: error: {message}", err=True)
        if isinstance(err, Stopped):
            die_of(err.signum)
        return EXIT_BAD_INPUT if isinstance(err, (click.UsageError, BadInput)) else err.exit_code
    finally:
        _restore(installed)
    return 0


def _die_on_stop_signals() -> dict:
    """Have each stop signal that is in its default disposition (Python's KeyboardInterrupt for
    SIGINT) print the one line and end the process; returns the handlers replaced. Nothing
    outside the main thread, and nothing for a signal that is ignored or that a caller handles."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    defaults = {signal.SIGINT: signal.default_int_handler, signal.SIGTERM: signal.SIG_DFL, signal.SIGHUP: signal.SIG_DFL}
    installed = {}
    for signum, default in defaults.items():
        if signal.getsignal(signum) is default:
            installed[signum] = signal.signal(signum, _stop_now)
    return installed


def _stop_now(signum, frame):
    if sys.stderr.isatty():  # a progress line may be drawn: clear it, and show the cursor it hid
        sys.stderr.write("\r\x1b[2K\x1b[?25h")
    sys.stderr.write(f"microsim: error: stopped by {signal.Signals(signum).name}\n")
    die_of(signum)


def _restore(installed: dict) -> None:
    for signum, handler in installed.items():
        signal.signal(signum, handler)


def die_of(signum: int) -> None:
    """End this process by ``signum`` with its default action, as a shell expects of a process
    that was stopped (status 128 + signum; a shell loop stops on Ctrl-C); nothing outside the
    main thread (a caller that runs microsim in a thread of its own keeps its process)."""
    if threading.current_thread() is threading.main_thread():
        sys.stderr.flush()
        signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)


if __name__ == "__main__":
    sys.exit(main())
