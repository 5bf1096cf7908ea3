"""PNG figures of a comparison: polar maps per incidence and the incidence-plane slice."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .frames import direction


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _polar_cells(ax, sensor, values, cmap, norm):
    """Draw every sensor cell as a polar bar: angle = phi, radius = theta in degrees."""
    t_lo, t_hi, p_lo, p_hi = sensor.cell_bounds()
    colours = cmap.with_extremes(bad="lightgrey")(norm(np.ma.masked_invalid(values)))
    ax.bar(0.5 * (p_lo + p_hi), np.degrees(t_hi - t_lo), width=p_hi - p_lo, bottom=np.degrees(t_lo),
           color=colours, edgecolor="none", align="center")
    ax.set_ylim(0, 90)
    ax.set_yticks([30, 60, 90])
    ax.set_yticklabels(["30", "60", "90"], fontsize=7)
    ax.tick_params(axis="x", labelsize=7)


def polar_maps(comparison, sensor, i: int, path: Path) -> None:
    """Simulation, model and relative error on the hemisphere for incidence ``i``."""
    plt = _pyplot()
    from matplotlib import colors

    sim, model, ok = comparison.sim[i], comparison.model[i], comparison.signal[i]
    rel = np.where(ok, (model - sim) / np.where(sim > 0, sim, 1.0), np.nan)
    top = np.nanmax(np.concatenate([sim[ok], model[ok]])) if ok.any() else 1.0
    fig, axes = plt.subplots(1, 3, subplot_kw={"projection": "polar"}, figsize=(13, 4.4))
    value_norm = colors.Normalize(0.0, top)
    limit = max(0.05, float(np.nanpercentile(np.abs(rel), 95))) if ok.any() else 0.1
    error_norm = colors.Normalize(-limit, limit)
    for ax, values, norm, cmap, title in (
        (axes[0], sim, value_norm, plt.cm.viridis, "simulation f (1/sr)"),
        (axes[1], model, value_norm, plt.cm.viridis, f"model {comparison.model_name}"),
        (axes[2], rel, error_norm, plt.cm.RdBu_r, "(model - sim) / sim"),
    ):
        _polar_cells(ax, sensor, values, cmap, norm)
        ax.set_title(title, fontsize=10)
        fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax, shrink=0.75)
    phi_i = comparison.phi_i[i]
    for ax in axes:
        ax.plot([phi_i], [np.degrees(comparison.theta_i[i])], marker="*", color="red", ms=10)
    fig.suptitle(f"theta_i = {np.degrees(comparison.theta_i[i]):.1f} deg (red star: retro direction; "
                 f"grey cells: no signal)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def incidence_plane(comparison, sensor, i: int, path: Path) -> None:
    """Cells on the plane of incidence: simulation with error bars, model, against signed theta_o.

    theta_o is negative on the backscatter side (phi = phi_i) and positive on the specular side.
    """
    plt = _pyplot()
    phi_i = comparison.phi_i[i]
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
    x, cell = x[order], cell[order]
    fig, ax = plt.subplots(figsize=(7, 4.2))
    ax.errorbar(x, comparison.sim[i, cell], yerr=comparison.stderr[i, cell], fmt="o", ms=3, capsize=2,
                label="simulation (cell average)")
    ax.plot(x, comparison.model[i, cell], "-", label=f"model {comparison.model_name} (cell average)")
    ax.axvline(-np.degrees(comparison.theta_i[i]), color="grey", ls=":", lw=1, label="retro direction")
    ax.set_xlabel("theta_o (deg): backscatter side < 0 < specular side")
    ax.set_ylabel("f (1/sr)")
    ax.set_title(f"plane of incidence, theta_i = {np.degrees(comparison.theta_i[i]):.1f} deg")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def write_all(comparison, sensor, directory: Path) -> list[Path]:
    """Both figures for every incidence; returns the files written."""
    directory.mkdir(parents=True, exist_ok=True)
    written = []
    for i, theta in enumerate(comparison.theta_i):
        stem = f"{comparison.model_name}_theta{np.degrees(theta):05.1f}"
        for kind, draw in (("polar", polar_maps), ("plane", incidence_plane)):
            path = directory / f"{stem}_{kind}.png"
            draw(comparison, sensor, i, path)
            written.append(path)
    return written
