"""``microsim compare``, ``fit`` and ``models``: a model judged against a table
(:func:`microsim.analysis.compare.compare`, :func:`microsim.analysis.fit.fit`), and the models listed."""

from __future__ import annotations

from pathlib import Path

import click

from microsim.analysis import judges
from microsim.analysis.judges import DEFAULT_ON
from microsim.analysis.selection import ORDER_ROWS
from microsim.cli.entry import BadInput, cli
from microsim.cli.inputs import MODEL_HELP, load_table, model_class, model_parameters, user_model_errors
from microsim.cli.report import print_comparison
from microsim.core import files

#: the parameter name of the flag --<on>: "on_" and the judge's word
FLAG_PREFIX = "on_"


class JudgedCommand(click.Command):
    """compare and fit: a flag --<on> for every estimator's judge but the cells'
    (:func:`microsim.analysis.judges.flagged`: --points, --retro), what they compare or fit
    instead of the cells, handed to the command as one argument ``on`` (:func:`_on`). The flags
    are added when the command's parameters are first asked for (its help, its parsing), so that
    the rest of the CLI loads none of the estimators' declarations."""

    def get_params(self, ctx):
        if not any(param.name.startswith(FLAG_PREFIX) for param in self.params):
            flagged = judges.flagged()
            at = next((k for k, param in enumerate(self.params) if param.name == "as_json"), len(self.params))
            self.params[at:at] = [
                click.Option([f"--{on}", FLAG_PREFIX + on], is_flag=True,
                             help=judge.help + "".join(f"; not with --{other}" for other in flagged if other != on))
                for on, judge in flagged.items()]
        return super().get_params(ctx)

    def invoke(self, ctx):
        flags = [name for name in ctx.params if name.startswith(FLAG_PREFIX)]
        asked = [name[len(FLAG_PREFIX):] for name in flags if ctx.params.pop(name)]
        ctx.params["on"] = _on(asked, ctx.params.get("plot_dir"))
        return super().invoke(ctx)


def _on(asked: list[str], plot_dir) -> str:
    """What the flags ``asked`` ask to compare or fit: "cells" without one, else its word;
    BadInput for two, or one with --plot (the figures are of cells)."""
    if len(asked) > 1:
        raise BadInput(f"{', '.join('--' + on for on in asked)}: give one of them (each is compared apart)")
    on = asked[0] if asked else DEFAULT_ON
    if on != DEFAULT_ON and plot_dir is not None:
        raise BadInput(f"--plot: the figures are of the cells; leave it out with --{on}")
    return on


def _check_plot_dir(plot_dir) -> None:
    """BadInput unless the figures' directory ``plot_dir`` exists and takes files or can be made
    (checked before the work: a comparison or a fit can take minutes)."""
    if plot_dir is not None and (why := files.refusal(plot_dir, "--plot", directory=True)):
        raise BadInput(why)


@cli.command(cls=JudgedCommand)
@click.argument("table_path", metavar="TABLE.h5", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--model", "model_name", required=True, help=MODEL_HELP)
@click.option("--param", "params", multiple=True, metavar="KEY=VALUE", help="model parameter, repeatable")
@click.option("--order", type=click.Choice(list(ORDER_ROWS)), default="all", show_default=True,
              help="compare with one scattering order of the table, orders 1 and 2 together (1+2, the "
                   "f2 of two-bounce models), or the part of order 1 that the base scattered (1-base; "
                   "scenes with a base)")
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


@cli.command(cls=JudgedCommand)
@click.argument("table_path", metavar="TABLE.h5", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--model", "model_name", required=True, help=MODEL_HELP)
@click.option("--free", "free", multiple=True, metavar="KEY", help="parameter to fit, repeatable")
@click.option("--param", "params", multiple=True, metavar="KEY=VALUE",
              help="fixed model parameter, or the starting value of a free one; repeatable")
@click.option("--order", type=click.Choice(list(ORDER_ROWS)), default="all", show_default=True,
              help="fit one scattering order of the table (as for compare)")
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
