"""Single scattering of mirror Gaussian surfaces against Smith's height-correlated model, and the
masking by facet normal that makes the model under-predict it.

Surfaces: scene heightfield, generator = "gaussian" (geometry/gaussian_surface.py), Beckmann
alpha in ALPHAS, correlation length 1, the default grid (8 samples a correlation length), a tile
of TILE correlation lengths (above the tile's bias floor, 6 sigma tan(theta_i), up to alpha 1
and theta_i 75 deg: docs/developer/performance.md; longer than the default to shrink the
realizations' spread), mirror facets (F = 1), theta_i in THETAS,
max_order = 1 (the paths end at their second hit: order 1 is all that is tallied), with
statistics = true (every realization's G1 by facet normal, geometry/surface_statistics.py).

(a) The order-1 albedo against the integral over the hemisphere of the microfacet BRDF with
    Beckmann's D at the requested alpha (the generator's facets have exactly its slope
    variance), Smith's height-correlated G2 = 1 / (1 + Lambda(wi) + Lambda(wo)) and F = 1
    (microsim.models.quadrature.directional_albedo, 64 x 128 nodes: converged to 1e-8). The
    difference, its standard error (the table's, over the realizations) and z.
(b) Why: the masking of facets of normal m towards wo, G1(wo, m) = scene/g1_free / scene/g1_rays
    summed over the realizations (shadow rays from points drawn on the facets in proportion to
    their area projected towards wo; no model in it), at theta_o in MASKING_THETAS, against
    Smith's G1(wo) = 1 / (1 + Lambda(wo)), which is the same for every m. Pooled over the facets
    tilted towards wo (m_xy . wo_xy > 0) and away from it, and at the facet that reflects the
    normal incidence into wo (m the half vector, tilted theta_o / 2 towards wo): at
    theta_i = 0 every point is lit, so the order-1 albedo is the integral of
    D(m) cos(theta_m) G1(wo(m), m) over m, and Smith's model replaces G1(wo(m), m) by G1(wo(m)).

    python benchmarks/smith_gaussian.py [--json]

Writes benchmarks/out/smith_gaussian.json and the chart, and copies both to docs/validation/img.
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
from report import OUT, save_figures

from microsim import tables
from microsim.app import session
from microsim.core.frames import direction
from microsim.models.quadrature import directional_albedo
from microsim.physics import distributions as nd

ALPHAS = (0.3, 0.5, 0.8, 1.0)
THETAS = (0.0, 30.0, 45.0, 60.0, 75.0)
#: the period, correlation lengths: the spread of the order-1 albedo between realizations, which
#: sets the errors more than the paths do, falls as 1 / TILE
TILE = 48.0
#: realizations and paths an incidence (over all realizations) by alpha: every albedo difference
#: at more than 5 standard errors (the smallest, alpha 1 at normal incidence, takes the most)
REALIZATIONS = {0.3: 32, 0.5: 32, 0.8: 96, 1.0: 288}
PATHS = {0.3: 960_000, 0.5: 960_000, 0.8: 960_000, 1.0: 2_880_000}
#: the sensor's cells, here the cells of facet normals the masking is binned in
CELLS = 400
#: shadow rays a masking direction and realization
STATISTICS_RAYS = 65536
#: the masking directions (surface_statistics' defaults at phi_o = 0) reported
MASKING_THETAS = (30.0, 60.0, 75.0, 85.0)
DOCS_IMG = Path(__file__).resolve().parents[1] / "docs/validation/img"


def surface_config(alpha: float, paths: int, seed: int) -> dict:
    return {"scene": {"kind": "heightfield", "generator": "gaussian", "roughness": alpha, "tile": TILE,
                      "statistics": True, "statistics_rays": STATISTICS_RAYS},
            "material": {"kind": "mirror"},
            "illumination": {"theta_i_deg": list(THETAS)}, "sensor": {"cells": CELLS},
            "run": {"paths": paths, "realizations": REALIZATIONS[alpha], "seed": seed, "max_order": 1}}


def smith_mirror(alpha: float):
    """The ``microfacet`` BRDF D G2 F / (4 mu_i mu_o) of Beckmann's D, Smith's height-correlated
    G2 and a mirror's F = 1, as f(wi, wo) for (N, 3) arrays."""
    def brdf(wi, wo):
        h = wi + wo
        h = h / np.linalg.norm(h, axis=-1, keepdims=True)
        g = nd.masking_shadowing("smith_height_correlated", "beckmann", alpha, alpha, wi, wo, h)
        return nd.ndf("beckmann", alpha, alpha, h) * g / (4.0 * wi[:, 2] * wo[:, 2])
    return brdf


def smith_albedo(alpha: float) -> np.ndarray:
    """Smith's order-1 albedo of the mirror surface at each of THETAS."""
    wi = np.array([direction(math.radians(theta), 0.0) for theta in THETAS])
    return directional_albedo(smith_mirror(alpha), wi)


def masking(table, alpha: float) -> list[dict]:
    """G1(wo, m) pooled over the realizations, by facet normal, against Smith's (module doc (b))."""
    scene = table.arrays
    directions = np.asarray(table.scene["statistics_directions_deg"])
    normals = table.sensor.directions()
    out = []
    for k, (theta, phi) in enumerate(directions):
        if theta not in MASKING_THETAS:
            continue
        wo = direction(math.radians(theta), math.radians(phi))
        rays = np.asarray(scene["scene/g1_rays"])[:, k].sum(axis=0)
        free = np.asarray(scene["scene/g1_free"])[:, k].sum(axis=0)
        smith = float(nd.smith_g1("beckmann", alpha, alpha, wo[None])[0])
        towards = normals[:, :2] @ wo[:2] > 0.0

        def pooled(cells):
            n, left = int(rays[cells].sum()), int(free[cells].sum())
            if n == 0:
                return None, None, 0
            return left / n, math.sqrt(left * (n - left) / n**3), n

        half = direction(math.radians(theta / 2), math.radians(phi))
        cell = int(table.sensor.lookup(half[None])[0])
        entry = {"theta_o": float(theta), "g1_smith": smith}
        for name, cells in (("towards", towards), ("away", ~towards), ("all", np.ones_like(towards)),
                            ("half_vector", np.arange(len(rays)) == cell)):
            entry[f"g1_{name}"], entry[f"g1_{name}_stderr"], entry[f"rays_{name}"] = pooled(cells)
        # the profile in the plane of wo: the cells the plane's normals lie in, by the signed tilt
        # of their centres (+ towards wo)
        grid = np.radians(np.arange(0.0, 90.0, 0.25))
        plane = np.concatenate([direction(grid, np.full_like(grid, math.radians(phi + turn))) for turn in (0.0, 180.0)])
        cells = np.unique(table.sensor.lookup(plane))
        cells = cells[rays[cells] >= 200]
        centre = normals[cells]
        tilt = np.degrees(np.arctan2(np.hypot(centre[:, 0], centre[:, 1]), centre[:, 2])) \
            * np.where(centre[:, :2] @ wo[:2] >= 0.0, 1.0, -1.0)
        order = np.argsort(tilt)
        seen = free[cells] / rays[cells]
        entry["profile"] = {"tilt_deg": tilt[order].tolist(), "g1": seen[order].tolist(),
                            "g1_stderr": np.sqrt(seen * (1.0 - seen) / rays[cells])[order].tolist()}
        out.append(entry)
    return out


def measure(alpha: float, seed: int, folder: Path) -> dict:
    start = time.perf_counter()
    outcome = session.run(surface_config(alpha, PATHS[alpha], seed), folder / f"alpha{alpha}.h5", threads=1,
                          force=True)
    wall = time.perf_counter() - start
    table = tables.load(outcome.tables[0])
    order1 = table.arrays["albedo_order"][:, 0]
    order1_se = table.arrays["albedo_order_stderr"][:, 0]
    smith = smith_albedo(alpha)
    # the facets' alpha, sqrt(2 <slope^2>) an axis, over the realizations: the requested alpha
    # within its error (Smith's albedo at it is reported beside)
    measured = np.hypot(table.arrays["scene/measured_roughness_x"],
                        table.arrays["scene/measured_roughness_y"]) / math.sqrt(2)
    measured_alpha = float(np.mean(measured))
    return {"alpha": alpha, "paths": PATHS[alpha], "realizations": REALIZATIONS[alpha], "seed": seed,
            "tile": float(table.scene["tile"]), "triangles": int(table.scene["surface_triangles"]),
            "measured_alpha": measured_alpha,
            "measured_alpha_stderr": float(np.std(measured, ddof=1) / math.sqrt(len(measured))),
            "smith_albedo_at_measured_alpha": smith_albedo(measured_alpha).tolist(),
            "order1_albedo": order1.tolist(), "order1_albedo_stderr": order1_se.tolist(),
            "smith_albedo": smith.tolist(),
            "difference": (order1 - smith).tolist(), "z": ((order1 - smith) / order1_se).tolist(),
            "truncated": table.arrays["energy/truncated"].tolist(),
            "tracing_s": float(table.attrs["wall_time_s"]), "wall_s": wall, "masking": masking(table, alpha)}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    start = time.perf_counter()
    figures = {"thetas": list(THETAS), "cells": CELLS, "tile": TILE, "load_before": os.getloadavg(),
               "statistics_rays": STATISTICS_RAYS, "surfaces": []}
    with tempfile.TemporaryDirectory() as folder:
        for n, alpha in enumerate(ALPHAS):
            figures["surfaces"].append(measure(alpha, 31 + n, Path(folder)))
            s = figures["surfaces"][-1]
            print(f"alpha {alpha}: {s['wall_s']:.0f} s; order 1 - Smith "
                  + ", ".join(f"{d:+.5f} (z {z:+.1f})" for d, z in zip(s["difference"], s["z"])), flush=True)
    figures["wall_s"] = time.perf_counter() - start
    figures["load_after"] = os.getloadavg()
    path = save_figures(figures, "smith_gaussian", args.json)
    shutil.copyfile(path, DOCS_IMG / "smith_gaussian.json")
    plot(figures)


def plot(figures):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    surfaces = figures["surfaces"]
    fig, axes = plt.subplots(1, 3, figsize=(16, 5))
    ax = axes[0]
    for s in surfaces:
        ax.errorbar(THETAS, s["difference"], 3 * np.array(s["order1_albedo_stderr"]), fmt="o-", capsize=3,
                    label=f"alpha {s['alpha']:g}")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set(xlabel="theta_i (deg)", ylabel="order-1 albedo: traced - Smith",
           title="(a) order-1 albedo over Smith's height-correlated\nprediction (3 se bars)")
    ax.legend(fontsize=8)
    ax = axes[1]
    for s in surfaces[1:]:
        for entry in s["masking"]:
            if entry["theta_o"] == 75.0:
                p = entry["profile"]
                ax.errorbar(p["tilt_deg"], np.array(p["g1"]) / entry["g1_smith"],
                                   3 * np.array(p["g1_stderr"]) / entry["g1_smith"], fmt="o", ms=3, capsize=2,
                                   label=f"alpha {s['alpha']:g} (Smith's G1 {entry['g1_smith']:.3f})")
                ax.axvline(37.5, color="0.6", lw=0.8, ls=":")
    ax.axhline(1.0, color="k", lw=0.8, label="Smith: G1(wo), every m")
    ax.set(xlabel="facet tilt in the plane of wo (deg; + towards wo)", ylabel="G1(wo, m) / Smith's G1(wo)",
           title="(b) masking at theta_o = 75 deg by facet normal, 3 se\n(dotted: the half vector of theta_i = 0)")
    ax.legend(fontsize=8)
    ax = axes[2]
    for s in surfaces:
        thetas = [e["theta_o"] for e in s["masking"]]
        line = ax.errorbar(thetas, [e["g1_half_vector"] / e["g1_smith"] for e in s["masking"]],
                           [3 * e["g1_half_vector_stderr"] / e["g1_smith"] for e in s["masking"]], fmt="o-",
                           capsize=3, label=f"alpha {s['alpha']:g}: half vector")
        ax.errorbar(thetas, [e["g1_away"] / e["g1_smith"] for e in s["masking"]],
                    [3 * e["g1_away_stderr"] / e["g1_smith"] for e in s["masking"]], fmt="s--",
                    color=line[0].get_color(), capsize=3, label="tilted away")
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set(xlabel="theta_o (deg)", ylabel="G1(wo, m) / Smith's G1(wo)",
           title="(c) the facets that reflect theta_i = 0 into wo,\nand the facets tilted away from wo (3 se)")
    ax.legend(fontsize=7, ncol=2)
    fig.suptitle(f"Mirror Gaussian surfaces, tile {figures['tile']:g}; realizations, paths an incidence: "
                 + ", ".join(f"alpha {s['alpha']:g} {s['realizations']}, {s['paths'] / 1e6:.3g} M" for s in surfaces)
                 + "\n"
                 "order 1 against Smith's height-correlated model, and G1 by facet normal")
    fig.tight_layout()
    fig.savefig(OUT / "smith_gaussian.png", dpi=110)
    shutil.copyfile(OUT / "smith_gaussian.png", DOCS_IMG / "smith_gaussian.png")


if __name__ == "__main__":
    main()
