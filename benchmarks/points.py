"""Next-event estimation at exact directions (microsim.tracer.estimators.points) against binning in
cells: what the points resolve, what they gain per second, and what they cost per path.

(a) The opposition peak of Boolean Lambertian spheres (albedo and rings of opposition.py: 0.9,
16 retro rings out to 6 r / l), theta_i = 30 deg, phi = 0.005, 0.02, 0.1 and 0.3, all orders,
with retro points at gamma = x r / l for x in PEAK_X (denser near 0 and around the half
width; only gamma < 90 deg, the config's limit, so phi = 0.3 stops at x = 5), --peak-paths paths
(32 realizations) per volume fraction, on a tile of PEAK_TILE radii (the default 64 is
shorter than 3 free paths at phi <= 0.02, the rule of docs/guide/scenes/poisson_spheres.md, and
256 halves the spread between realizations of the peak's figures).
Order 1 is set beside ``boolean_spheres_single`` (phi <= 0.1). The figures, on the order-1
estimates of the points:

    background  b = f1(gamma_max), gamma_max = 10 r / l (the model has a slow tail in gamma,
                so b lies a little above the model without shadow hiding, which the model
                module does not expose; the same b is used for simulation and model);
    height      H = f1(0) - b, the peak above its background;
    half width  the smallest x at which f1(gamma) - b falls below H / 2, by linear interpolation
                between the two points around it, in units of r / l (and in degrees).

The model's figures come from its values at the same points by the same rules (so the
interpolation's error is common to both); the model's half width found by root finding on the
continuous curve is given beside it. The simulation's standard errors are jackknife errors over
the realizations (microsim.testing.trace_realizations gives every realization's estimates): the points
share their paths, so their errors are correlated, and H and the half width are nonlinear in
them. z = (simulation - model) / se. Targets at phi = 0.005: |z| <= 2 for H and the half width,
se(H) / H < 5 %. For contrast, the same paths binned on the retro rings: the relative standard
error of the innermost ring, and of the innermost ring any path left through where none did.

(b) Error per second, NEE against binning at equal angular resolution, on the 3240-cell sensor,
theta_i = 30 deg, albedo 0.8: a Lambertian plane, Boolean spheres phi = 0.3 and Lambertian
V-cavities (Beckmann, roughness 0.5), each at theta_o = 0 deg, 60 and 85 deg (phi_o = 180,
forward) and at retro. Binning: the cell containing the direction, from a run without points;
NEE: one point at that cell's centre, from a run with that one point (same sensor, same seed).
Figure of merit per estimate: m = (se / f)^2 t, t the run's tracing seconds (attribute
wall_time_s), one thread; the runs alternate (binning, then the NEE run of each direction),
REPEATS times with other seeds, and m is the median over the repeats. Gain = m_binning / m_NEE;
m / 0.01^2 is the tracing time a 1 % relative error would need. Beside it, the cell average's
bias against the point, (f_cell - f_point) / f_point over the repeats (none on the plane, whose
f is constant; NEE is exact there, zero variance, and its gain infinite). Target: gain >= 10 at
retro and at theta_o = 85 deg on the spheres.

(c) Cost per path of k points, k in POINT_COUNTS (theta_o from an equal-solid-angle spiral up to
85 deg), spheres phi = 0.3 and the plane: tracing seconds per path, one thread, the runs of
every k alternated, the median of REPEATS.

--peak-runs K: part (a) alone, at phi = 0.005, over K independent seeds (--seed, --seed + 1,
...; seeds are independent, runner's streams are keyed by (seed, realization)): each run's half
width and z against the model on the same grid, then their mean with the standard error of the
mean, and the runs' spread beside the mean jackknife error (whether the jackknife is calibrated).
One run of 1 M paths has se(half width) / half width = 0.35 %, so a run's z says nothing about a
0.1 % bias; the default seed is fixed, so rerunning the benchmark redraws the same z.

Path counts (FULL_PATHS, or QUICK_PATHS with --quick): 1 M per volume fraction in (a); in (b)
1 M a run on the spheres, 4 M on the plane and the V-cavities; in (c) 250 000 on the spheres
and 2 M on the plane.

    python benchmarks/points.py [--quick] [--json]
    python benchmarks/points.py --peak-runs 9 [--peak-paths N] [--seed S]

Writes benchmarks/out/points.png and .json (every figure the plot shows, and the config of every
run). Full mode: 6 min on 2 cores (8 min beside a test run); --quick: about 1.5 minutes.
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path

import numpy as np
from opposition import ALBEDO as PEAK_ALBEDO
from opposition import MODEL_MAX_PHI, RINGS, ring_reach_deg
from report import OUT, save_figures
from scipy.optimize import brentq

from microsim import config, models, tables
from microsim.app import session
from microsim.core.orders import ORDERS
from microsim.physics.boolean_model import radius_over_free_path
from microsim.run.plan import Plan
from microsim.testing import trace_realizations
from microsim.tracer.estimators.points import PointSet
from microsim.tracer.estimators.retro_rings import RetroRings

THETA_I_DEG = 30.0
PEAK_PHIS = [0.005, 0.02, 0.1, 0.3]
#: the volume fraction whose peak is checked against the model
REPORTED_PHI = 0.005
#: retro points' phase angles in units of r / l; the last is the background
PEAK_X = [0.0, 0.1, 0.2, 0.35, 0.5, 0.65, 0.8, 1.0, 1.5, 2.5, 5.0, 10.0]
MAX_GAMMA_DEG = 90.0
PEAK_TILE = 256.0
REALIZATIONS = 32
CELLS = 3240
ALBEDO = 0.8
SCENES = {
    "plane": {"kind": "plane"},
    "spheres": {"kind": "poisson_spheres", "volume_fraction": 0.3},
    "vcavities": {"kind": "vcavities", "distribution": "beckmann", "roughness": 0.5},
}
#: (label, [theta_o, phi_o] deg, or None for retro) of part (b)
DIRECTIONS = [("theta_o 0", [0.0, 0.0]), ("theta_o 60", [60.0, 180.0]), ("theta_o 85", [85.0, 180.0]),
              ("retro", None)]
POINT_COUNTS = [0, 1, 4, 16, 64]
REPEATS = 3
#: (peak, efficiency plane and V-cavities, efficiency spheres, cost plane, cost spheres) paths
FULL_PATHS = (1_000_000, 4_000_000, 1_000_000, 2_000_000, 250_000)
QUICK_PATHS = (64_000, 200_000, 64_000, 200_000, 32_000)


def jackknife(samples: np.ndarray, statistic):
    """(statistic of the mean of ``samples`` (R, ...) over the realizations, its jackknife
    standard error): leave one realization out at a time."""
    r = len(samples)
    total = samples.sum(axis=0)
    value = np.asarray(statistic(total / r), dtype=float)
    left_out = np.array([statistic((total - s) / (r - 1)) for s in samples], dtype=float)
    return value, np.sqrt((r - 1) / r * np.sum((left_out - left_out.mean(axis=0)) ** 2, axis=0))


def height(f):
    """H = f(0) - f(gamma_max) (module doc)."""
    return f[0] - f[-1]


def half_width(x, f):
    """The smallest x where f - f(gamma_max) falls below H / 2, interpolated linearly; NaN if
    it never does."""
    excess = f - f[-1]
    below = np.flatnonzero(excess < excess[0] / 2.0)
    if excess[0] <= 0 or below.size == 0 or below[0] == 0:
        return math.nan
    j = below[0]
    return x[j - 1] + (excess[0] / 2.0 - excess[j - 1]) * (x[j] - x[j - 1]) / (excess[j] - excess[j - 1])


def retro_directions(wi, gamma_deg):
    """Unit vectors of retro points at ``gamma_deg`` about wi (azimuth 0)."""
    return PointSet.of(retro_points_deg=list(gamma_deg)).directions(wi, 0.0)


def peak(phi, paths, seed):
    """Part (a) for one volume fraction."""
    r_over_l = radius_over_free_path(phi)
    unit = math.degrees(r_over_l)
    x = np.array([v for v in PEAK_X if v * unit < MAX_GAMMA_DEG])
    cfg = {"scene": {"kind": "poisson_spheres", "volume_fraction": phi, "tile": PEAK_TILE},
           "material": {"kind": "lambert", "albedo": PEAK_ALBEDO},
           "illumination": {"theta_i_deg": [THETA_I_DEG]},
           "sensor": {"cells": 100, "retro_rings": RINGS, "retro_max_deg": ring_reach_deg(phi),
                      "retro_points_deg": (x * unit).tolist()},
           "run": {"paths": paths, "realizations": REALIZATIONS, "seed": seed}}
    start = time.perf_counter()
    plan, est = trace_realizations(config.validate(cfg))
    seconds = time.perf_counter() - start
    order1, every = est["brdf_points"][:, 0, 0], est["brdf_points"][:, 0, ORDERS]
    case = {"volume_fraction": phi, "r_over_l": r_over_l, "x": x.tolist(), "gamma_deg": (x * unit).tolist(),
            "config": cfg, "seconds_with_compiling": seconds}
    for name, samples in (("order1", order1), ("all_orders", every)):
        f, f_se = jackknife(samples, lambda f: f)
        ratio, ratio_se = jackknife(samples, lambda f: f / f[-1])
        h, h_se = jackknife(samples, height)
        w, w_se = jackknife(samples, lambda f: half_width(x, f))
        case[name] = {"f": f.tolist(), "f_stderr": f_se.tolist(), "ratio": ratio.tolist(),
                      "ratio_stderr": ratio_se.tolist(), "height": float(h), "height_stderr": float(h_se),
                      "hwhm_x": float(w), "hwhm_x_stderr": float(w_se)}
    rings = est["brdf_retro"][:, 0]  # (R, rows, rings)
    case["rings"] = {"gamma_hi_deg": np.degrees(RetroRings.reaching(RINGS, ring_reach_deg(phi)).phase_bounds()[1]).tolist()}
    for name, row in (("order1", 0), ("all_orders", ORDERS)):
        mean = rings[:, row].mean(axis=0)
        se = rings[:, row].std(axis=0, ddof=1) / math.sqrt(REALIZATIONS)
        seen = np.flatnonzero(mean > 0)
        first = int(seen[0]) if seen.size else None
        case["rings"][name] = {"f": mean.tolist(), "f_stderr": se.tolist(),
                               "inner_relative_stderr": float(se[0] / mean[0]) if mean[0] > 0 else None,
                               "first_ring_seen": first, "first_ring_seen_relative_stderr":
                                   None if first is None else float(se[first] / mean[first])}
    if phi <= MODEL_MAX_PHI:
        case["model"] = model_peak(phi, x, unit, plan.incidence_direction(0), case["order1"])
    return case


def model_peak(phi, x, unit, wi, measured):
    """``boolean_spheres_single`` at the points, its figures by the same rules, z-scores against
    ``measured``, and its curve on a fine grid."""
    model = models.create("boolean_spheres_single", albedo=PEAK_ALBEDO, volume_fraction=phi)

    def f(xs):
        xs = np.atleast_1d(xs)
        return model(np.broadcast_to(wi, (len(xs), 3)), retro_directions(wi, xs * unit))

    at = f(x)
    h, w = height(at), half_width(x, at)
    fine = np.linspace(0.0, x[-1], 101)
    return {"f": at.tolist(), "ratio": (at / at[-1]).tolist(), "height": float(h), "hwhm_x": float(w),
            "hwhm_x_continuous": float(brentq(lambda v: f(v)[0] - at[-1] - h / 2.0, 0.0, x[-1], xtol=1e-6)),
            "z_f0": (measured["f"][0] - at[0]) / measured["f_stderr"][0],
            "z_height": (measured["height"] - h) / measured["height_stderr"],
            "z_hwhm": (measured["hwhm_x"] - w) / measured["hwhm_x_stderr"],
            "fine_x": fine.tolist(), "fine_ratio": (f(fine) / at[-1]).tolist()}


def table_run(cfg, folder: Path):
    """Run ``cfg`` on one thread: its table."""
    outcome = session.run(cfg, folder / "run.h5", threads=1, force=True)
    return tables.load(outcome.tables[0])


def efficiency(scene_name, paths, seed, folder):
    """Part (b) for one scene: per direction, the binned cell and the point, REPEATS times."""
    base = {"scene": SCENES[scene_name], "material": {"kind": "lambert", "albedo": ALBEDO},
            "illumination": {"theta_i_deg": [THETA_I_DEG]}, "sensor": {"cells": CELLS},
            "run": {"paths": paths, "realizations": REALIZATIONS}}
    plan = Plan.from_config(config.validate({**base, "run": {**base["run"], "seed": seed}}))
    wi = plan.incidence_direction(0)
    sensor = plan.sensor
    asked = PointSet.of([d for _, d in DIRECTIONS if d is not None])
    wanted = np.vstack([asked.directions(wi, 0.0), wi])  # retro last, as in DIRECTIONS
    cells = sensor.lookup(wanted)
    centre = sensor.directions()[cells]
    centre_deg = np.stack([np.degrees(np.arccos(np.clip(centre[:, 2], -1, 1))),
                           np.degrees(np.arctan2(centre[:, 1], centre[:, 0]))], axis=1)
    cases = [{"direction": label, "cell": int(c), "cell_centre_deg": d.tolist(), "binning": [], "nee": []}
             for (label, _), c, d in zip(DIRECTIONS, cells, centre_deg)]
    for repeat in range(REPEATS):
        cfg = {**base, "run": {**base["run"], "seed": seed + repeat}}
        table = table_run(cfg, folder)
        for case in cases:
            case["binning"].append(record(cfg, table, table.arrays["brdf"][0, case["cell"]],
                                          table.arrays["brdf_stderr"][0, case["cell"]]))
        for case in cases:
            point = {**cfg, "sensor": {"cells": CELLS, "directions_deg": [case["cell_centre_deg"]]}}
            table = table_run(point, folder)
            case["nee"].append(record(point, table, table.arrays["brdf_points"][0, 0],
                                      table.arrays["brdf_points_stderr"][0, 0]))
    for case in cases:
        for kind in ("binning", "nee"):
            merit = float(np.median([r["merit"] for r in case[kind]]))
            case[f"{kind}_merit"] = merit
            case[f"{kind}_seconds_for_1pct"] = merit / 0.01**2
        case["gain"] = case["binning_merit"] / case["nee_merit"] if case["nee_merit"] > 0 else None
        cell, point = ([r["f"] for r in case[kind]] for kind in ("binning", "nee"))
        cell_se, point_se = ([r["stderr"] for r in case[kind]] for kind in ("binning", "nee"))
        f_point = np.mean(point)
        case["cell_bias"] = float(np.mean(cell) / f_point - 1.0)
        case["cell_bias_stderr"] = float(math.hypot(math.sqrt(np.sum(np.square(cell_se))) / REPEATS / f_point,
                                                    math.sqrt(np.sum(np.square(point_se))) / REPEATS
                                                    * np.mean(cell) / f_point**2))
    return cases


def record(cfg, table, f, stderr):
    """One run's estimate f with its standard error, its tracing seconds and m = (se / f)^2 t."""
    f, stderr, seconds = float(f), float(stderr), float(table.attrs["wall_time_s"])
    relative = stderr / f
    if relative < 1e-6:  # the plane's points: exact (every path adds albedo / pi), their spread is rounding
        relative = 0.0
    return {"config": cfg, "f": f, "stderr": stderr, "seconds": seconds, "merit": relative**2 * seconds}


def spiral(k):
    """k directions [theta_o, phi_o], deg: equal solid angle in theta_o up to 85 deg, golden-angle azimuths."""
    top = 1.0 - math.cos(math.radians(85.0))
    return [[math.degrees(math.acos(1.0 - (j + 0.5) / k * top)), (137.50776 * j) % 360.0] for j in range(k)]


def cost(scene_name, paths, seed, folder):
    """Part (c) for one scene: tracing seconds per path of every k, REPEATS times."""
    runs = {k: [] for k in POINT_COUNTS}
    for repeat in range(REPEATS):
        for k in POINT_COUNTS:
            cfg = {"scene": SCENES[scene_name], "material": {"kind": "lambert", "albedo": ALBEDO},
                   "illumination": {"theta_i_deg": [THETA_I_DEG]}, "sensor": {"cells": CELLS},
                   "run": {"paths": paths, "realizations": REALIZATIONS, "seed": seed + repeat}}
            if k:
                cfg["sensor"]["directions_deg"] = spiral(k)
            runs[k].append({"config": cfg, "seconds": float(table_run(cfg, folder).attrs["wall_time_s"])})
    per_path = [float(np.median([r["seconds"] for r in runs[k]])) / paths for k in POINT_COUNTS]
    return {"points": POINT_COUNTS, "seconds_per_path": per_path,
            "relative_to_no_points": [s / per_path[0] for s in per_path], "runs": [runs[k] for k in POINT_COUNTS]}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small path counts (about 1.5 minutes)")
    parser.add_argument("--peak-paths", type=int, help="paths per volume fraction in (a)")
    parser.add_argument("--seed", type=int, default=71)
    parser.add_argument("--peak-runs", type=int, help="part (a) alone at phi 0.005, over this many seeds")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.peak_runs:
        peak_runs(args.peak_runs, args.peak_paths or FULL_PATHS[0], args.seed, args.json)
        return
    peak_paths, flat_paths, sphere_paths, plane_cost_paths, sphere_cost_paths = (QUICK_PATHS if args.quick
                                                                                  else FULL_PATHS)
    peak_paths = args.peak_paths or peak_paths
    started = time.perf_counter()
    figures = {"quick": args.quick, "theta_i_deg": THETA_I_DEG, "realizations": REALIZATIONS, "repeats": REPEATS,
               "peak": {"albedo": PEAK_ALBEDO, "paths": peak_paths, "cases": []}, "efficiency": {}, "cost": {}}

    print(f"(a) opposition peak, order 1, {peak_paths:,} paths: x = gamma / (r / l)")
    for phi in PEAK_PHIS:
        case = peak(phi, peak_paths, args.seed)
        figures["peak"]["cases"].append(case)
        o1, rings = case["order1"], case["rings"]["order1"]
        inner = rings["inner_relative_stderr"]
        line = (f"  phi {phi:<6g} H {o1['height']:.4f} +- {o1['height_stderr']:.4f} "
                f"({100 * o1['height_stderr'] / o1['height']:.2f} %)  hwhm x {o1['hwhm_x']:.4f} +- "
                f"{o1['hwhm_x_stderr']:.4f} ({o1['hwhm_x'] * math.degrees(case['r_over_l']):.4f} deg)")
        if "model" in case:
            m = case["model"]
            line += (f"  model H {m['height']:.4f} (z {m['z_height']:+.2f}) hwhm x {m['hwhm_x']:.4f} "
                     f"(z {m['z_hwhm']:+.2f}; continuous {m['hwhm_x_continuous']:.4f})  f1(0) z {m['z_f0']:+.2f}")
        first = rings["first_ring_seen"]
        line += (f"  inner ring rel. se {'no exit' if inner is None else f'{100 * inner:.0f} %'}"
                 + (f" (ring {first}: {100 * rings['first_ring_seen_relative_stderr']:.0f} %)" if first else "")
                 + f"  {case['seconds_with_compiling']:.0f} s")
        print(line, flush=True)

    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        print(f"(b) error per second, gain = binning / NEE of (se / f)^2 t, median of {REPEATS}")
        for name in SCENES:
            paths = sphere_paths if name == "spheres" else flat_paths
            cases = efficiency(name, paths, args.seed, folder)
            figures["efficiency"][name] = {"paths": paths, "cases": cases}
            for c in cases:
                gain = "inf (NEE exact)" if c["gain"] is None else f"{c['gain']:.3g}"
                print(f"  {name:<9} {c['direction']:<10} gain {gain:<15} s for 1 %: binning "
                      f"{c['binning_seconds_for_1pct']:.3g}, NEE {c['nee_seconds_for_1pct']:.3g}  cell bias "
                      f"{100 * c['cell_bias']:+.2f} +- {100 * c['cell_bias_stderr']:.2f} %", flush=True)
        print("(c) tracing seconds per path with k points")
        for name, paths in (("spheres", sphere_cost_paths), ("plane", plane_cost_paths)):
            figures["cost"][name] = entry = {"paths": paths, **cost(name, paths, args.seed, folder)}
            print(f"  {name:<8} " + ", ".join(f"k {k}: {1e6 * s:.3g} us" for k, s in
                                               zip(POINT_COUNTS, entry["seconds_per_path"])), flush=True)
    figures["seconds"] = time.perf_counter() - started
    print(f"{figures['seconds']:.0f} s in all")
    save_figures(figures, "points", args.json)
    plot(figures)


def peak_runs(runs, paths, seed, print_json):
    """--peak-runs: the order-1 half width at REPORTED_PHI over ``runs`` independent seeds."""
    print(f"(a) alone, phi {REPORTED_PHI:g}, order 1, {runs} runs of {paths:,} paths (seeds {seed}..{seed + runs - 1})")
    cases = []
    for k in range(runs):
        case = peak(REPORTED_PHI, paths, seed + k)
        cases.append(case)
        o1, m = case["order1"], case["model"]
        print(f"  seed {seed + k}: hwhm x {o1['hwhm_x']:.5f} +- {o1['hwhm_x_stderr']:.5f} (model {m['hwhm_x']:.5f}, "
              f"z {m['z_hwhm']:+.2f})  H {o1['height']:.5f} +- {o1['height_stderr']:.5f} (z {m['z_height']:+.2f})  "
              f"{case['seconds_with_compiling']:.0f} s", flush=True)
    width = np.array([c["order1"]["hwhm_x"] for c in cases])
    width_se = np.array([c["order1"]["hwhm_x_stderr"] for c in cases])
    high = np.array([c["order1"]["height"] for c in cases])
    model = cases[0]["model"]
    summary = {"runs": runs, "paths": paths, "seed": seed, "hwhm_x_mean": float(width.mean()),
               "hwhm_x_mean_stderr": float(np.sqrt(np.sum(width_se**2)) / runs),
               "hwhm_x_spread": float(width.std(ddof=1)) if runs > 1 else math.nan,
               "hwhm_x_rms_jackknife": float(np.sqrt(np.mean(width_se**2))),
               "height_mean": float(high.mean()), "model_hwhm_x": model["hwhm_x"], "model_height": model["height"],
               "cases": cases}
    summary["z_hwhm_mean"] = (summary["hwhm_x_mean"] - model["hwhm_x"]) / summary["hwhm_x_mean_stderr"]
    print(f"  mean hwhm x {summary['hwhm_x_mean']:.5f} +- {summary['hwhm_x_mean_stderr']:.5f} (model "
          f"{model['hwhm_x']:.5f}, z {summary['z_hwhm_mean']:+.2f}; continuous {model['hwhm_x_continuous']:.5f}); "
          f"spread of the runs {summary['hwhm_x_spread']:.5f}, rms jackknife se {summary['hwhm_x_rms_jackknife']:.5f}")
    save_figures(summary, "points_peak_runs", print_json)


def plot(figures):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(16, 4.6))
    ax = axes[0]
    for case in figures["peak"]["cases"]:
        x = np.array(case["x"])
        o1, every = case["order1"], case["all_orders"]
        line = ax.errorbar(x, o1["ratio"], o1["ratio_stderr"], fmt="o", ms=3, capsize=2,
                           label=f"phi {case['volume_fraction']:g}, order 1")
        colour = line[0].get_color()
        ax.errorbar(x, every["ratio"], every["ratio_stderr"], fmt="s", ms=3, mfc="none", capsize=2, color=colour,
                    label=f"phi {case['volume_fraction']:g}, all orders")
        if "model" in case:
            ax.plot(case["model"]["fine_x"], case["model"]["fine_ratio"], "-", color=colour, lw=0.8)
    ax.set_xscale("symlog", linthresh=1.0)
    ax.set_xlabel("phase angle / (r / l)")
    ax.set_ylabel("f / f(gamma_max), gamma_max = 10 r / l (phi 0.3: 5 r / l)")
    ax.set_title(f"(a) opposition peak, theta_i {figures['theta_i_deg']:g}, {figures['peak']['paths']:,} paths; "
                 "lines: boolean_spheres_single", fontsize=8)
    ax.legend(fontsize=6, ncol=2)
    reported = next(c for c in figures["peak"]["cases"] if c["volume_fraction"] == REPORTED_PHI)
    o1, m = reported["order1"], reported["model"]
    ax.text(0.98, 0.55, f"phi {REPORTED_PHI:g}, order 1:\nH {o1['height']:.4f} +- {o1['height_stderr']:.4f} "
            f"(model {m['height']:.4f}, z {m['z_height']:+.2f})\nhwhm {o1['hwhm_x']:.3f} +- {o1['hwhm_x_stderr']:.3f} "
            f"r/l (model {m['hwhm_x']:.3f}, z {m['z_hwhm']:+.2f})", transform=ax.transAxes, ha="right", fontsize=6)

    ax = axes[1]
    labels, gains, exact = [], [], []
    for scene, entry in figures["efficiency"].items():
        for case in entry["cases"]:
            labels.append(f"{scene}\n{case['direction']}")
            gains.append(case["gain"])
            exact.append(case["gain"] is None)
    top = max(g for g in gains if g is not None) * 3.0
    heights = [top if g is None else g for g in gains]
    bars = ax.bar(range(len(labels)), heights, color=["0.8" if e else "C0" for e in exact])
    for bar, e in zip(bars, exact):
        if e:
            ax.text(bar.get_x() + bar.get_width() / 2, top, "NEE\nexact", ha="center", va="top", fontsize=6)
    ax.axhline(10.0, color="r", lw=0.8, ls="--", label="target 10")
    ax.set_yscale("log")
    ax.set_xticks(range(len(labels)), labels, fontsize=5, rotation=90)
    ax.set_ylabel("gain: (se/f)^2 t binning / NEE")
    ax.set_title(f"(b) efficiency, NEE point vs its {CELLS}-cell cell, theta_i {figures['theta_i_deg']:g}",
                 fontsize=8)
    ax.legend(fontsize=6)

    ax = axes[2]
    for scene, entry in figures["cost"].items():
        ax.plot(entry["points"], 1e6 * np.array(entry["seconds_per_path"]), "o-", label=scene)
    ax.set_xscale("symlog", linthresh=1.0)
    ax.set_yscale("log")
    ax.set_xlabel("points k")
    ax.set_ylabel("tracing us per path (1 thread)")
    ax.set_title("(c) cost per path of k points", fontsize=8)
    ax.legend(fontsize=6)
    fig.tight_layout()
    OUT.mkdir(exist_ok=True)
    fig.savefig(OUT / "points.png", dpi=120)


if __name__ == "__main__":
    main()
