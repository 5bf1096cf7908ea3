"""Command line (CONVENTIONS 7): ``microsim run``, ``microsim compare``, ``microsim models``.

Bad input of any kind (CONVENTIONS 9) ends with one line on stderr naming the key or flag and
what is accepted, exit status 2, no traceback, and no output file.
"""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

import click

from . import config as config_module
from .compare import ORDER_ROWS

EXIT_BAD_INPUT = 2
#: threads a process may run (Python threads, each tracing in a numba call without the GIL)
MAX_THREADS = 256


class BadInput(click.ClickException):
    exit_code = EXIT_BAD_INPUT


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="microsim")
def cli():
    """microsim: ground-truth BRDF tables from explicit random microgeometry."""


@cli.command()
@click.argument("config_path", metavar="CONFIG.toml", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--out", "out", type=click.Path(dir_okay=False, path_type=Path),
              help="table to write [default: <name or config stem>.h5]")
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
        config = config_module.load(config_path, overrides)
    except config_module.ConfigError as err:
        raise BadInput(str(err)) from None
    out = out if out is not None else Path(f"{config.name or config_path.stem}.h5")
    _check_writable(out, force)
    try:
        plan = runner.Plan.from_config(config, threads, workers)
    except runner.PlanError as err:
        raise BadInput(str(err)) from None
    total = plan.paths * plan.n_incidences
    with _progress(total) as advance:
        try:
            result = runner.run(config, workers=workers, threads=threads, progress=advance)
        except embree.EmbreeUnavailable as err:  # a worker's own check of the binding failed
            raise click.ClickException(str(err)) from None
    tables.write(out, result, config)
    albedo = ", ".join(
        f"{math.degrees(t):g}deg {a.mean[-1]:.4f}+-{a.stderr[-1]:.4f}" for t, a in zip(plan.theta_i, result.albedo)
    )
    rate = total / result.wall_time
    click.echo(f"albedo {albedo} | {result.wall_time:.1f} s, {rate:.3g} paths/s, {workers} worker(s) x "
               f"{plan.threads} thread(s), backend {plan.backend}")
    if plan.backend_note:
        click.echo(f"note: {plan.backend_note}")
    click.echo(f"table written to {out}")


@cli.command()
@click.argument("table_path", metavar="TABLE.h5", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--model", "model_name", required=True, help="analytic model (see `microsim models`)")
@click.option("--param", "params", multiple=True, metavar="KEY=VALUE", help="model parameter, repeatable")
@click.option("--order", type=click.Choice(list(ORDER_ROWS)), default="all", show_default=True,
              help="compare with one scattering order of the table")
@click.option("--json", "as_json", is_flag=True, help="print one JSON object")
@click.option("--plot", "plot_dir", type=click.Path(file_okay=False, path_type=Path),
              help="write PNG figures (polar maps, plane of incidence) into this directory")
def compare(table_path, model_name, params, order, as_json, plot_dir):
    """Average a model over the cells of TABLE.h5 and report how far it is from the simulation."""
    import json

    from . import compare as compare_module
    from . import models, tables

    values = {}
    for item in params:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise BadInput(f"--param {item!r}: expected KEY=VALUE")
        values[key.strip()] = value.strip()
    try:
        model = models.create(model_name, **values)
    except ValueError as err:
        raise BadInput(f"--model {model_name}: {err}" if "unknown model" not in str(err) else f"--model: {err}") from None
    try:
        table = tables.load(table_path)
    except FileNotFoundError:
        raise BadInput(f"TABLE.h5: {table_path} not found") from None
    except (OSError, KeyError) as err:
        raise BadInput(f"TABLE.h5: {table_path} is not a microsim table ({err})") from None
    result = compare_module.compare(table, model, order)
    if plot_dir is not None:
        from . import plots

        written = plots.write_all(result, table.sensor, plot_dir)
    if as_json:
        click.echo(json.dumps(result.as_dict()))
    else:
        click.echo(f"{model!r} vs {table_path} (order {order}; cells with signal: table > "
                   f"{compare_module.SIGNAL_TO_NOISE:g} standard errors)")
        click.echo(f"{'theta_i':>8} {'cells':>6} {'med|rel|':>9} {'rel rmse':>9} {'max|z|':>8} "
                   f"{'albedo model':>13} {'albedo sim':>16}")
        for row in result.as_dict()["per_incidence"]:
            click.echo(f"{row['theta_i_deg']:8.1f} {row['cells_with_signal']:6d} {row['median_abs_rel_err']:9.4f} "
                       f"{row['rel_rmse']:9.4f} {row['max_abs_z']:8.2f} {row['albedo_model']:13.4f} "
                       f"{row['albedo_sim']:9.4f}+-{row['albedo_sim_stderr']:.4f}")
        o = result.as_dict()["overall"]
        click.echo(f"{'overall':>8} {o['cells_with_signal']:6d} {o['median_abs_rel_err']:9.4f} {o['rel_rmse']:9.4f} "
                   f"{o['max_abs_z']:8.2f}")
    if plot_dir is not None and not as_json:
        click.echo(f"{len(written)} figures written to {plot_dir}")


@cli.command("models")
def list_models():
    """List the analytic models, their parameters with accepted values, and their references."""
    from . import models

    for name in models.available():
        cls = models.get(name)
        click.echo(f"{name}: {cls.reference}")
        if not cls.reciprocal:
            click.echo(f"    (not reciprocal: {cls.nonreciprocal_reason})")
        for p in cls.params:
            default = "no default" if p.default is None else f"default {p.default}"
            click.echo(f"    {p.name:<14} {p.describe():<30} {default:<16} {p.doc}")


def _check_writable(out: Path, force: bool) -> None:
    if out.exists() and not force:
        raise BadInput(f"--out: {out} exists; pass --force to overwrite it")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise BadInput(f"--out: directory {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise BadInput(f"--out: directory {parent} is not writable")


class _progress:
    """A rich progress bar on a terminal; nothing otherwise. Yields ``advance(paths)``."""

    def __init__(self, total: int):
        self.total = total
        self.bar = None

    def __enter__(self):
        if not sys.stderr.isatty():
            return lambda n: None
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

        self.bar = Progress(TextColumn("tracing"), BarColumn(), MofNCompleteColumn(), TextColumn("paths"),
                            TimeRemainingColumn(), console=Console(stderr=True), transient=True)
        self.bar.start()
        task = self.bar.add_task("trace", total=self.total)
        return lambda n: self.bar.advance(task, n)

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
        return EXIT_BAD_INPUT if isinstance(err, (click.UsageError, BadInput)) else err.exit_code
    return 0


if __name__ == "__main__":
    sys.exit(main())
