"""Command line (CONVENTIONS 7): ``microsim run``, ``microsim compare``, ``microsim models``.

Bad input of any kind (CONVENTIONS 9) ends with one line on stderr naming the key or flag and
what is accepted, exit status 2, no traceback, and no output file. A run stopped by SIGINT,
SIGTERM or SIGHUP stops its workers, writes nothing, says so in one line and then dies of that
signal (a shell reports 130, 143, 129; a shell loop stops on Ctrl-C as it should). A signal
that was ignored when microsim started (nohup, a background job) stays ignored.
"""

from __future__ import annotations

import contextlib
import csv
import math
import os
import signal
import sys
import threading
import time
from pathlib import Path

import click

from . import config as config_module
from . import sweep
from .compare import ORDER_ROWS
from .integrators.records import RESULT_ALL_ORDERS

EXIT_BAD_INPUT = 2
#: threads a process may run (Python threads, each tracing in a numba call without the GIL)
MAX_THREADS = 256


class BadInput(click.ClickException):
    exit_code = EXIT_BAD_INPUT


#: signals that stop a run cleanly (its workers killed, no table written)
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class Stopped(click.ClickException):
    """A run stopped by a signal: exit status 128 + its number (:func:`main` then dies of it)."""

    def __init__(self, signum: int):
        super().__init__(f"stopped by {signal.Signals(signum).name}; no table written")
        self.signum = signum
        self.exit_code = 128 + signum


@contextlib.contextmanager
def _stop_on_signals():
    """Within the block, the first of STOP_SIGNALS raises :class:`Stopped` (in the main thread,
    between bytecodes: the runner's clean-up then kills its workers); later ones are ignored while
    it stops. Signals ignored on entry stay ignored; outside the main thread nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    stopping = []

    def stop(signum, frame):
        if not stopping:
            stopping.append(signum)
            raise Stopped(signum)

    previous = {signum: signal.getsignal(signum) for signum in STOP_SIGNALS}
    for signum, handler in previous.items():
        if handler is not signal.SIG_IGN:
            signal.signal(signum, stop)
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


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
@click.option("--backend", type=click.Choice(["auto", "direct", "embreex"]),
              help="how Embree is called (overrides run.backend)")
@click.option("--paths", type=click.IntRange(1, 10**12), help="paths per incidence (overrides run.paths)")
@click.option("--seed", type=click.IntRange(0, 2**63 - 1), help="random seed (overrides run.seed)")
@click.option("--force", is_flag=True, help="overwrite an existing table")
def run(config_path, out, workers, threads, backend, paths, seed, force):
    """Trace CONFIG.toml and write its HDF5 table."""
    from . import embree, runner, tables

    overrides = {}
    if paths is not None:
        overrides["run.paths"] = paths
    if seed is not None:
        overrides["run.seed"] = seed
    if backend is not None:
        overrides["run.backend"] = backend
    try:
        data = config_module.read(config_path, overrides)
        points = sweep.points(data)
        config = config_module.validate(data) if points is None else None
    except config_module.ConfigError as err:
        raise BadInput(str(err)) from None
    if points is not None:
        _run_sweep(points, out if out is not None else Path(config_path.stem), workers, threads, force)
        return
    out = out if out is not None else Path(f"{config_path.stem}.h5")
    if out.is_dir():
        raise BadInput(f"--out: {out} is a directory; a config without [sweep] writes one table")
    try:
        plan = runner.Plan.from_config(config, threads, workers)
    except runner.PlanError as err:
        raise BadInput(str(err)) from None
    # a run of several albedos writes one table each, named from --out with the albedo appended
    outs = [out.with_name(f"{out.stem}_albedo{c:g}{out.suffix}") for c in plan.albedos] or [out]
    for path in outs:
        _check_writable(path, force)
    total = plan.paths * plan.n_incidences
    with _stop_on_signals(), _progress(plan) as advance:
        try:
            results = runner.run_albedos(config, workers=workers, threads=threads, progress=advance)
        except (embree.EmbreeUnavailable, runner.WorkerFailed) as err:  # in a worker, one line each
            raise click.ClickException(str(err)) from None
        except runner.PlanError as err:
            raise BadInput(str(err)) from None
        try:
            for path, result in zip(outs, results):
                tables.write(path, result, config, overwrite=force)
        except tables.TableExists as err:
            raise BadInput(f"--out: {err}") from None
    summaries = [_albedo_summary(plan, result) for result in results]
    rate = total / results[0].wall_time
    timing = (f"{results[0].wall_time:.1f} s, {rate:.3g} paths/s, {workers} worker(s) x {plan.threads} thread(s), "
              f"backend {plan.backend}")
    if len(results) == 1:
        click.echo(f"albedo {summaries[0]} | {timing}")
    else:
        for path, result, summary in zip(outs, results, summaries):
            click.echo(f"material albedo {result.albedo_value:g}: albedo {summary} -> {path}")
        click.echo(f"{len(results)} albedos from one run of {plan.paths:,} paths an incidence: {timing}")
    if plan.backend_note:
        click.echo(f"note: {plan.backend_note}")
    click.echo(f"table written to {out}" if len(outs) == 1 else f"{len(outs)} tables written")


@cli.command()
@click.argument("table_path", metavar="TABLE.h5", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--model", "model_name", required=True, help="analytic model (see `microsim models`)")
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
    from . import models

    values = _model_parameters(params)
    try:
        model = models.create(model_name, **values)
    except ValueError as err:
        raise BadInput(f"--model {model_name}: {err}" if "unknown model" not in str(err) else f"--model: {err}") from None
    table = _load_table(table_path)
    try:
        result = compare_module.compare(table, model, order)
    except ValueError as err:  # NaN or infinity in the model's values (the message names it)
        raise BadInput(str(err)) from None
    _report(result, table, f"{model!r} vs {table_path}", as_json, plot_dir, result.as_dict())


@cli.command()
@click.argument("table_path", metavar="TABLE.h5", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--model", "model_name", required=True, help="analytic model (see `microsim models`)")
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
    from . import models

    if model_name not in models.available():
        raise BadInput(f"--model: unknown model {model_name!r}; available: {', '.join(models.available())}")
    values = _model_parameters(params)
    table = _load_table(table_path)
    try:
        result = fit_module.fit(table, model_name, list(free), values, order)
    except ValueError as err:
        message = " ".join(str(err).split())
        raise BadInput(message if message.startswith(("--", "table")) else f"--model {model_name}: {message}") from None
    fitted = ", ".join(f"{k} = {v:.6g} +- {e:.2g}" for k, (v, e) in result.free.items())
    header = (f"fit of {model_name} to {table_path}: {fitted}; chi^2 / dof = {result.chi2_per_dof:.3g} "
              f"({result.dof} dof, {result.evaluations} evaluations)\nbest fit")
    _report(result.comparison, table, header, as_json, plot_dir, result.as_dict())


def _model_parameters(params) -> dict:
    """--param KEY=VALUE items as a dictionary (values as text; the model checks them)."""
    values = {}
    for item in params:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise BadInput(f"--param {item!r}: expected KEY=VALUE")
        values[key.strip()] = value.strip()
    return values


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

        written = plots.write_all(result, table.sensor, plot_dir)
    if as_json:
        click.echo(json.dumps(json_object))
    else:
        click.echo(f"{title} (order {result.order}; cells with signal: table > "
                   f"{compare_module.SIGNAL_TO_NOISE:g} standard errors)")
        click.echo(f"{'theta_i':>8} {'phi_i':>6} {'cells':>6} {'med|rel|':>9} {'rel rmse':>9} {'max|z|':>8} "
                   f"{'albedo model':>13} {'albedo sim':>16}")
        for row in result.as_dict()["per_incidence"]:
            click.echo(f"{row['theta_i_deg']:8.1f} {row['phi_i_deg']:6.1f} {row['cells_with_signal']:6d} "
                       f"{row['median_abs_rel_err']:9.4f} "
                       f"{row['rel_rmse']:9.4f} {row['max_abs_z']:8.2f} {row['albedo_model']:13.4f} "
                       f"{row['albedo_sim']:9.4f}+-{row['albedo_sim_stderr']:.4f}")
        o = result.as_dict()["overall"]
        click.echo(f"{'overall':>8} {'':>6} {o['cells_with_signal']:6d} {o['median_abs_rel_err']:9.4f} {o['rel_rmse']:9.4f} "
                   f"{o['max_abs_z']:8.2f}")
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


def _run_sweep(points, out_dir: Path, workers: int, threads: int, force: bool) -> None:
    """Trace every point of a sweep into ``out_dir``: one table per point, named from its values,
    and ``index.csv`` (rewritten as each point ends: values, table, status, albedo per incidence)."""
    from . import embree, runner, tables

    if out_dir.exists() and not out_dir.is_dir():
        raise BadInput(f"--out: {out_dir} is a file; a sweep writes its tables into a directory")
    if out_dir.is_dir() and any(out_dir.iterdir()) and not force:
        raise BadInput(f"--out: directory {out_dir} is not empty; pass --force to overwrite its tables")
    parent = out_dir.parent if str(out_dir.parent) else Path(".")
    if not parent.is_dir() or not os.access(parent, os.W_OK):
        raise BadInput(f"--out: directory {parent} does not exist or is not writable")
    plans = []
    for point in points:
        try:
            plans.append(runner.Plan.from_config(point.config, threads, workers))
        except runner.PlanError as err:
            raise BadInput(f"sweep point {point.name}: {err}") from None
    out_dir.mkdir(exist_ok=True)
    keys = list(points[0].values)
    rows = [{"point": p.name, **{k: p.values[k] for k in keys}, "table": f"{p.name}.h5", "status": "pending"}
            for p in points]
    _write_index(out_dir, rows)
    for row, point, plan in zip(rows, points, plans):
        with _stop_on_signals(), _progress(plan) as advance:
            try:
                result = runner.run(point.config, workers=workers, threads=threads, progress=advance)
            except (embree.EmbreeUnavailable, runner.WorkerFailed) as err:
                raise click.ClickException(f"sweep point {point.name}: {err}") from None
            tables.write(out_dir / row["table"], result, point.config, overwrite=force)
        row["status"] = "done"
        for t, a in zip(plan.theta_i, result.albedo):
            row[f"albedo_theta{math.degrees(t):g}"] = f"{a.mean[RESULT_ALL_ORDERS]:.6g}"
        _write_index(out_dir, rows)
        click.echo(f"{point.name}: albedo {_albedo_summary(plan, result)} | {result.wall_time:.1f} s")
    click.echo(f"{len(points)} tables and {sweep.INDEX} written to {out_dir}")


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
    columns = list(dict.fromkeys(key for row in rows for key in row))
    tmp = out_dir / f".{sweep.INDEX}.tmp"
    with open(tmp, "w", newline="") as handle:
        writer = csv.DictWriter(handle, columns, restval="")
        writer.writeheader()
        writer.writerows(rows)
    os.replace(tmp, out_dir / sweep.INDEX)


def _check_writable(out: Path, force: bool) -> None:
    if out.exists() and not force:
        raise BadInput(f"--out: {out} exists; pass --force to overwrite it")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise BadInput(f"--out: directory {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise BadInput(f"--out: directory {parent} is not writable")


class _progress:
    """A rich progress bar on a terminal, nothing otherwise; yields ``advance(unit, paths)``.

    It counts units (realization x incidence) and paths per incidence, as ``--paths`` does, and
    its time left is the mean rate since the start applied to what is left (steadier than a
    recent-rate estimate when units end in bursts, as they do with workers)."""

    def __init__(self, plan):
        self.plan = plan
        self.bar = None

    def __enter__(self):
        if not sys.stderr.isatty():
            return lambda unit, paths: None
        from rich.console import Console
        from rich.progress import BarColumn, Progress, TextColumn

        plan, start = self.plan, time.monotonic()
        self.bar = Progress(TextColumn("tracing"), BarColumn(), TextColumn("{task.fields[status]}"),
                            console=Console(stderr=True), transient=True)
        self.bar.start()
        units = len(plan.units)
        task = self.bar.add_task("trace", total=units, status=f"0/{units} units")

        def advance(unit, paths):
            self.bar.advance(task, 1)
            done = int(self.bar.tasks[0].completed)
            left = (time.monotonic() - start) * (units - done) / done
            per_incidence = done * plan.paths_per_realization // plan.n_incidences
            self.bar.update(task, status=f"{done}/{units} units, {per_incidence:,} of {plan.paths:,} paths per "
                                         f"incidence, {left:.0f} s left")
        return advance

    def __exit__(self, *exc):
        if self.bar is not None:
            self.bar.stop()
        return False


def main(argv=None) -> int:
    """Entry point of the ``microsim`` console script."""
    try:
        cli.main(args=argv, prog_name="microsim", standalone_mode=False)
    except click.exceptions.Abort:
        click.echo("microsim: aborted", err=True)
        return 130
    except click.ClickException as err:
        message = err.format_message().replace("\n", " ")
        click.echo(f"microsim: error: {message}", err=True)
        if isinstance(err, Stopped) and threading.current_thread() is threading.main_thread():
            sys.stderr.flush()
            signal.signal(err.signum, signal.SIG_DFL)
            os.kill(os.getpid(), err.signum)  # die of it, as the shell expects
        return EXIT_BAD_INPUT if isinstance(err, (click.UsageError, BadInput)) else err.exit_code
    return 0


if __name__ == "__main__":
    sys.exit(main())
