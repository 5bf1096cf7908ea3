"""One billion paths in V-cavities, and the fastest exact way to intersect a groove.

The setting of Meneveaux et al. 2015, Sec. 3.3 ("one billion light paths and a
sensor containing 3240 cells"): Lambertian facets of albedo 0.8, Beckmann roughness 0.5, one
incidence (theta_i = 45 deg), all orders.

1. Intersectors side by side, one process and one thread, best of --repeats, interleaved:
   - the analytic intersector (the default) and the Embree one (the canonical groove,
     rtcIntersect1 called from numba) trace the same --paths paths (same streams, same grooves):
     segments/s and paths/s of each;
   - the Embree intersector's queries, logged in the order it makes them, replayed through Embree
     alone: raw direct rays/s (rtcIntersect1 from numba, as the tracer calls it:
     ``embree.Scene.intersect``) and raw embreex rays/s (embreex's ``run`` on the same canonical
     mesh, in batches of 1 M rays);
   - the same logged rays through :func:`microsim.tracer.integrators.vcavity.meet_analytic` alone (the
     canonical groove, depth 1): raw analytic rays/s, the cost of the intersection itself;
   - each intersector's segments/s over raw Embree's rays/s on those same rays.
2. The billion: ``microsim.testing.trace`` on --workers processes of one thread, --billion-paths paths in 64
   realizations; the table goes to benchmarks/out/vcavities_billion.h5. Wall time (builds and
   compilation included), paths/s, segments/s, albedo and its standard error.

Writes benchmarks/out/vcavities_billion.png (throughput bars; f1, f2 and f_inf of the billion run
on the plane of incidence) and benchmarks/out/vcavities_billion.json; --json prints that JSON as
the last line. About 8 minutes on this 2-core machine.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numba
import numpy as np
from report import OUT, save_figures

from microsim import config, geometry, tables
from microsim.analysis.plots import incidence_plane_cells
from microsim.core.tally import SEGMENTS
from microsim.physics.rng import stream_key
from microsim.testing import trace
from microsim.tracer import embree
from microsim.tracer.integrators import vcavity
from microsim.tracer.integrators.embreex import embree_scene
from microsim.tracer.integrators.vcavity import VCavityTracer, meet_analytic
from microsim.tracer.sensor import Sensor

THETA_I = 45.0
EMBREEX_BATCH = 1 << 20


@numba.njit(cache=True)
def analytic_replay(origins, directions):
    """meet_analytic on logged canonical rays (depth 1); the sum of t keeps the work observable."""
    total = 0.0
    for k in range(len(origins)):
        facet, t = meet_analytic(0, 0, 0, (np.float64(origins[k, 0]), np.float64(origins[k, 2])),
                                 (np.float64(directions[k, 0]), np.float64(directions[k, 2])), 1.0, -1)
        if facet >= 0:
            total += t
    return total


def settings(paths: int, intersector: str = "analytic") -> dict:
    return {
        "name": "vcavities-billion",
        "scene": {"kind": "vcavities", "distribution": "beckmann", "roughness": 0.5, "intersector": intersector},
        "material": {"kind": "lambert", "albedo": 0.8},
        "illumination": {"theta_i_deg": [THETA_I]},
        "sensor": {"cells": 3240},
        "run": {"paths": paths, "realizations": 64, "seed": 1, "max_order": 0},
    }


def tracer(intersector: str, sensor, log_rays: int = 0) -> VCavityTracer:
    cfg = config.validate(settings(64, intersector))  # only resolves the scene: a run refuses fewer paths than realizations
    generator = geometry.SCENES["vcavities"]
    scene = generator.generate(generator.resolve(cfg), cfg, None)
    return VCavityTracer(scene, sensor, threads=1, log_rays=log_rays)


def side_by_side(paths: int, repeats: int) -> dict:
    """Figure 1 of the module docstring."""
    sensor = Sensor.build(3240)
    wi = np.array([np.sin(np.radians(THETA_I)), 0.0, np.cos(np.radians(THETA_I))])
    tracers = {name: tracer(name, sensor) for name in ("analytic", "embree")}
    for t in tracers.values():  # compile (or load) first
        t.trace(wi, 1000, stream_key(1, 0, 0), 0)
    logger = tracer("embree", sensor, log_rays=1)
    logger.trace(wi, 10, stream_key(1, 0, 0), 0)
    canonical = embree.Scene(vcavity.CANONICAL_VERTICES, vcavity.CANONICAL_FACES)
    canonical.intersect(logger.ray_log[:, :3], logger.ray_log[:, 3:6], logger.ray_log[:, 6])
    analytic_replay(logger.ray_log[:, :3], logger.ray_log[:, 3:6])
    embreex = embree_scene(vcavity.CANONICAL_VERTICES, vcavity.CANONICAL_FACES)
    best, segments = {}, {}
    key = stream_key(1, 0, 0)  # every repeat traces the same paths: its segments are those of the best time
    for _ in range(repeats):
        for name, t in tracers.items():
            start = time.perf_counter()
            tally = t.trace(wi, paths, key, 0)
            best[name] = min(best.get(name, np.inf), time.perf_counter() - start)
            segments[name] = int(tally.counts[SEGMENTS])
        logger = tracer("embree", sensor, log_rays=segments["embree"])
        logger.trace(wi, paths, key, 0)
        log = [np.ascontiguousarray(c) for c in (logger.ray_log[:, :3], logger.ray_log[:, 3:6], logger.ray_log[:, 6])]
        hits = canonical.intersect(*log)  # written once before the clock: the replay times Embree alone
        start = time.perf_counter()
        canonical.intersect(*log, out=hits)
        best["raw_direct"] = min(best.get("raw_direct", np.inf), time.perf_counter() - start)
        parts = [slice(first, first + EMBREEX_BATCH) for first in range(0, len(log[0]), EMBREEX_BATCH)]
        dists = [log[2][part].copy() for part in parts]  # embreex overwrites them
        start = time.perf_counter()
        for part, d in zip(parts, dists):
            embreex.run(log[0][part], log[1][part], dists=d, output=1)
        best["raw_embreex"] = min(best.get("raw_embreex", np.inf), time.perf_counter() - start)
        start = time.perf_counter()
        analytic_replay(log[0], log[1])
        best["raw_analytic"] = min(best.get("raw_analytic", np.inf), time.perf_counter() - start)
    rays = segments["embree"]
    out = {"paths": paths, "segments_analytic": segments["analytic"], "segments_embree": rays,
           "raw_direct_rays_per_s": rays / best["raw_direct"], "raw_embreex_rays_per_s": rays / best["raw_embreex"],
           "raw_analytic_rays_per_s": rays / best["raw_analytic"]}
    for name in ("analytic", "embree"):
        out[f"{name}_segments_per_s"] = segments[name] / best[name]
        out[f"{name}_paths_per_s"] = paths / best[name]
        out[f"{name}_over_raw_direct"] = out[f"{name}_segments_per_s"] / out["raw_direct_rays_per_s"]
        out[f"{name}_over_raw_embreex"] = out[f"{name}_segments_per_s"] / out["raw_embreex_rays_per_s"]
    return out


def billion(paths: int, workers: int) -> tuple[dict, Path]:
    """Figure 2 of the module docstring."""
    cfg = config.validate(settings(paths))
    start = time.perf_counter()
    result = trace(cfg, workers=workers)
    wall = time.perf_counter() - start
    OUT.mkdir(exist_ok=True)
    path = tables.write(OUT / "vcavities_billion.h5", result, cfg, overwrite=True)
    segments = int(result.counts[0, SEGMENTS])
    return {"paths": int(result.paths[0]), "workers": workers, "wall_s": wall, "paths_per_s": result.paths[0] / wall,
            "segments": segments, "segments_per_s": segments / wall, "segments_per_path": segments / result.paths[0],
            "albedo": float(result.albedo[0].mean[4]), "albedo_stderr": float(result.albedo[0].stderr[4]),
            "within_15_min": wall <= 900.0}, path


def chart(speed: dict, run: dict, table_path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(13, 4.8))
    names = ["tracer,\nanalytic", "tracer,\nembree", "raw Embree\n(direct)", "raw embreex", "raw analytic\nintersection"]
    values = [speed["analytic_segments_per_s"], speed["embree_segments_per_s"], speed["raw_direct_rays_per_s"],
              speed["raw_embreex_rays_per_s"], speed["raw_analytic_rays_per_s"]]
    bars = left.bar(names, np.array(values) / 1e6, color=["C2", "C0", "grey", "lightgrey", "C2"])
    left.bar_label(bars, fmt="%.1f", fontsize=8)
    left.set_ylabel("M segments (rays) / s, one thread")
    left.set_title("same paths, same Embree queries, side by side", fontsize=10)
    table = tables.load(table_path)
    x, cells = incidence_plane_cells(table.sensor, table.phi_i[0])
    a = table.arrays
    for values, errors, label in ((table.brdf_order[0, 0], a["brdf_order_stderr"][0, 0], "f1"),
                                  (a["brdf_orders12"][0], a["brdf_orders12_stderr"][0], "f2"),
                                  (table.brdf[0], table.brdf_stderr[0], "f_inf")):
        right.errorbar(x, values[cells], yerr=errors[cells], fmt="o-", ms=2.5, lw=1, capsize=1.5, label=label)
    right.axvline(-THETA_I, color="grey", ls=":", lw=1, label="retro direction")
    right.set_xlabel("theta_o (deg): backscatter side < 0 < specular side")
    right.set_ylabel("f (1/sr)")
    right.set_title(f"{run['paths']:.3g} paths, {run['wall_s']:.0f} s on {run['workers']} workers; "
                    f"theta_i = {THETA_I:g} deg", fontsize=10)
    right.legend(fontsize=8)
    fig.suptitle("Lambertian V-cavities (albedo 0.8, Beckmann 0.5), 3240 cells", fontsize=11)
    fig.tight_layout()
    path = OUT / "vcavities_billion.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paths", type=int, default=2_000_000, help="paths of the side-by-side measurement")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--billion-paths", type=int, default=1_000_000_000)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    speed = side_by_side(args.paths, args.repeats)
    print(f"side by side, one thread, {args.paths} paths, best of {args.repeats}:")
    for name in ("analytic", "embree"):
        print(f"  {name:9s} intersector: {speed[f'{name}_segments_per_s'] / 1e6:7.2f} M segments/s "
              f"{speed[f'{name}_paths_per_s'] / 1e6:6.2f} M paths/s; / raw direct Embree "
              f"{speed[f'{name}_over_raw_direct']:.2f}, / raw embreex {speed[f'{name}_over_raw_embreex']:.2f}")
    print(f"  on the same rays: raw Embree direct {speed['raw_direct_rays_per_s'] / 1e6:.2f} M rays/s, "
          f"raw embreex {speed['raw_embreex_rays_per_s'] / 1e6:.2f} M rays/s, "
          f"analytic intersection alone {speed['raw_analytic_rays_per_s'] / 1e6:.2f} M rays/s")
    run, table_path = billion(args.billion_paths, args.workers)
    print(f"billion: {run['paths']} paths on {run['workers']} workers in {run['wall_s']:.1f} s: "
          f"{run['paths_per_s'] / 1e6:.2f} M paths/s, {run['segments_per_s'] / 1e6:.2f} M segments/s "
          f"({run['segments_per_path']:.3f} segments a path); albedo {run['albedo']:.6f} +- {run['albedo_stderr']:.1e}; "
          f"within 15 min: {run['within_15_min']}")
    png = chart(speed, run, table_path)
    print(f"wrote {png}, {table_path}")
    save_figures({"side_by_side": speed, "billion": run, "table": str(table_path), "chart": str(png)},
                 "vcavities_billion", args.json)


if __name__ == "__main__":
    main()
