"""Command line (conventions §7): ``microsim run``, ``compare``, ``fit`` and ``models``.

Argument parsing and printing only: a run is :func:`microsim.app.session.run`, a comparison
:func:`microsim.analysis.compare.compare`, a fit :func:`microsim.analysis.fit.fit`. Bad input of any kind
(conventions §9) ends with one line on stderr naming the key or flag and what is accepted, exit
status 2, no traceback, and no output file; a run that fails ends in one line with status 1, and
one stopped by SIGINT, SIGTERM or SIGHUP says in one line how many units it kept for
``--resume`` and then dies of that signal (a shell reports 130, 143, 129; a shell loop stops on
Ctrl-C as it should). A signal that was ignored when microsim started stays ignored.
"""

from __future__ import annotations

import contextlib
import functools
import signal
import sys
from pathlib import Path

import click

from microsim.analysis.compare import ORDER_ROWS
from microsim.core import files
from microsim.core.choices import BACKEND_CHOICES, EXECUTORS, MAX_THREADS, MAX_WORKERS
from microsim.core.interrupts import Stopped, die_of, die_on_stop_signals, restore

# The modules of the work itself (config and geometry, numba, h5py, the models) are imported by
# each command as it needs them: --help, `models` and a refused argument answer without them.

EXIT_BAD_INPUT = 2

MODEL_HELP = ("analytic model: a name `microsim models` lists, or your own as module:Name or path.py:Name (a "
              "BRDFModel subclass, or a function f(wi, wo, **params) in 1/sr)")


class BadInput(click.ClickException):
    exit_code = EXIT_BAD_INPUT


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


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="microsim")
def cli():
    """microsim: ground-truth BRDF tables from explicit random microgeometry."""


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
            result = compare_module.compare(table, model, order, on=on)
        except ValueError as err:  # NaN or infinity in the model's values, data the table lacks (named)
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

    cls = _model_class(model_name)
    values = _model_parameters(params)
    _check_plot_dir(plot_dir)
    table = _load_table(table_path)
    with _user_model_errors(model_name), fit_status(cls.name) as status:
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
    _report(result.comparison, table, header, as_json, plot_dir, result.as_dict())


def _model_class(text: str):
    """The model class ``--model`` names (a registered model, module:Name or path.py:Name), or
    BadInput in one line."""
    from microsim.models import user_models

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


@cli.command()
@click.argument("table_path", metavar="TABLE.h5", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--format", "fmt", type=click.Choice(["merl", "netcdf-grid"]), required=True,
              help="merl: the MERL database's binary (90 x 90 x 180 half/difference angles, three float64 "
                   "channels); netcdf-grid: Eradiate's mqdiffuse layout, brdf(cos_theta_o, phi_d, cos_theta_i)")
@click.option("--out", "out", type=click.Path(dir_okay=False, path_type=Path),
              help="the file to write (default: TABLE with .binary or .nc)")
@click.option("--force", is_flag=True, help="overwrite --out if it exists")
def export(table_path, fmt, out, force):
    """Write the BRDF of a full-BRDF table (illumination.incidences) in a format other tools read,
    every node filled from its tabulated BRDF (microsim.models.tabulated); isotropic tables only."""
    from microsim.interop import exporters
    from microsim.models.tabulated import TabulatedBRDF

    out = out if out is not None else table_path.with_suffix(exporters.SUFFIXES[fmt])
    _check_output(out, force, {"the table": table_path})
    table = _load_table(table_path)
    try:
        exporters.export(TabulatedBRDF(table), fmt, out)
    except ValueError as err:  # not a full BRDF, or anisotropic: the message names the table
        raise BadInput(str(err)) from None
    click.echo(f"{fmt} written to {out}")


@cli.command("render")
@click.argument("table_path", metavar="TABLE.h5", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--model", "model_name", help="a model to render beside the table: " + MODEL_HELP)
@click.option("--param", "params", multiple=True, metavar="KEY=VALUE", help="model parameter, repeatable")
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="the picture to write, in the format of its suffix: .png, .jpg (.jpeg), .pdf or .svg")
@click.option("--force", is_flag=True, help="overwrite --out if it exists")
@click.option("--size", type=click.IntRange(16, 4096), default=256, show_default=True, help="pixels a side")
@click.option("--spp", type=click.IntRange(1, 65536), default=64, show_default=True, help="samples a pixel")
@click.option("--mesh", type=click.Path(dir_okay=False, path_type=Path),
              help="render this mesh (.ply, .obj; centred, its bounding box's longest side scaled to 2) instead "
                   "of the unit sphere")
def render_command(table_path, model_name, params, out, force, size, spp, mesh):
    """Render a full-BRDF table on a sphere under a directional light and a constant environment,
    beside a model and their relative difference (Mitsuba 3: the extra render, pip install -e
    '.[render]' in microsim's clone)."""
    from microsim.interop.render import FORMATS
    from microsim.models.tabulated import TabulatedBRDF

    _check_output(out, force, {"the table": table_path, "the mesh": mesh})
    if out.suffix.lower() not in FORMATS:
        raise BadInput(f"--out {out}: the format is taken from the suffix; accepted: {', '.join(FORMATS)}")
    if params and model_name is None:
        raise BadInput("--param: give --model, the model they are parameters of")
    if mesh is not None and (not mesh.is_file() or mesh.suffix.lower() not in (".ply", ".obj")):
        raise BadInput(f"--mesh {mesh}: {'not found' if not mesh.is_file() else 'accepted: a .ply or .obj file'}")
    from microsim.interop import mitsuba, render

    try:
        mitsuba.load()
    except ImportError as err:
        raise BadInput(f"render: {err}") from None
    table = _load_table(table_path)
    try:
        tabulated = TabulatedBRDF(table)
        tabulated.require_full_brdf()
    except ValueError as err:  # the message names the table
        raise BadInput(str(err)) from None
    model = None
    if model_name is not None:
        with _user_model_errors(model_name):
            try:
                model = _model_class(model_name)(**_model_parameters(params))
            except ValueError as err:
                raise BadInput(f"--model {model_name}: {err}") from None
    try:
        images = render.comparison(mitsuba.bsdf(tabulated), None if model is None else mitsuba.bsdf(model),
                                   size=size, spp=spp, mesh=mesh)
    except mitsuba.ModelRaised as err:  # the model's own error, which Mitsuba reports as "(see above)"
        if err.model is tabulated or ":" not in model_name:  # microsim's own: its traceback
            raise err.error from None
        raise BadInput(f"--model {model_name}: evaluating it raised {type(err.error).__name__}: "
                       f"{' '.join(str(err.error).split())}") from None
    except ValueError as err:  # a mesh Mitsuba cannot read
        raise BadInput(str(err)) from None
    render.figure(images, out, (f"table {table_path.name}", repr(model)))
    click.echo(f"render written to {out} (Mitsuba {mitsuba.variant()}, {size} x {size}, {spp} samples a pixel)")


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


def _check_output(out: Path, force: bool, inputs: dict) -> None:
    """BadInput, before the work, unless ``out`` can be written (:func:`microsim.core.files.refusal`):
    never over one of ``inputs``, with --force or not."""
    if why := files.refusal(out, force=force, inputs=inputs):
        raise BadInput(why)


def _load_table(table_path):
    """The table at ``table_path``, or BadInput in one line."""
    from microsim import tables

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

    from microsim.analysis import compare as compare_module

    if plot_dir is not None:
        from microsim.analysis import plots

        written = plots.write_all(result, table.sensor, plot_dir, table.path.name)
    if as_json:
        click.echo(json.dumps(json_object))
    elif isinstance(result, compare_module.PointComparison):
        _print_points(result, title)
    else:
        click.echo(f"{title} (order {result.order}; cells with signal: table > "
                   f"{compare_module.SIGNAL_TO_NOISE:g} standard errors; chi^2 per cell: 1 expected for the model "
                   f"of the table, {100 * (1 - compare_module.CHI2_OUTSIDE):g} % two-sided bounds; consistent: "
                   "within them, and the albedo's z^2 within its bound)")
        if result.model_errors:
            click.echo(f"errors (the z, the chi^2 and the +- of albedo sim): {result.model_errors}")
        click.echo(f"{'theta_i':>8} {'phi_i':>6} {'cells':>6} {'med|rel|':>9} {'rel rmse':>9} {'max|z|':>7} "
                   f"{'chi2/cell':>9} {'bounds':>14} {'albedo z^2':>10} {'bound':>6}  {'verdict':<12} "
                   f"{'albedo model':>12} "
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
    if getattr(result, "warning", None) and not as_json:
        click.echo(f"warning: {result.warning}", err=True)
    if plot_dir is not None and not as_json:
        click.echo(f"{len(written)} figures written to {plot_dir}")


def _print_points(result, title) -> None:
    """compare's per-incidence and overall figures at the points or on the retro rings."""
    from microsim.analysis import compare as compare_module

    unit, _, count, _ = compare_module.ON[result.on]
    rows = result.as_dict()
    hotelling = rows.get("points_statistic") == "hotelling" or "p_value_min" in rows["overall"]
    level = f"{100 * (1 - compare_module.CHI2_OUTSIDE):g} % two-sided"
    if hotelling:
        what = ("points: the model at each exact direction (next-event estimation); per incidence Hotelling's F of "
                f"the points with the covariance of their errors, {level} bounds (an incidence with too few "
                "realizations: chi^2 per point, bounds of 1 degree of freedom); overall: every incidence at the "
                "Bonferroni level")
    elif result.on == "points":
        what = ("points: the model at each exact direction (next-event estimation), every point but where both are "
                f"0; exact points (no spread) must match to {compare_module.EXACT_POINT:g}; chi^2 per point: 1 "
                "expected for the model of the table, bounds of 1 degree of freedom (the table holds no covariance "
                f"of the points' errors), {level}")
    else:
        what = (f"retro rings with signal: table > {compare_module.SIGNAL_TO_NOISE:g} standard errors; chi^2 per "
                f"ring: 1 expected for the model of the table, {level}")
    click.echo(f"{title} (order {result.order}; {what}; no albedo rows: the albedo sums the cells, not the {unit}s)")
    statistic = "F or chi2" if hotelling else f"chi2/{unit}"
    click.echo(f"{'theta_i':>8} {'phi_i':>6} {unit + 's':>6} {'med|rel|':>9} {'rel rmse':>9} {'max|z|':>9} "
               f"{statistic:>10} {'bounds':>18}{' p-value' if hotelling else ''}  verdict")
    for row in [*rows["per_incidence"], rows["overall"]]:
        where = (f"{row['theta_i_deg']:8.1f} {row['phi_i_deg']:6.1f}" if "theta_i_deg" in row
                 else f"{'overall':>8} {'':>6}")
        value, limits = row[f"chi2_per_{unit}"], row["chi2_bounds"]
        if "hotelling_f" in row:
            value, limits = row["hotelling_f"], row["hotelling_bounds"]
        p = ""
        if hotelling:
            p = f" {row['p_value']:8.2g}" if "p_value" in row else f" {row['p_value_min']:8.2g}"
        if value is None:  # no point with spread: each must equal the model
            shown, bounds = f"{'exact':>10}", f"|d| <= {compare_module.EXACT_POINT:g} f"
        else:
            shown, bounds = f"{value:10.3g}", f"[{limits[0]:.3g}, {limits[1]:.3g}]"
        if hotelling and "theta_i_deg" not in row:  # overall: the smallest p against Bonferroni's level
            shown, bounds = f"{'':>10}", f"p >= {row['bonferroni_level']:.3g}"
        click.echo(f"{where} {row[count]:6d} {row['median_abs_rel_err']:9.4f} {row['rel_rmse']:9.4f} "
                   f"{row['max_abs_z']:9.3g} {shown} {bounds:>18}{p}  {VERDICTS[row['consistent']]}")
    if rows.get("points_delta_lobes"):
        click.echo(f"not in the points (delta lobes next-event estimation does not see): {rows['points_delta_lobes']}")


@cli.command("models")
def list_models():
    """List the analytic models, their parameters with accepted values, and their references."""
    from microsim import models

    for line in models.listing():
        click.echo(line)


def main(argv=None) -> int:
    """Entry point of the ``microsim`` command: 0, or the exit status of its one-line error.

    A stop signal (SIGINT, SIGTERM, SIGHUP) ends the command in one line whenever it comes, and
    the process then dies of it. While a run traces and writes its tables, the session stops it
    cleanly (:class:`microsim.core.interrupts.StopOnSignals`); at any other time there is nothing to
    clean up, and the process dies at once (:func:`microsim.core.interrupts.die_on_stop_signals`).
    Where a caller of ``main`` left SIGINT to Python's KeyboardInterrupt, it is reported in the
    same line and ``main`` returns 130. The handlers are the caller's again when ``main`` returns
    or raises."""
    installed = die_on_stop_signals()
    try:
        cli.main(args=argv, prog_name="microsim", standalone_mode=False)
    except (KeyboardInterrupt, click.exceptions.Abort):
        click.echo("microsim: error: stopped by SIGINT", err=True)
        return 128 + signal.SIGINT
    except Stopped as err:
        restore(installed)
        click.echo(f"microsim: error: {err}", err=True)
        die_of(err.signum)
        return err.exit_code
    except click.ClickException as err:
        message = err.format_message().replace("\n", " ")
        click.echo(f"microsim: error: {message}", err=True)
        return EXIT_BAD_INPUT if isinstance(err, (click.UsageError, BadInput)) else err.exit_code
    finally:
        restore(installed)
    return 0


if __name__ == "__main__":
    sys.exit(main())
