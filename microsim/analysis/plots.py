"""PNG figures of a comparison: polar maps per incidence and the incidence-plane slice."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from microsim.core.frames import direction


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


#: a ring's cells are drawn with at least this many straight pieces around the circle
RING_PIECES = 96


def polar_cells(ax, sensor, values, cmap, norm):
    """Draw every sensor cell on polar axes (angle = phi, radius = theta in degrees): one
    pcolormesh per ring (a few ms each; a bar per cell is far slower: docs/developer/performance.md,
    'The time left and the figures'), each cell cut into enough pieces in phi that its arcs stay round."""
    edges = np.degrees(sensor.ring_theta_bounds())
    for k in range(sensor.n_rings):
        count, first = int(sensor.ring_counts[k]), int(sensor.ring_start[k])
        pieces = max(1, -(-RING_PIECES // count))
        phi = (np.arange(count * pieces + 1) / pieces - 0.5) * (2.0 * np.pi / count)
        row = np.repeat(np.ma.masked_invalid(values[first:first + count]), pieces)[None, :]
        ax.pcolormesh(phi, edges[:, k], row, cmap=cmap.with_extremes(bad="lightgrey"), norm=norm, shading="flat")
    ax.set_ylim(0, 90)
    ax.set_yticks([30, 60, 90])
    ax.set_yticklabels(["30", "60", "90"], fontsize=7)
    ax.set_rlabel_position(112.5)
    ax.tick_params(axis="x", labelsize=7)


def describe(comparison, i: int, table_name: str) -> str:
    """What a figure shows: the model with its parameters, the table, the order and the incidence."""
    params = ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in comparison.params.items())
    return (f"{comparison.model_name}({params}) vs {table_name}, order {comparison.order}, "
            f"theta_i = {np.degrees(comparison.theta_i[i]):.1f} deg, phi_i = {np.degrees(comparison.phi_i[i]):.1f} deg")


def polar_maps(comparison, sensor, i: int, path: Path, table_name: str = "table") -> None:
    """Simulation, model, relative error and z on the hemisphere for incidence ``i`` (z: the
    difference over the cell's standard deviation if the model were right, as chi-square per
    cell takes it, table_noise.predicted_variance); colour bars below the maps, so that nothing
    hides the backscatter mark at the rim."""
    plt = _pyplot()
    from matplotlib import colors

    sim, model, ok = comparison.sim[i], comparison.model[i], comparison.signal[i]
    rel = np.where(ok, (model - sim) / np.where(sim > 0, sim, 1.0), np.nan)
    z = np.where(ok, (model - sim) / np.sqrt(comparison.variance[i]), np.nan)
    top = np.nanmax(np.concatenate([sim[ok], model[ok]])) if ok.any() else 1.0
    fig, axes = plt.subplots(1, 4, subplot_kw={"projection": "polar"}, figsize=(17, 5.4))
    value_norm = colors.Normalize(0.0, top)
    limit = max(0.05, float(np.nanpercentile(np.abs(rel), 95))) if ok.any() else 0.1
    error_norm = colors.Normalize(-limit, limit)
    z_limit = max(3.0, float(np.nanpercentile(np.abs(z), 99))) if ok.any() else 3.0
    for ax, values, norm, cmap, title, label in (
        (axes[0], sim, value_norm, plt.cm.viridis, "simulation", "f (1/sr)"),
        (axes[1], model, value_norm, plt.cm.viridis, f"model {comparison.model_name}", "f (1/sr)"),
        (axes[2], rel, error_norm, plt.cm.RdBu_r, "(model - sim) / sim",
         f"scale clipped at +-{limit:.3g} (95th percentile of |error|, at least 0.05)"),
        (axes[3], z, colors.Normalize(-z_limit, z_limit), plt.cm.PuOr_r, "z = (model - sim) / sd",
         f"sd: the cell's if the model were right; scale +-{z_limit:.3g} (99th percentile, at least 3)"),
    ):
        polar_cells(ax, sensor, values, cmap, norm)
        ax.set_title(title, fontsize=10, pad=14)
        bar = fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax, orientation="horizontal",
                           shrink=0.8, pad=0.1)
        bar.set_label(label, fontsize=7)
        bar.ax.tick_params(labelsize=7)
    phi_i = comparison.phi_i[i]
    for ax in axes:
        ax.plot([phi_i], [np.degrees(comparison.theta_i[i])], marker="*", color="red", ms=11, mec="white",
                zorder=5, clip_on=False)
    fig.suptitle(f"{describe(comparison, i, table_name)}\nradius: theta_o (deg), angle: phi_o; red star: backscatter "
                 "direction; grey cells: no signal", fontsize=10)
    fig.subplots_adjust(top=0.8, bottom=0.02, left=0.03, right=0.97)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def incidence_plane(comparison, sensor, i: int, path: Path, table_name: str = "table") -> None:
    """Cells on the plane of incidence: simulation with error bars, model, against signed theta_o.

    theta_o is negative on the backscatter side (phi = phi_i) and positive on the specular side.
    """
    plt = _pyplot()
    x, cell = incidence_plane_cells(sensor, comparison.phi_i[i])
    fig, ax = plt.subplots(figsize=(7, 4.2))
    ax.errorbar(x, comparison.sim[i, cell], yerr=comparison.stderr[i, cell], fmt="o", ms=3, capsize=2,
                label="simulation (cell average)")
    ax.plot(x, comparison.model[i, cell], "-", label=f"model {comparison.model_name} (cell average)")
    ax.axvline(-np.degrees(comparison.theta_i[i]), color="grey", ls=":", lw=1, label="retro direction")
    ax.set_xlabel("theta_o (deg): backscatter side < 0 < specular side")
    ax.set_ylabel("f (1/sr)")
    ax.set_title(f"plane of incidence: {describe(comparison, i, table_name)}", fontsize=8)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def incidence_plane_cells(sensor, phi_i: float):
    """(signed theta_o in degrees, cell) of the cells on the plane of incidence at azimuth phi_i,
    one per ring and side, sorted: theta_o < 0 on the backscatter side (phi = phi_i)."""
    theta = sensor.ring_centres()
    rings = np.arange(sensor.n_rings)
    xs, cells = [], []
    for side, sign in ((phi_i, -1.0), (phi_i + np.pi, 1.0)):
        w = direction(theta, side)
        w[0] = [0.0, 0.0, 1.0]
        cell = sensor.lookup(w)
        keep = rings if sign < 0 else rings[1:]
        xs.append(sign * np.degrees(theta[keep]))
        cells.append(cell[keep])
    x, cell = np.concatenate(xs), np.concatenate(cells)
    order = np.argsort(x)
    return x[order], cell[order]


def write_all(comparison, sensor, directory: Path, table_name: str = "table") -> list[Path]:
    """Both figures for every incidence, titled with the model and its parameters, the table
    ``table_name``, the order and the incidence, and named by model, order, incidence number,
    theta_i and phi_i (distinct for distinct incidences and orders); returns the files written."""
    directory.mkdir(parents=True, exist_ok=True)
    written = []
    for i, (theta, phi) in enumerate(zip(comparison.theta_i, comparison.phi_i)):
        stem = (f"{comparison.model_name}_order{comparison.order}_i{i:02d}_theta{np.degrees(theta):05.1f}"
                f"_phi{np.degrees(phi):05.1f}")
        for kind, draw in (("polar", polar_maps), ("plane", incidence_plane)):
            path = directory / f"{stem}_{kind}.png"
            draw(comparison, sensor, i, path, table_name)
            written.append(path)
    return written
