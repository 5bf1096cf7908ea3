"""Packed against Boolean spheres, and both against radiative transfer: the packing study.

``--part dilute`` (the dilute limit): at phi = 0.01, albedo 0.8, theta_i = 0, 30, 60, 80 deg,
default tile and depth, --cells cells, --paths paths an incidence over 16 realizations: tables of
``packed_spheres``, ``poisson_spheres`` and the half space of Lambert-sphere point scatterers
(``halfspace_medium``, the radiative-transfer limit both tend to), each pair compared cell by
cell (``compare`` of one table against the other, :class:`~microsim.models.tabulated.TabulatedBRDF`):
chi-square per cell with its two-sided bounds, the albedos' mean z^2 with its bound, the median
|rel| over the cells with signal, and the albedos. JSON in benchmarks/out/packing_study.json.

    python benchmarks/packing_study.py --part dilute [--paths 400000] [--workers 2]

``--part study``: packed against Boolean at --phis (default 0.01, 0.1, 0.2, ..., 0.6), albedos
0.3, 0.8 and 0.95 traced together (one run each kind and phi), the same incidences and cells,
the retro points ``RETRO_POINTS_DEG`` (next-event estimation at phase angles from the retro
direction), --paths paths an incidence over --realizations realizations. Per phi and albedo: the
packed/Boolean albedo ratio at each incidence with its standard error; the chi-square per cell
of the packed table against the Boolean one order by order (1, 2, 3, 4+) with its two-sided
bounds; the opposition peak of each kind, f at retro over f at ``PEAK_REFERENCE_DEG`` from it,
at each incidence with its standard error (the points' covariance); the void's structure
(``statistics = true``: the mean chord, the share of short chords, the first flights); the median |rel| over the
cells with signal of ``lambert_sphere`` (method exact: the radiative-transfer half space of the
grains) and ``hapke`` (its defaults with the grains' albedo and the scene's volume fraction, and
with the anisotropic multiple scattering) on each kind; at phi <= 0.1 the finite-size
single-scattering model ``boolean_spheres_single`` against order 1 at the retro points (its
chi-square over the points, with their covariance); and the fits (``--fits``) of ``hapke``
(AMSA; albedo and volume fraction free) and ``vmf_diffuse`` (its roughness r free, the grains'
albedo given) to each table: the fitted values with their standard errors, chi-square per degree
of freedom and the fit's median |rel|.

    python benchmarks/packing_study.py --part study [--phis 0.1 0.3] [--paths 100000] [--realizations 8] [--fits]

``--part chart``: the study's chart (benchmarks/out/packing_study.png) from the figures ``--part
study`` wrote: each model's median |rel| against phi on both kinds, and the albedo ratio.

``--part cost``: one realization of about 10^4 equal spheres (phi = 0.6, tile 64, depth 17): the
seconds to generate its packing (an empty cache), to read it back, to build its Embree scene and
to trace --paths paths at normal incidence on one thread.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from report import save_figures

from microsim import config
from microsim import tables as tables_module
from microsim.analysis import compare
from microsim.analysis.fit import fit
from microsim.app import session
from microsim.models.tabulated import TabulatedBRDF
from microsim.testing import trace_table

THETA_I = [0.0, 30.0, 60.0, 80.0]
SCENES = {"packed": {"kind": "packed_spheres", "volume_fraction": 0.01},
          "boolean": {"kind": "poisson_spheres", "volume_fraction": 0.01},
          "transfer": {"kind": "halfspace_medium", "phase": "lambert_sphere"}}


ALBEDOS = [0.3, 0.8, 0.95]
#: the study's retro points (phase angles from the retro direction, deg); the opposition peak is
#: f at the first over f at PEAK_REFERENCE_DEG
RETRO_POINTS_DEG = [0.0, 0.5, 1.0, 2.0, 5.0, 10.0]
PEAK_REFERENCE_DEG = 10.0
#: the finite-size single-scattering model holds at and below this volume fraction
SINGLE_SCATTERING_MAX_PHI = 0.1
#: the models of the study: name -> (model, its parameters given the albedo and the volume fraction)
MODELS = {"lambert_sphere": lambda c, phi: ("lambert_sphere", {"albedo": c, "method": "exact"}),
          "hapke IMSA": lambda c, phi: ("hapke", {"albedo": c, "volume_fraction": phi}),
          "hapke AMSA": lambda c, phi: ("hapke", {"albedo": c, "volume_fraction": phi,
                                                  "multiple_scattering": "anisotropic"})}


#: the fits of the study: label -> (model, free parameters, fixed ones and starts given c and phi)
FITS = {"hapke AMSA fit": ("hapke", ["albedo", "volume_fraction"],
                           lambda c, phi: {"albedo": c, "volume_fraction": min(phi, 0.7),
                                           "multiple_scattering": "anisotropic"}),
        "vmf_diffuse fit": ("vmf_diffuse", ["roughness"], lambda c, phi: {"albedo": c, "roughness": 0.5})}


def table(directory: Path, scene: dict, albedo, paths: int, cells: int, workers: int, realizations: int = 16,
          retro_points: list | None = None):
    """The table of ``scene`` (a list of tables, one per albedo, for a list of albedos traced
    together, as ``microsim run`` traces them) and the seconds it took."""
    sensor = {"cells": cells, **({"retro_points_deg": retro_points} if retro_points else {})}
    data = {"scene": scene, "material": {"kind": "lambert", "albedo": albedo},
            "illumination": {"theta_i_deg": THETA_I}, "sensor": sensor,
            "run": {"paths": paths, "realizations": realizations, "seed": 11}}
    start = time.perf_counter()
    name = f"{scene['kind']}-{scene.get('volume_fraction', 0)}.h5"
    if isinstance(albedo, list):
        outcome = session.run(data, out=directory / name, workers=workers)
        return [tables_module.load(path) for path in outcome.tables], time.perf_counter() - start
    traced = trace_table(config.validate(data), directory / name, workers=workers)
    return traced, time.perf_counter() - start


def pair(a, b) -> dict:
    """``a`` against ``b`` cell by cell: the figures of the module doc."""
    comparison = compare.compare(a, TabulatedBRDF(b))
    metrics = comparison.metrics()
    return {"chi2_per_cell": round(metrics["chi2_per_cell"], 4), "chi2_bounds": [round(x, 4) for x in metrics["chi2_bounds"]],
            "albedo_z2": round(metrics["albedo_z2"], 3), "albedo_z2_bound": round(metrics["albedo_z2_bound"], 3),
            "median_abs_rel": round(float(metrics["median_abs_rel_err"]), 4), "consistent": metrics["consistent"]}


def dilute(args) -> dict:
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        tables = {}
        for name, scene in SCENES.items():
            tables[name], seconds = table(Path(tmp), scene, 0.8, args.paths, args.cells, args.workers)
            out[f"{name} albedo"] = np.round(tables[name].albedo, 5).tolist()
            out[f"{name} albedo stderr"] = np.round(tables[name].albedo_stderr, 5).tolist()
            out[f"{name} seconds"] = round(seconds, 1)
            print(f"{name}: albedo {out[f'{name} albedo']} +- {out[f'{name} albedo stderr']} ({seconds:.1f} s)", flush=True)
        for a, b in (("packed", "boolean"), ("packed", "transfer"), ("boolean", "transfer")):
            out[f"{a} against {b}"] = figures = pair(tables[a], tables[b])
            print(f"{a} against {b}: {figures}", flush=True)
    return out


def study(args) -> dict:
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for phi in args.phis:
            kinds = {}
            for kind in ("packed_spheres", "poisson_spheres"):
                scene = {"kind": kind, "volume_fraction": phi, "statistics": True}
                kinds[kind], seconds = table(Path(tmp), scene, ALBEDOS, args.paths, args.cells, args.workers,
                                             args.realizations, RETRO_POINTS_DEG)
                out[f"{kind} {phi} seconds"] = round(seconds, 1)
                out[f"{kind} {phi} structure"] = structure(kinds[kind][0])
            for j, c in enumerate(ALBEDOS):
                packed, boolean = kinds["packed_spheres"][j], kinds["poisson_spheres"][j]
                ratio = packed.albedo / boolean.albedo
                error = ratio * np.hypot(packed.albedo_stderr / packed.albedo, boolean.albedo_stderr / boolean.albedo)
                row = {"albedo ratio packed / Boolean": np.round(ratio, 4).tolist(),
                       "its stderr": np.round(error, 4).tolist(),
                       "packed albedo": np.round(packed.albedo, 4).tolist(),
                       "Boolean albedo": np.round(boolean.albedo, 4).tolist()}
                for order in ("1", "2", "3", "4+"):
                    metrics = compare.compare(packed, TabulatedBRDF(boolean), order=order).metrics()
                    row[f"order {order} packed against Boolean: chi2 per cell"] = [
                        round(metrics["chi2_per_cell"], 3), [round(x, 3) for x in metrics["chi2_bounds"]]]
                for kind, t in (("packed", packed), ("Boolean", boolean)):
                    peak, error = opposition_peak(t)
                    row[f"opposition peak {kind}"] = np.round(peak, 4).tolist()
                    row[f"opposition peak {kind} stderr"] = np.round(error, 4).tolist()
                if phi <= SINGLE_SCATTERING_MAX_PHI:
                    for kind, t in (("packed", packed), ("Boolean", boolean)):
                        metrics = compare.compare(t, "boolean_spheres_single", order="1", on="points", albedo=c,
                                                  volume_fraction=phi).metrics()
                        row[f"boolean_spheres_single on {kind} order 1 at the retro points"] = {
                            key: metrics[key] for key in ("chi2_per_point", "chi2_bounds", "consistent") if key in metrics}
                for label, make in MODELS.items():
                    name, params = make(c, phi)
                    for kind, t in (("packed", packed), ("Boolean", boolean)):
                        row[f"{label} on {kind}: median |rel|"] = round(
                            compare.compare(t, name, **params).metrics()["median_abs_rel_err"], 4)
                if args.fits:
                    for kind, t in (("packed", packed), ("Boolean", boolean)):
                        for label, (name, free, fixed) in FITS.items():
                            fitted = fit(t, name, free, fixed(c, phi))
                            row[f"{label} on {kind}"] = {
                                "fit": {k: [round(v, 4), round(e, 4)] for k, (v, e) in fitted.free.items()},
                                "chi2_per_dof": round(fitted.chi2_per_dof, 2),
                                "median |rel|": round(fitted.comparison.metrics()["median_abs_rel_err"], 4)}
                out[f"phi {phi}, c {c}"] = row
                print(f"phi {phi}, c {c}: {row}", flush=True)
    return out


def structure(t) -> dict:
    """The void's measured structure (scene/ of a table with statistics): the mean chord over the
    realizations with its standard error, in free paths of the scene (scene/free_path); the share
    of chords shorter than a quarter of it (an exponential law's: 1 - exp(-1/4) = 0.221); and the
    mean first flight from the top at each incidence, from the bins' centres, in free paths."""
    scene, free = t.arrays, float(t.scene["free_path"])
    edges = np.asarray(t.scene["chord_edges"])
    centres = np.append(0.5 * (edges[:-1] + edges[1:]), edges[-1])  # those beyond: at the last edge
    means = scene["scene/mean_chord"]
    chords = scene["scene/chords"].sum(axis=0)
    short = chords[:len(edges) - 1][edges[1:] <= 0.25 * free + 1e-12].sum() / chords.sum()
    top = scene["scene/free_path_top"].sum(axis=0)
    return {"mean chord / l": [round(float(means.mean()) / free, 4),
                               round(float(means.std(ddof=1) / np.sqrt(len(means))) / free, 4)],
            "chords under l/4": round(float(short), 4),
            "mean first flight / l": np.round(top @ centres / top.sum(axis=1) / free, 3).tolist(),
            "free path l": round(free, 4)}


def opposition_peak(t) -> tuple[np.ndarray, np.ndarray]:
    """(n_i,) f at retro over f at PEAK_REFERENCE_DEG from it, and its standard error from the
    points' covariance (they share their paths)."""
    a, b = 0, RETRO_POINTS_DEG.index(PEAK_REFERENCE_DEG)
    f, cov = t.arrays["brdf_points"], t.arrays["brdf_points_covariance"]
    ratio = f[:, a] / f[:, b]
    relative = cov[:, a, a] / f[:, a] ** 2 + cov[:, b, b] / f[:, b] ** 2 - 2 * cov[:, a, b] / (f[:, a] * f[:, b])
    return ratio, ratio * np.sqrt(np.maximum(relative, 0.0))


def cost(args) -> dict:
    import os

    from microsim import geometry
    from microsim.physics.rng import geometry_rng, stream_key
    from microsim.run.plan import Plan

    with tempfile.TemporaryDirectory() as tmp:
        os.environ["MICROSIM_CACHE"] = tmp
        cfg = config.validate({"scene": {"kind": "packed_spheres", "volume_fraction": 0.6, "tile": 64.0, "depth": 17.0},
                               "material": {"kind": "lambert", "albedo": 0.8}, "illumination": {"theta_i_deg": [0.0]},
                               "run": {"paths": args.paths, "realizations": 2, "seed": 5}})
        plan = Plan.from_config(cfg)
        generator, out = geometry.SCENES["packed_spheres"], {}
        for step in ("generate", "read back"):
            start = time.perf_counter()
            scene = generator.generate(plan.scene, plan.config, geometry_rng(5, 0))
            out[f"{step} s"] = round(time.perf_counter() - start, 3)
        out["spheres"] = scene.info["spheres"]
        start = time.perf_counter()
        tracer = plan.tracer_class(scene, plan.sensor, estimators=plan.estimators, **plan.tracer_options)
        out["Embree scene s"] = round(time.perf_counter() - start, 3)
        tracer.trace(plan.incidence_direction(0), 1000, stream_key(5, 0, 0), 0, plan.albedo_scale, 0.0)  # compiled
        start = time.perf_counter()
        tracer.trace(plan.incidence_direction(0), args.paths, stream_key(5, 0, 0), 0, plan.albedo_scale, 0.0)
        out["trace s"] = round(time.perf_counter() - start, 3)
        out["paths"] = args.paths
    print(out)
    return out


def chart(args) -> dict:
    """The study's chart from its figures (benchmarks/out/packing_study_study.json): each model's
    median |rel| against phi on packed (solid) and Boolean (dashed) tables, per albedo; and the
    albedo ratio packed / Boolean against phi at normal and 80 deg incidence, with its errors."""
    import json

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from report import OUT

    figures = json.loads((OUT / "packing_study_study.json").read_text())["study"]
    phis = sorted({float(key.split()[1].rstrip(",")) for key in figures if key.startswith("phi ")})
    rows = {(phi, c): figures[f"phi {phi}, c {c}"] for phi in phis for c in ALBEDOS}
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    for label, colour in zip(MODELS, ("tab:blue", "tab:orange", "tab:green")):
        for c, marker in zip(ALBEDOS, "o^s"):
            for kind, style in (("packed", "-"), ("Boolean", "--")):
                left.plot(phis, [100 * rows[phi, c][f"{label} on {kind}: median |rel|"] for phi in phis], style,
                          marker=marker, color=colour, ms=4, label=f"{label}, c {c}" if kind == "packed" else None)
    left.set(xlabel="volume fraction phi", ylabel="median |rel| over the cells, %",
             title="models on packed (solid) and Boolean (dashed) spheres")
    left.legend(fontsize=6.5, ncol=3)
    for c, marker in zip(ALBEDOS, "o^s"):
        for j, colour in ((0, "tab:purple"), (3, "tab:red")):
            right.errorbar(phis, [rows[phi, c]["albedo ratio packed / Boolean"][j] for phi in phis],
                           yerr=[rows[phi, c]["its stderr"][j] for phi in phis], marker=marker, ms=4, color=colour,
                           capsize=2, label=f"theta_i {THETA_I[j]:g} deg, c {c}")
    right.axhline(1.0, color="grey", lw=0.8)
    right.set(xlabel="volume fraction phi", ylabel="albedo, packed / Boolean", title="packed against Boolean")
    right.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(OUT / "packing_study.png", dpi=110)
    return {"chart": str(OUT / "packing_study.png")}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", choices=["dilute", "study", "cost", "chart"], default="dilute")
    parser.add_argument("--phis", type=float, nargs="+", default=[0.01, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    parser.add_argument("--realizations", type=int, default=8)
    parser.add_argument("--fits", action="store_true", help="fit hapke and vmf_diffuse to every table (study)")
    parser.add_argument("--paths", type=int, default=400_000)
    parser.add_argument("--cells", type=int, default=400)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--json", action="store_true", help="print the figures as JSON on the last line")
    args = parser.parse_args()
    figures = {args.part: {"dilute": dilute, "study": study, "cost": cost, "chart": chart}[args.part](args)}
    save_figures(figures, f"packing_study_{args.part}", args.json)


if __name__ == "__main__":
    main()
