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

EXIT_BAD_INPUT = 2


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
@click.option("--paths", type=click.IntRange(1, 10**12), help="paths per incidence (overrides run.paths)")
@click.option("--seed", type=click.IntRange(0, 2**63 - 1), help="random seed (overrides run.seed)")
@click.option("--force", is_flag=True, help="overwrite an existing table")
def run(config_path, out, workers, paths, seed, force):
    """Trace CONFIG.toml and write its HDF5 table."""
    from . import runner, tables

    overrides = {}
    if paths is not None:
        overrides["run.paths"] = paths
    if seed is not None:
        overrides["run.seed"] = seed
    try:
        config = config_module.load(config_path, overrides)
    except config_module.ConfigError as err:
        raise BadInput(str(err)) from None
    out = out if out is not None else Path(f"{config.name or config_path.stem}.h5")
    _check_writable(out, force)
    plan = runner.Plan.from_config(config)
    total = plan.paths * plan.n_incidences
    with _progress(total) as advance:
        result = runner.run(config, workers=workers, progress=advance)
    tables.write(out, result, config)
    albedo = ", ".join(
        f"{math.degrees(t):g}deg {a.mean[-1]:.4f}+-{a.stderr[-1]:.4f}" for t, a in zip(plan.theta_i, result.albedo)
    )
    rate = total / result.wall_time
    click.echo(f"albedo {albedo} | {result.wall_time:.1f} s, {rate:.3g} paths/s, {workers} worker(s)")
    click.echo(f"table written to {out}")


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
