"""The opposition peak of Boolean spheres in single scattering, resolved on retro rings and set
beside the finite-size model.

Shadow hiding makes the order-1 peak: the light that reaches a sphere through a gap leaves
through the same gap when it goes back the way it came. Its width is about r / l, 0.2 deg at
phi = 0.005, far below a sensor cell (the cap cell of 3240 cells is 1.4 deg wide), so the
multiple-scattering runs of ``sphere_study.py`` (1 M paths) resolve it only from phi = 0.05 on.
Order 1 alone is cheap to trace (two segments a path), so here every volume fraction gets
--paths paths at max_order = 1, theta_i = 0 and 30 deg, albedo 0.9, with RINGS retro rings out
to 6 r / l (within [0.5, 60] deg).

Per ring, the enhancement over point scatterers E = f / f_RT - 1, f_RT = c p(-wi.wo) / (mu_i +
mu_o) averaged over the ring (radiative transfer has no peak); beside it, the same from the
finite-size model ``boolean_spheres_single`` (first order in r / l; microsim/models/boolean_spheres.py;
phi <= 0.1) and chi^2 per ring of the table against it. Peak height: E(ring 0) - E(outer OUTER_RINGS
rings); half width at half height, interpolated, measured and modelled. At max_order = 1 the
slab is ln(1e3) free paths deep, which cuts the peak's tip (exact retro, where the way out is
free once the way in was) by exp(-depth / (mu_i l)), 1e-3 at theta_i = 0; the model integrates to
infinite depth (docs/validation/benchmarks.md, points.py).

    python benchmarks/opposition.py [--phis ...] [--paths N] [--json]

Writes benchmarks/out/opposition.png and .json. About 5 minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
from report import OUT, save_figures

from microsim import config, models
from microsim.core.orders import ORDERS
from microsim.models.radiative_transfer import single_scattering
from microsim.physics.boolean_model import radius_over_free_path
from microsim.testing import trace
from microsim.tracer.estimators.retro_rings import RetroRings

PHIS = [0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.3, 0.45, 0.6]
THETA_I_DEG = [0.0, 30.0]
ALBEDO = 0.9
RINGS = 16
OUTER_RINGS = 3
#: the finite-size model is first order in r / l; it accepts phi up to 0.1
MODEL_MAX_PHI = 0.1


def ring_reach_deg(phi: float) -> float:
    return float(min(max(math.degrees(6.0 * radius_over_free_path(phi)), 0.5), 60.0))


def half_width(centre, excess):
    """Phase angle where ``excess`` (peak at ring 0) first falls to half its ring-0 value, by
    linear interpolation; None if it never does within the rings."""
    below = np.flatnonzero(excess < excess[0] / 2.0)
    if excess[0] <= 0 or below.size == 0:
        return None
    j = below[0]
    if j == 0:
        return None
    return float(centre[j - 1] + (excess[0] / 2.0 - excess[j - 1]) * (centre[j] - centre[j - 1]) / (excess[j] - excess[j - 1]))


def measure(phi, paths, seed):
    cfg = config.validate({
        "scene": {"kind": "poisson_spheres", "volume_fraction": phi},
        "material": {"kind": "lambert", "albedo": ALBEDO},
        "illumination": {"theta_i_deg": THETA_I_DEG},
        "sensor": {"cells": 100, "retro_rings": RINGS, "retro_max_deg": ring_reach_deg(phi)},
        "run": {"paths": paths, "realizations": 32, "seed": seed, "max_order": 1},
    })
    start = time.perf_counter()
    result = trace(cfg, threads=2)
    seconds = time.perf_counter() - start
    model = models.create("boolean_spheres_single", albedo=ALBEDO, volume_fraction=phi) if phi <= MODEL_MAX_PHI else None
    rings = RetroRings.reaching(RINGS, ring_reach_deg(phi))
    lo, hi = rings.phase_bounds()
    centre = np.degrees(0.5 * (lo + hi))
    rows = []
    for i in range(len(THETA_I_DEG)):
        wi = result.plan.incidence_direction(i)
        w, weight = rings.quadrature(wi, 4, 16)
        wis = np.broadcast_to(wi, w.reshape(-1, 3).shape)
        rt = np.sum(single_scattering(wis, w.reshape(-1, 3), ALBEDO).reshape(weight.shape) * weight, axis=1)
        retro = result.estimates["brdf_retro"][i]
        f, se = retro.mean[ORDERS], retro.stderr[ORDERS]  # the row after the four orders: all of them
        measured, error = f / rt - 1.0, se / rt
        base = measured[-OUTER_RINGS:].mean()
        row = {"theta_i_deg": THETA_I_DEG[i], "excess": measured.tolist(), "excess_stderr": error.tolist(),
               "height": float(measured[0] - base),
               "height_stderr": float(math.hypot(error[0], np.sqrt(np.sum(error[-OUTER_RINGS:] ** 2)) / OUTER_RINGS)),
               "hwhm_deg": half_width(centre, measured - base),
               "model_excess": None, "model_height": None, "model_hwhm_deg": None, "chi2_per_ring_vs_model": None}
        if model is not None:
            finite = np.sum(model(wis, w.reshape(-1, 3)).reshape(weight.shape) * weight, axis=1)
            modelled = finite / rt - 1.0
            model_base = modelled[-OUTER_RINGS:].mean()
            row.update({"model_excess": modelled.tolist(), "model_height": float(modelled[0] - model_base),
                        "model_hwhm_deg": half_width(centre, modelled - model_base),
                        "chi2_per_ring_vs_model": float(np.mean(((f - finite) / se) ** 2))})
        rows.append(row)
    return {"volume_fraction": phi, "r_over_l": radius_over_free_path(phi), "ring_reach_deg": ring_reach_deg(phi),
            "gamma_deg": centre.tolist(), "paths": paths, "seconds": seconds, "incidences": rows}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--phis", type=float, nargs="+", default=PHIS)
    parser.add_argument("--paths", type=int, default=16_000_000)
    parser.add_argument("--seed", type=int, default=61)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    figures = {"albedo": ALBEDO, "rings": RINGS, "cases": []}
    print("phi     r/l      theta_i  height (model)            hwhm deg (model)   chi2/ring vs model  seconds")
    for phi in args.phis:
        case = measure(phi, args.paths, args.seed)
        figures["cases"].append(case)
        for row in case["incidences"]:
            print(f"{phi:<7g} {case['r_over_l']:.4f}  {row['theta_i_deg']:5.0f}    {row['height']:.3f} +- "
                  f"{row['height_stderr']:.3f} ({_fmt(row['model_height'])})   {_fmt(row['hwhm_deg'])} "
                  f"({_fmt(row['model_hwhm_deg'])})        {_fmt(row['chi2_per_ring_vs_model'], 2)}        "
                  f"{case['seconds']:.0f}", flush=True)
        save_figures(figures, "opposition", False)
    save_figures(figures, "opposition", args.json)
    plot(figures)


def _fmt(value, digits=3):
    return "n/a" if value is None else f"{value:.{digits}f}"


def plot(figures):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    for case in figures["cases"]:
        row = case["incidences"][0]
        x = np.array(case["gamma_deg"]) / math.degrees(case["r_over_l"])
        line = axes[0].errorbar(x, row["excess"], row["excess_stderr"], fmt="o", ms=3, capsize=2,
                                label=f"phi {case['volume_fraction']:g}")
        if row["model_excess"] is not None:
            axes[0].plot(x, row["model_excess"], "-", color=line[0].get_color(), lw=0.8)
    axes[0].set_xlabel("phase angle / (r / l)")
    axes[0].set_ylabel("f / f_RT - 1 (order 1, theta_i 0)")
    axes[0].set_title("order-1 enhancement over point scatterers; lines: boolean_spheres_single", fontsize=8)
    axes[0].legend(fontsize=6)
    phis = [c["volume_fraction"] for c in figures["cases"]]
    for k, marker in ((0, "o"), (1, "s")):
        rows = [c["incidences"][k] for c in figures["cases"]]
        t = rows[0]["theta_i_deg"]
        axes[1].errorbar(phis, [r["height"] for r in rows], [r["height_stderr"] for r in rows], fmt=marker, ms=4,
                         capsize=2, label=f"measured, theta_i {t:g}")
        axes[1].plot(phis, [np.nan if r["model_height"] is None else r["model_height"] for r in rows], marker + "--",
                     mfc="none", label=f"model, theta_i {t:g}")
        axes[2].plot(phis, [r["hwhm_deg"] if r["hwhm_deg"] is not None else np.nan for r in rows], marker, ms=4,
                     label=f"measured, theta_i {t:g}")
        axes[2].plot(phis, [r["model_hwhm_deg"] if r["model_hwhm_deg"] is not None else np.nan for r in rows],
                     marker + "--", mfc="none", label=f"model, theta_i {t:g}")
    axes[2].plot(phis, [math.degrees(c["r_over_l"]) for c in figures["cases"]], "k:", label="r / l (deg)")
    for ax, title in zip(axes[1:], ("peak height over the outer rings", "half width at half height (deg)")):
        ax.set_xscale("log")
        ax.set_xlabel("volume fraction")
        ax.set_title(title, fontsize=9)
        ax.legend(fontsize=6)
    axes[2].set_yscale("log")
    fig.tight_layout()
    OUT.mkdir(exist_ok=True)
    fig.savefig(OUT / "opposition.png", dpi=120)


if __name__ == "__main__":
    main()
