"""Gaussian random surfaces against microfacet theory: where Smith's masking holds, and where the
V-cavity one does.

Surfaces: scene heightfield, generator = "gaussian" (geometry/gaussian_surface.py), Beckmann
alpha in ALPHAS (facets' slope variance alpha^2 / 2 an axis), correlation length 1, the default
grid (8 samples a correlation length) and tile; conductor facets (eta + ik = 0.2 + 3.9i, as
runs/vcavities_conductor.toml), theta_i in THETAS, 900 cells, all orders, statistics = true
(every realization's NDF, visible NDF and G1: geometry/surface_statistics.py).

What is charted (benchmarks/out/gaussian_surfaces.png, .json):

(a) The NDF. The measured D (cells' plain averages over the realizations) against Beckmann with
    the requested alpha, and the facets' measured alpha (sqrt(2 <slope^2>) an axis; its mean
    and standard error over the realizations). The cells of one realization move together (a
    rougher realization moves them all), so chi-square per cell is a summary here; the test of
    the NDF is tests/test_gaussian_surface.py (Hotelling's T^2 on moments and bins).
(b) Single scattering (order 1) against the ``microfacet`` model with the surface's own D
    (Beckmann at the measured alpha, which (a) shows is the D of the facets) and three G:
    Smith's separable G1(i) G1(o), Smith's height-correlated G2 (both from Beckmann's Lambda)
    and the V-cavity (Torrance-Sparrow) G; chi-square per cell and median |rel| per alpha and
    theta_i (``microsim.analysis.compare``: cells with signal, the cell's predicted variance).
(c) Masking: the measured G1(wo, m) = D_wo(m) cos(theta_o) / (<wo.m> D(m)) of facets of normal m
    in the plane of wo, at theta_o = 75 and 85 deg, against Smith's 1 / (1 + Lambda(wo)) (the
    same for every m) and the V-cavity min(1, 2 (n.m)(n.wo) / (wo.m)); and the chi-square per
    cell of the visible NDF against each model at every alpha and theta_o.
(d) What multiple scattering adds: (albedo of all orders - order 1) / all orders, the quantity
    Heitz et al. 2016 model, per alpha and theta_i.

    python benchmarks/gaussian_surfaces.py [--quick] [--json]
    python benchmarks/gaussian_surfaces.py --convergence   (the default grid's measurement)

Full: PATHS paths an incidence, REALIZATIONS realizations; --quick: a tenth of the paths.
--convergence: a mirror surface, alpha 0.8, tile 16, theta_i 0/60/80, 100 cells, at 2 to 24
samples a correlation length, each against the finest; and the visible NDF of alpha 0.8 against
Smith's at 8 and 16 samples (is Smith's error the grid's? no: docs/developer/performance.md);
and the tile's bias at grazing incidence (tiles 8 to 55 correlation lengths, mirror, alpha 0.8).
Writes benchmarks/out/gaussian_surface_grid.json.
"""

from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path

import numpy as np
from report import OUT, save_figures

from microsim import config, geometry, tables
from microsim.analysis import compare
from microsim.app import session
from microsim.core.frames import direction
from microsim.physics import distributions as nd
from microsim.physics.rng import geometry_rng
from microsim.tracer.sensor import Sensor

ALPHAS = (0.1, 0.3, 0.5, 0.8, 1.0)
THETAS = (0.0, 30.0, 60.0, 75.0, 85.0)
GAFS = ("smith", "smith_height_correlated", "torrance_sparrow")
ETA, K = 0.2, 3.9
PATHS = 2_000_000
REALIZATIONS = 32
CELLS = 900
#: shadow rays a masking direction and realization (surface_statistics)
STATISTICS_RAYS = 65536
#: the masking directions whose G1 profile panel (c) draws
PROFILE_THETAS = (75.0, 85.0)


def surface_config(alpha: float, paths: int, seed: int) -> dict:
    return {"scene": {"kind": "heightfield", "generator": "gaussian", "roughness": alpha, "statistics": True,
                      "statistics_rays": STATISTICS_RAYS},
            "material": {"kind": "conductor", "eta": ETA, "k": K},
            "illumination": {"theta_i_deg": list(THETAS)}, "sensor": {"cells": CELLS},
            "run": {"paths": paths, "realizations": REALIZATIONS, "seed": seed, "max_order": 0}}


def plain_average(sensor, func, nodes: int = 8) -> np.ndarray:
    """Solid-angle average of ``func(w (M, 3))`` over each cell (the NDF's cell value)."""
    w, weight = sensor.cell_quadrature(nodes, nodes)
    weight = weight / w[:, :, 2]
    weight /= weight.sum(axis=1, keepdims=True)
    return np.sum(func(w.reshape(-1, 3)).reshape(weight.shape) * weight, axis=1)


def vcavity_g1(wo, m):
    """min(1, 2 (n.m)(n.wo) / (wo.m)) where wo.m > 0, else 0."""
    wo_m = m @ wo
    return np.where(wo_m > 0.0, np.minimum(1.0, 2.0 * m[:, 2] * wo[2] / np.where(wo_m > 0.0, wo_m, 1.0)), 0.0)


def mean_and_stderr(values: np.ndarray):
    return values.mean(axis=0), values.std(axis=0, ddof=1) / math.sqrt(len(values))


def chi2_per_cell(measured, stderr, model) -> float:
    """Mean z^2 over the cells where the measurement or the model is above 3 standard errors (a
    selection on the measurement alone would keep its upward fluctuations)."""
    signal = (stderr > 0.0) & (np.maximum(measured, model) > 3.0 * stderr)
    return float(np.mean(((measured - model)[signal] / stderr[signal]) ** 2))


def tilted_shares(vndf: np.ndarray, smith: np.ndarray, sensor, wo) -> dict:
    """The visible NDF of the facets tilted towards wo (m_xy . wo_xy > 0) and away from it, each
    summed over its cells, over Smith's: mean and standard error over the realizations (rows of
    ``vndf``; Smith's is the same for every one)."""
    toward = sensor.directions()[:, :2] @ wo[:2] > 0.0
    out = {}
    for name, side in (("toward", toward), ("away", ~toward)):
        if smith[side].sum() > 0.0:
            ratio = vndf[:, side].sum(axis=1) / smith[side].sum()
            out[f"seen_over_smith_{name}"], out[f"seen_over_smith_{name}_stderr"] = map(float, mean_and_stderr(ratio))
    return out


def surface_figures(alpha: float, table) -> dict:
    sensor = table.sensor
    scene = {key.removeprefix("scene/"): value for key, value in table.arrays.items() if key.startswith("scene/")}
    ax = float(np.mean(scene["measured_roughness_x"]))
    ay = float(np.mean(scene["measured_roughness_y"]))
    alpha_se = float(np.std(np.hypot(scene["measured_roughness_x"], scene["measured_roughness_y"]) / math.sqrt(2),
                            ddof=1) / math.sqrt(len(scene["measured_roughness_x"])))
    ndf, ndf_se = mean_and_stderr(np.asarray(scene["ndf"]))
    beckmann = plain_average(sensor, lambda m: nd.ndf("beckmann", alpha, alpha, m))
    out = {"alpha": alpha, "measured_alpha": [ax, ay], "measured_alpha_stderr": alpha_se,
           "ndf_chi2_per_cell": chi2_per_cell(ndf, ndf_se, beckmann),
           "ndf_median_abs_rel": float(np.median(np.abs(ndf - beckmann)[ndf > 3 * ndf_se] / beckmann[ndf > 3 * ndf_se]))}
    # (b) order 1 against the microfacet model with the measured D and each G
    out["order1"] = {}
    for gaf in GAFS:
        result = compare.compare(table, "microfacet", order="1", distribution="beckmann", roughness_x=ax,
                                 roughness_y=ay, gaf=gaf, eta=ETA, k=K)
        out["order1"][gaf] = [{"theta_i": float(THETAS[i]), **{key: result.metrics(i)[key] for key in
                               ("chi2_per_cell", "chi2_bounds", "median_abs_rel_err", "cells_with_signal")}}
                              for i in range(len(THETAS))]
    # (c) the visible NDF and G1 against Smith and the V-cavity
    vndf = np.asarray(scene["vndf"])
    directions = np.asarray(table.scene["statistics_directions_deg"])
    out["masking"] = []
    for k, (theta, phi) in enumerate(directions):
        wo = direction(math.radians(theta), math.radians(phi))
        measured, se = mean_and_stderr(vndf[:, k])
        smith_g1 = float(1.0 / (1.0 + nd.smith_lambda("beckmann", ax, ay, wo[None])[0]))
        projected = plain_average(sensor, lambda m: np.maximum(m @ wo, 0.0) * nd.ndf("beckmann", ax, ay, m) / wo[2])
        vcavity = plain_average(sensor, lambda m: vcavity_g1(wo, m) * np.maximum(m @ wo, 0.0)
                                * nd.ndf("beckmann", ax, ay, m) / wo[2])
        g1, g1_se = mean_and_stderr(np.asarray(scene["g1"])[:, k])
        entry = {"theta_o": float(theta), "phi_o": float(phi), "g1": float(g1), "g1_stderr": float(g1_se),
                 "g1_exact": float(np.mean(math.cos(math.radians(theta)) / np.asarray(scene["facing_area"])[:, k])),
                 "g1_smith": smith_g1,
                 "vndf_chi2_smith": chi2_per_cell(measured, se, smith_g1 * projected),
                 "vndf_chi2_vcavity": chi2_per_cell(measured, se, vcavity),
                 **tilted_shares(vndf[:, k], smith_g1 * projected, sensor, wo)}
        if theta in PROFILE_THETAS and phi == 0.0:  # cells near the plane of wo: G1(wo, m) by the signed tilt of m
            rays, free = (np.asarray(scene[name])[:, k].sum(axis=0) for name in ("g1_rays", "g1_free"))
            d = sensor.directions()
            keep = (np.abs(d[:, 1]) < 0.2 * np.hypot(d[:, 0], d[:, 1]) + 1e-9) & (rays >= 100)
            tilt = np.degrees(np.arctan2(np.hypot(d[:, 0], d[:, 1]), d[:, 2])) * np.sign(d[:, 0])
            order = np.argsort(tilt[keep])
            seen = free[keep] / rays[keep]  # pooled over the realizations: no model in it
            entry["profile"] = {"tilt_deg": tilt[keep][order].tolist(), "g1": seen[order].tolist(),
                                "g1_stderr": np.sqrt(seen * (1 - seen) / rays[keep])[order].tolist(),
                                "vcavity": vcavity_g1(wo, d[keep])[order].tolist()}
        out["masking"].append(entry)
    # (d) multiple scattering
    order1 = table.arrays["albedo_order"][:, 0]
    out["multiple_share"] = ((table.albedo - order1) / table.albedo).tolist()
    out["albedo_all"] = table.albedo.tolist()
    out["albedo_all_stderr"] = table.albedo_stderr.tolist()
    out["tile"] = float(table.scene["tile"])
    out["triangles"] = int(table.scene["surface_triangles"])
    out["wall_time_s"] = float(table.attrs["wall_time_s"])
    return out


def convergence(folder: Path) -> dict:
    """Albedo by order at 2 .. 24 samples a correlation length, each against 24 (module doc)."""
    out = {}
    for samples in (2, 4, 6, 8, 12, 16, 24):
        cfg = {"scene": {"kind": "heightfield", "generator": "gaussian", "roughness": 0.8, "pixel": 1.0 / samples,
                         "tile": 16.0},
               "material": {"kind": "mirror"}, "illumination": {"theta_i_deg": [0.0, 60.0, 80.0]},
               "sensor": {"cells": 100}, "run": {"paths": 1_600_000, "realizations": 32, "seed": 12}}
        table = tables.load(session.run(cfg, folder / f"grid{samples}.h5", threads=1, force=True).tables[0])
        out[samples] = {"albedo": table.arrays["albedo_order"].tolist(),
                        "albedo_stderr": table.arrays["albedo_order_stderr"].tolist(),
                        "wall_time_s": float(table.attrs["wall_time_s"])}
    finest = out[24]
    for samples, entry in out.items():
        entry["z_against_24"] = ((np.array(entry["albedo"]) - finest["albedo"])
                                 / np.hypot(entry["albedo_stderr"], finest["albedo_stderr"])).tolist()
    return {"albedo_by_order": out, "masking_against_smith": {samples: masking_against_smith(0.8, samples)
                                                             for samples in (8, 16)},
            "tile": tile_bias(folder)}


def tile_bias(folder: Path) -> dict:
    """Mirror, alpha 0.8, theta_i 85 and 60 deg, tiles 8, 16, 27.625 (the default) and 55.25
    correlation lengths, each against 55.25: chi-square per cell of all orders (both errors) and
    the order-1 albedo's relative difference and z (docs/developer/performance.md)."""
    runs = {}
    for tile in (8.0, 16.0, 27.625, 55.25):
        cfg = {"scene": {"kind": "heightfield", "generator": "gaussian", "roughness": 0.8, "tile": tile},
               "material": {"kind": "mirror"}, "illumination": {"theta_i_deg": [85.0, 60.0]}, "sensor": {"cells": 100},
               "run": {"paths": 3_200_000, "realizations": 32, "seed": 21}}
        runs[tile] = tables.load(session.run(cfg, folder / f"tile{tile}.h5", threads=1, force=True).tables[0])
    longest = runs[55.25]
    out = {}
    for tile, table in runs.items():
        z = (table.brdf - longest.brdf) / np.hypot(table.brdf_stderr, longest.brdf_stderr)
        signal = longest.brdf > 3.0 * longest.brdf_stderr
        order1, order1_se = table.arrays["albedo_order"][:, 0], table.arrays["albedo_order_stderr"][:, 0]
        reference, reference_se = longest.arrays["albedo_order"][:, 0], longest.arrays["albedo_order_stderr"][:, 0]
        out[tile] = {"chi2_per_cell": [float(np.mean(z[i][signal[i]] ** 2)) for i in range(2)],
                     "order1_albedo_rel": ((order1 - reference) / longest.albedo).tolist(),
                     "order1_albedo_z": ((order1 - reference) / np.hypot(order1_se, reference_se)).tolist(),
                     "wall_time_s": float(table.attrs["wall_time_s"])}
    return out


def masking_against_smith(alpha: float, samples: int) -> list[dict]:
    """The visible NDF of REALIZATIONS surfaces of ``alpha`` at ``samples`` a correlation length
    (no paths traced) against Smith's: chi-square per cell, and the measured over Smith's visible
    share of the facets tilted towards wo and away from it (module doc (c))."""
    cfg = config.validate({"scene": {"kind": "heightfield", "generator": "gaussian", "roughness": alpha,
                                     "pixel": 1.0 / samples, "statistics": True, "statistics_rays": STATISTICS_RAYS},
                           "material": {"kind": "mirror"}, "illumination": {"theta_i_deg": [0.0]},
                           "sensor": {"cells": CELLS}, "run": {"paths": 1000}})
    generator = geometry.SCENES["heightfield"]
    resolved = generator.resolve(cfg)
    infos = [generator.generate(resolved, cfg, geometry_rng(77, r)).info for r in range(REALIZATIONS)]
    sensor = Sensor.build(CELLS)
    ax, ay = (float(np.mean([info[f"measured_roughness_{axis}"] for info in infos])) for axis in "xy")
    rows = []
    for k, (theta, phi) in enumerate(resolved["statistics_directions_deg"]):
        wo = direction(math.radians(theta), math.radians(phi))
        measured, se = mean_and_stderr(np.array([info["vndf"][k] for info in infos]))
        smith = plain_average(sensor, lambda m: np.maximum(m @ wo, 0.0) * nd.ndf("beckmann", ax, ay, m) / wo[2]) \
            / (1.0 + nd.smith_lambda("beckmann", ax, ay, wo[None])[0])
        rows.append({"theta_o": float(theta), "chi2_per_cell": chi2_per_cell(measured, se, smith),
                     **tilted_shares(np.array([info["vndf"][k] for info in infos]), smith, sensor, wo)})
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--convergence", action="store_true")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        if args.convergence:
            save_figures(convergence(folder), "gaussian_surface_grid", args.json)
            return
        paths = PATHS // 10 if args.quick else PATHS
        figures = {"paths": paths, "realizations": REALIZATIONS, "cells": CELLS, "eta": ETA, "k": K, "surfaces": []}
        for n, alpha in enumerate(ALPHAS):
            table = tables.load(session.run(surface_config(alpha, paths, 1 + n), folder / f"alpha{alpha}.h5",
                                            threads=1, force=True).tables[0])
            figures["surfaces"].append(surface_figures(alpha, table))
            print(f"alpha {alpha}: done in {figures['surfaces'][-1]['wall_time_s']:.0f} s", flush=True)
    save_figures(figures, "gaussian_surfaces", args.json)
    plot(figures)


def plot(figures):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    surfaces = figures["surfaces"]
    fig, axes = plt.subplots(2, 3, figsize=(16, 9.5))
    # (a) measured alpha against requested
    ax = axes[0, 0]
    requested = [s["alpha"] for s in surfaces]
    measured = [np.mean(s["measured_alpha"]) for s in surfaces]
    ax.errorbar(requested, np.array(measured) / requested, [3 * s["measured_alpha_stderr"] / s["alpha"] for s in surfaces],
                fmt="o", capsize=3, label="facets' alpha / requested (3 se)")
    ax.axhline(1.0, color="k", lw=0.8)
    ax.text(0.03, 0.03, "NDF against Beckmann, chi2 per cell:\n" + "\n".join(
        f"alpha {s['alpha']:g}: {s['ndf_chi2_per_cell']:.2f}" for s in surfaces), transform=ax.transAxes, fontsize=7)
    ax.set(xlabel="requested alpha", ylabel="measured / requested", title="(a) the NDF: Beckmann with the requested alpha")
    ax.legend(fontsize=8)
    # (b) order 1: chi2 per cell per G
    for col, gaf, title in ((1, "smith_height_correlated", "Smith, height-correlated G2"),
                            (2, "torrance_sparrow", "V-cavity G")):
        ax = axes[0, col]
        grid = np.array([[row["chi2_per_cell"] for row in s["order1"][gaf]] for s in surfaces])
        image = ax.imshow(np.log10(grid), origin="lower", cmap="magma", vmin=-0.3, vmax=3.0, aspect="auto")
        for i in range(grid.shape[0]):
            for j in range(grid.shape[1]):
                rel = surfaces[i]["order1"][gaf][j]["median_abs_rel_err"]
                ax.text(j, i, f"{grid[i, j]:.3g}\n{100 * rel:.2g}%", ha="center", va="center", fontsize=7,
                        color="w" if np.log10(grid[i, j]) < 2 else "k")
        ax.set_xticks(range(len(THETAS)), [f"{t:g}" for t in THETAS])
        ax.set_yticks(range(len(surfaces)), [f"{a:g}" for a in requested])
        ax.set(xlabel="theta_i (deg)", ylabel="alpha", title=f"(b) order 1 vs microfacet, {title}:\n"
                                                             "chi2 per cell, median |rel|")
        fig.colorbar(image, ax=ax, label="log10 chi2 per cell")
    # (c) G1 profiles
    ax = axes[1, 0]
    for n, s in enumerate(surfaces[2:]):
        for entry in s["masking"]:
            if "profile" in entry and entry["theta_o"] == 85.0:
                p = entry["profile"]
                line = ax.errorbar(p["tilt_deg"], p["g1"], 3 * np.array(p["g1_stderr"]), fmt="o", ms=3, capsize=2,
                                   label=f"alpha {s['alpha']:g}: measured (3 se), Smith (line)")
                ax.axhline(entry["g1_smith"], color=line[0].get_color(), lw=1)
                if n == 0:  # the V-cavity G1 depends on wo and m only
                    ax.plot(p["tilt_deg"], p["vcavity"], "k--", lw=1, label="V-cavity (every alpha)")
    ax.set(xlabel="facet tilt in the plane of wo (deg; + towards wo)", ylabel="G1(wo, m)", ylim=(0, 1.05),
           title="(c) masking at theta_o = 85 deg, by facet normal")
    ax.legend(fontsize=7, ncol=2)
    # (c') visible NDF chi2 per cell
    ax = axes[1, 1]
    for s in surfaces:
        thetas = [e["theta_o"] for e in s["masking"]]
        line, = ax.semilogy(thetas, [max(e["vndf_chi2_smith"], 1e-2) for e in s["masking"]], "o-",
                            label=f"alpha {s['alpha']:g} Smith")
        ax.semilogy(thetas, [max(e["vndf_chi2_vcavity"], 1e-2) for e in s["masking"]], "s--",
                    color=line.get_color(), label="V-cavity")
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set(xlabel="theta_o (deg)", ylabel="chi2 per cell", title="(c) visible NDF against Smith and V-cavity")
    ax.legend(fontsize=7, ncol=2)
    # (d) multiple scattering
    ax = axes[1, 2]
    for s in surfaces:
        ax.plot(THETAS, 100 * np.array(s["multiple_share"]), "o-", label=f"alpha {s['alpha']:g}")
    ax.set(xlabel="theta_i (deg)", ylabel="orders >= 2, % of the albedo", title="(d) what multiple scattering adds")
    ax.legend(fontsize=8)
    fig.suptitle(f"Gaussian random surfaces, conductor {ETA} + {K}i: {figures['paths']:.3g} paths an incidence, "
                 f"{figures['realizations']} realizations, {figures['cells']} cells")
    fig.tight_layout()
    for path in (OUT / "gaussian_surfaces.png", Path(__file__).resolve().parents[1] / "docs/validation/img/gaussian_surfaces.png"):
        fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
