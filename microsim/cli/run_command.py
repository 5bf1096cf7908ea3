"""``microsim run``: a config traced into its table (or a sweep into its directory of tables), by
:func:`microsim.app.session.run`, with the progress line and the report printed."""

from __future__ import annotations

from pathlib import Path

import click

from microsim.cli.entry import BadInput, cli
from microsim.core.choices import BACKEND_CHOICES, EXECUTORS, MAX_THREADS, MAX_WORKERS


@cli.command()
@click.argument("config_path", metavar="CONFIG.toml", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--out", "out", type=click.Path(path_type=Path),
              help="table to write [default: the config file's stem + .h5, in the current directory]; for "
                   "a config with [sweep], the directory of its tables [default: the config file's stem]")
@click.option("--workers", type=click.IntRange(1, MAX_WORKERS), default=1, show_default=True, help="worker processes")
@click.option("--threads", type=click.IntRange(1, MAX_THREADS), default=1, show_default=True,
              help="threads per process, sharing one scene (direct backend)")
@click.option("--backend", type=click.Choice(BACKEND_CHOICES),
              help="how Embree is called (overrides run.backend)")
@click.option("--paths", type=click.IntRange(1, 10**12), help="paths per incidence (overrides run.paths)")
@click.option("--seed", type=click.IntRange(0, 2**63 - 1), help="random seed (overrides run.seed)")
@click.option("--force", is_flag=True, help="overwrite an existing table (and, without --resume, discard the units "
                                           "an interrupted run kept)")
@click.option("--resume", is_flag=True, help="continue an interrupted run from the units it kept in TABLE.partial")
@click.option("--executor", type=click.Choice(list(EXECUTORS)), default="local", show_default=True,
              help="local: this process or --workers forked processes; dask: tasks on a dask.distributed "
                   "cluster (a LocalCluster of --workers processes without --scheduler)")
@click.option("--scheduler", metavar="ADDRESS", help="address of a Dask scheduler, e.g. tcp://10.0.0.5:8786 "
                                                      "(with --executor dask)")
def run(config_path, **flags):
    """Trace CONFIG.toml and write its HDF5 table."""
    from microsim.app import session
    from microsim.app.progress import ProgressBar
    from microsim.core.interrupts import IgnoredOnceDone

    with IgnoredOnceDone() as once_done:  # once the tables are written, a signal waits for the report
        try:
            outcome = session.run(config_path, **flags, progress=ProgressBar(),
                                  on_point=lambda point: click.echo(point.line()), once_done=once_done)
        except session.RunRefused as err:
            raise BadInput(str(err)) from None
        except session.RunFailed as err:
            raise click.ClickException(str(err)) from None
        for line in outcome.report():
            click.echo(line)
