"""What ``compare`` and ``fit`` print: the per-incidence and overall figures of a comparison (or
its JSON object), and the figures written."""

from __future__ import annotations

import click

#: compare's verdict, by its JSON value
VERDICTS = {True: "consistent", False: "inconsistent", None: "n/a"}


def print_comparison(result, table, title, as_json, plot_dir, json_object) -> None:
    """compare's per-incidence and overall figures (or ``json_object``), and its figures."""
    import json

    from microsim.analysis.point_comparison import PointComparison
    from microsim.analysis.selection import SIGNAL_TO_NOISE
    from microsim.core.table_noise import CHI2_OUTSIDE

    if plot_dir is not None:
        from microsim.analysis import plots

        written = plots.write_all(result, table.sensor, plot_dir, table.path.name)
    if as_json:
        click.echo(json.dumps(json_object))
    elif isinstance(result, PointComparison):
        _print_points(result, title)
    else:
        click.echo(f"{title} (order {result.order}; cells with signal: table > "
                   f"{SIGNAL_TO_NOISE:g} standard errors; chi^2 per cell: 1 expected for the model "
                   f"of the table, {100 * (1 - CHI2_OUTSIDE):g} % two-sided bounds; consistent: "
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
    from microsim.analysis.point_comparison import EXACT_POINT

    unit, count = result.unit, result.counted
    rows = result.as_dict()
    hotelling = rows.get("points_statistic") == "hotelling" or "p_value_min" in rows["overall"]
    what = result.summary()
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
            shown, bounds = f"{'exact':>10}", f"|d| <= {EXACT_POINT:g} f"
        else:
            shown, bounds = f"{value:10.3g}", f"[{limits[0]:.3g}, {limits[1]:.3g}]"
        if hotelling and "theta_i_deg" not in row:  # overall: the smallest p against Bonferroni's level
            shown, bounds = f"{'':>10}", f"p >= {row['bonferroni_level']:.3g}"
        click.echo(f"{where} {row[count]:6d} {row['median_abs_rel_err']:9.4f} {row['rel_rmse']:9.4f} "
                   f"{row['max_abs_z']:9.3g} {shown} {bounds:>18}{p}  {VERDICTS[row['consistent']]}")
    if rows.get("points_delta_lobes"):
        click.echo(f"not in the points (delta lobes next-event estimation does not see): {rows['points_delta_lobes']}")
