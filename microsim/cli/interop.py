"""``microsim export`` and ``render``: a full-BRDF table written in other tools' formats
(:mod:`microsim.interop.exporters`), or rendered beside a model (:mod:`microsim.interop.render`)."""

from __future__ import annotations

from pathlib import Path

import click

from microsim.cli.entry import BadInput, cli
from microsim.cli.inputs import MODEL_HELP, check_output, load_table, model_class, model_parameters, user_model_errors


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
    check_output(out, force, {"the table": table_path})
    table = load_table(table_path)
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

    check_output(out, force, {"the table": table_path, "the mesh": mesh})
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
    table = load_table(table_path)
    try:
        tabulated = TabulatedBRDF(table)
        tabulated.require_full_brdf()
    except ValueError as err:  # the message names the table
        raise BadInput(str(err)) from None
    model = None
    if model_name is not None:
        with user_model_errors(model_name):
            try:
                model = model_class(model_name)(**model_parameters(params))
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
