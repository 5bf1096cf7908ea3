"""``microsim compare``, ``fit`` and ``models``: a model judged against a table
(:func:`microsim.analysis.compare.compare`, :func:`microsim.analysis.fit.fit`), and the models listed."""

from __future__ import annotations

import functools
from pathlib import Path

import click

from microsim.analysis.selection import ORDER_ROWS
from microsim.cli.entry import BadInput, cli
from microsim.cli.inputs import MODEL_HELP, load_table, model_class, model_parameters, user_model_errors
from microsim.cli.report import print_comparison
from microsim.core import files


def on_points_or_rings(command):
    """The --points and --retro flags of compare and fit (what they compare or fit instead of the
    cells), handed to ``command`` as one argument ``on``: "cells", "points" or "retro" (:func:`_on`)."""

    @functools.wraps(command)
    def with_on(*args, on_points, on_retro, **kwargs):
        return command(*args, on=_on(on_points, on_retro, kwargs["plot_dir"]), **kwargs)

    flagged = click.option("--retro", "on_retro", is_flag=True,
                           help="instead of the cells, the table's retro rings (sensor.retro_rings): the model "
                                "averaged over each ring, cos-weighted, against brdf_retro, each ring judged as a "
                                "cell; no albedo, not with --points")(with_on)
    return click.option("--points", "on_points", is_flag=True,
                        help="instead of the cells, the table's points (sensor.directions_deg, "
                             "sensor.retro_points_deg): the model at each exact direction against brdf_points "
                             "(next-event estimation), nothing averaged; no albedo, not with --retro")(flagged)


def _on(on_points: bool, on_retro: bool, plot_dir) -> str:
    """What --points and --retro ask to compare or fit: "cells", "points" or "retro"; BadInput
    for both, or either with --plot (the figures are of cells)."""
    if on_points and on_retro:
        raise BadInput("--points, --retro: give one of them (the points and the retro rings are compared apart)")
    on = "points" if on_points else "retro" if on_retro else "cells"
    if on != "cells" and plot_dir is not None:
        raise BadInput(f"--plot: the figures are of the cells; leave it out with --{on}")
    return on


def _check_plot_dir(plot_dir) -> None:
    """BadInput unless the figures' directory ``plot_dir`` exists and takes files or can be made
    (checked before the work: a comparison or a fit can take minutes)."""
    if plot_dir is not None and (why := files.refusal(plot_dir, "--plot", directory=True)):
        raise BadInput(why)


@cli.command()
@click.argument("table_path", metavar="TABLE.h5", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--model", "model_name", required=True, help=MODEL_HELP)
@click.option("--param", "params", multiple=True, metavar="KEY=VALUE", help="model parameter, repeatable")
@click.option("--order", type=click.Choice(list(ORDER_ROWS)), default="all", show_default=True,
              help="compare with one scattering order of the table, orders 1 and 2 together (1+2, the "
                   "f2 of two-bounce models), or the part of order 1 that the base scattered (1-base; "
                   "scenes with a base)")
@on_points_or_rings
@click.option("--json", "as_json", is_flag=True, help="print one JSON object")
@click.option("--plot", "plot_dir", type=click.Path(file_okay=False, path_type=Path),
              help="write PNG figures (polar maps, plane of incidence) into this directory (cells only)")
def compare(table_path, model_name, params, order, on, as_json, plot_dir):
    """Average a model over the cells of TABLE.h5 (or take it at the table's points, or average it
    over its retro rings) and report how far it is from the simulation."""
    from microsim.analysis import compare as compare_module

    values = model_parameters(params)
    _check_plot_dir(plot_dir)
    cls = model_class(model_name)
    with user_model_errors(model_name):
        try:
            model = cls(**values)
        except ValueError as err:
            raise BadInput(f"--model {model_name}: {err}") from None
    table = load_table(table_path)
    with user_model_errors(model_name):
        try:
            result = compare_module.compare(table, model, order, on=on)
        except ValueError as err:  # NaN or infinity in the model's values, data the table lacks (named)
            raise BadInput(str(err)) from None
    print_comparison(result, table, f"{model!r} vs {table_path}", as_json, plot_dir, result.as_dict())


@cli.command()
@click.argument("table_path", metavar="TABLE.h5", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--model", "model_name", required=True, help=MODEL_HELP)
@click.option("--free", "free", multiple=True, metavar="KEY", help="parameter to fit, repeatable")
@click.option("--param", "params", multiple=True, metavar="KEY=VALUE",
              help="fixed model parameter, or the starting value of a free one; repeatable")
@click.option("--order", type=click.Choice(list(ORDER_ROWS)), default="all", show_default=True,
              help="fit one scattering order of the table (as for compare)")
@on_points_or_rings
@click.option("--json", "as_json", is_flag=True, help="print one JSON object: compare's, with a key fit")
@click.option("--plot", "plot_dir", type=click.Path(file_okay=False, path_type=Path),
              help="write PNG figures of the best fit into this directory (cells only)")
def fit(table_path, model_name, free, params, order, on, as_json, plot_dir):
    """Fit model parameters to TABLE.h5 (weighted least squares on cell averages, or at its points,
    or on its retro rings); report them with standard errors, chi-square per degree of freedom
    and compare's figures for the best fit."""
    from microsim.analysis import fit as fit_module
    from microsim.app.progress import fit_status

    cls = model_class(model_name)
    values = model_parameters(params)
    _check_plot_dir(plot_dir)
    table = load_table(table_path)
    with user_model_errors(model_name), fit_status(cls.name) as status:
        try:
            result = fit_module.fit(table, cls, list(free), values, order, progress=status, on=on)
        except ValueError as err:
            message = " ".join(str(err).split())
            raise BadInput(message if message.startswith(("--", "table")) else f"--model {model_name}: {message}") \
                from None
    fitted = ", ".join(f"{k} = {v:.6g} +- {e:.2g}" for k, (v, e) in result.free.items())
    quality = (f"chi^2 / dof = {result.chi2_per_dof:.3g} ({result.dof:.1f} dof" if result.chi2_per_dof is not None
               else "no chi^2 / dof (0 dof: the values fitted are exact, or no more than the parameters")
    header = f"fit of {cls.name} to {table_path}: {fitted}; {quality}, {result.evaluations} evaluations)\nbest fit"
    print_comparison(result.comparison, table, header, as_json, plot_dir, result.as_dict())


@cli.command("models")
def list_models():
    """List the analytic models, their parameters with accepted values, and their references."""
    from microsim import models

    for line in models.listing():
        click.echo(line)
