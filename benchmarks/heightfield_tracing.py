"""A Gaussian heightfield traced as a heightfield (the grid backend's walk) against Embree's
triangles: which is faster, for the same surface.

The surface of runs/gaussian_alpha08_lambert.toml (alpha 0.8, its default tile: 228^2 samples,
about 104 000 triangles; --run picks another heightfield run), its first realization, laid twice:
``intersector = "triangles"`` (Embree, the direct backend) and ``"grid"``
(microsim/tracer/integrators/grid.py). At each incidence, single-threaded, best of --repeats:

1. the tracer: --paths paths on each, ns a segment (the same paths: the same random streams);
2. the queries alone: every query the direct backend made to Embree (origin, direction, tfar),
   in order, answered by Embree (rtcIntersect1) and by the walk (``grid.walk``), ns a query.
   Both must find the same hits: hit or miss agree, and t to float32's precision (the fractions
   that do not are printed);
3. whole runs (``microsim.testing.trace``, --run-paths an incidence, 8 realizations, every incidence, a
   surface generated a realization, 1 and 2 threads), alternated.

Printed and written (benchmarks/out/heightfield_tracing.json). Results:
docs/developer/performance.md ("Gaussian heightfields: triangles or a grid walk").

    python benchmarks/heightfield_tracing.py [--paths 20000] [--repeats 3] [--run-paths 200000] [--json]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from report import save_figures  # noqa: E402
from throughput import fused_trace, grid_trace, load, realization, replay, replay_direct  # noqa: E402

from microsim.core.tally import SEGMENTS  # noqa: E402
from microsim.physics.rng import stream_key  # noqa: E402
from microsim.testing import trace
from microsim.tracer.integrators.grid import fill_first_hits, first_hits  # noqa: E402
from microsim.tracer.integrators.records import Beam  # noqa: E402
from microsim.tracer.sensor import Sensor  # noqa: E402


def measure(cfg, paths: int, repeats: int) -> dict:
    """Figures 1-3 of the module doc at each incidence of ``cfg``."""
    _, plan, scene = realization(cfg)
    gridded = cfg.model_copy(update={"scene": cfg.scene.model_copy(update={"intersector": "grid"})})
    grid_scene = realization(gridded)[2]
    assert np.array_equal(grid_scene.vertices, scene.vertices)  # the same realization
    sensor = Sensor.build(cfg.sensor.cells)
    out = {"samples": len(grid_scene.grid.heights), "triangles": scene.n_triangles, "incidences": {}}
    for k in range(len(cfg.illumination.theta_i_deg)):
        wi = np.asarray(plan.incidence_direction(k), np.float64)
        warm = Beam(wi, np.uint64(0), 200, 0)
        fused_trace(scene, sensor, warm, 1, log_rays=1)
        grid_trace(grid_scene, sensor, warm, 1)
        beam = Beam(wi, np.uint64(stream_key(cfg.run.seed, 0, k)), paths, 0)
        embree_runs = [fused_trace(scene, sensor, beam, 1) for _ in range(repeats)]
        grid_runs = [grid_trace(grid_scene, sensor, beam, 1) for _ in range(repeats)]
        segments = int(embree_runs[0][1].counts[SEGMENTS])
        grid_segments = int(grid_runs[0][1].counts[SEGMENTS])
        logger = fused_trace(scene, sensor, beam, 1, log_rays=segments)[2]
        log = [np.ascontiguousarray(c) for c in (logger.ray_log[:, :3], logger.ray_log[:, 3:6], logger.ray_log[:, 6])]
        prim, t_embree, _ = logger.embree.intersect(*log)
        embree_s = min(replay_direct(logger) for _ in range(repeats))
        faces, walked = first_hits(grid_scene.grid, *log)
        walk_s = min(replay([log], lambda o, d, t: fill_first_hits(grid_scene.grid, o, d, t, faces, walked))
                     for _ in range(repeats))
        hit_e, hit_w = prim >= 0, faces >= 0
        both = hit_e & hit_w
        close = np.abs(walked[both] - t_embree[both]) <= 1e-5 * np.maximum(1.0, t_embree[both])
        theta = cfg.illumination.theta_i_deg[k]
        f = out["incidences"][f"{theta:g}"] = {
            "queries": len(walked), "embree_ns_per_query": embree_s / len(walked) * 1e9,
            "walk_ns_per_query": walk_s / len(walked) * 1e9, "hit_disagree": float(np.mean(hit_e != hit_w)),
            "t_disagree": float(1.0 - close.mean()), "hit_fraction": float(hit_e.mean()),
            "triangles_ns_per_segment": min(r[0] for r in embree_runs) / segments * 1e9,
            "grid_ns_per_segment": min(r[0] for r in grid_runs) / grid_segments * 1e9,
            "grid_segments_over_triangles": grid_segments / segments}
        f["grid_speedup"] = f["triangles_ns_per_segment"] / f["grid_ns_per_segment"]
        print(f"theta_i {theta:g}: {f['queries']} queries, Embree {f['embree_ns_per_query']:.0f} ns, walk "
              f"{f['walk_ns_per_query']:.0f} ns; hit/miss disagree {f['hit_disagree']:.1e}, t disagree "
              f"{f['t_disagree']:.1e}; tracer {f['triangles_ns_per_segment']:.0f} ns a segment on triangles, "
              f"{f['grid_ns_per_segment']:.0f} on the grid (x{f['grid_speedup']:.2f})", flush=True)
    return out


def whole_runs(cfg, repeats: int) -> dict:
    """Seconds of a whole run (microsim.testing.trace) with each intersector on 1 and 2 threads (surfaces generated), alternated."""
    best = {}
    for _ in range(repeats):
        for threads in (1, 2):
            for intersector in ("triangles", "grid"):
                run = cfg.model_copy(update={"scene": cfg.scene.model_copy(update={"intersector": intersector})})
                start = time.perf_counter()
                trace(run, threads=threads)
                key = f"{intersector}_{threads}_threads_s"
                best[key] = min(best.get(key, math.inf), time.perf_counter() - start)
    for threads in (1, 2):
        print(f"whole runs ({cfg.run.paths} paths an incidence, {cfg.run.realizations} realizations, {threads} "
              f"threads): triangles {best[f'triangles_{threads}_threads_s']:.2f} s, grid "
              f"{best[f'grid_{threads}_threads_s']:.2f} s", flush=True)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", default="gaussian_alpha08_lambert")
    parser.add_argument("--paths", type=int, default=20_000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--run-paths", type=int, default=200_000, help="paths an incidence of the whole runs")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    cfg = load(args.run, args.run_paths)
    start = time.perf_counter()
    figures = measure(cfg, args.paths, args.repeats)
    figures["whole_runs"] = whole_runs(cfg, args.repeats)
    figures["seconds"] = time.perf_counter() - start
    save_figures(figures, "heightfield_tracing", args.json)


if __name__ == "__main__":
    main()
