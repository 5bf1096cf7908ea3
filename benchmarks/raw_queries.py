"""Raw closest-hit queries on the same triangles and the same rays: microsim's Embree scene, built
as it is and as Mitsuba 3 builds its own, against Mitsuba 3's ``scene.ray_intersect``.

For each scene (--scenes: runs/gaussian_alpha08_lambert.toml, its first realization's 103 058
triangles; runs/spheres_phi030.toml as the generator's icospheres, mesh_error 0.01, the triangles
a Mitsuba user would trace) and incidence (--theta-index: the config's incidences by index), the
direct backend traces --paths paths on the triangles and logs every query it makes, in order
(origin, direction, tfar: float32). The same queries are then answered, in rounds that alternate
every way (this machine's speed drifts by 10-20 % over minutes; a round sees the same load), by:

- ``embree medium robust``: microsim's scene before the rebuild (build quality MEDIUM,
  RTC_SCENE_FLAG_ROBUST);
- ``embree high robust``: build quality HIGH (Mitsuba's ``rtcSetSceneBuildQuality``) and robust;
- ``embree high``: Mitsuba's own settings, HIGH and no flag (RTC_SCENE_FLAG_NONE: faster, and not
  watertight: a ray through a shared edge may pass between the triangles);
- ``mitsuba preliminary``, 1 and 2 threads: Mitsuba 3 (variant llvm_ad_rgb, Dr.Jit's LLVM backend,
  its Embree through rtcIntersect8 on AVX2) ``scene.ray_intersect_preliminary`` on the whole
  wavefront, evaluated (``dr.eval``) to t and the primitive; ``mitsuba ray_intersect``, 1 thread:
  ``scene.ray_intersect``, which also computes the surface interaction.

microsim's queries are rtcIntersect1 calls from a numba loop, one thread (:meth:`microsim.tracer.embree.Scene.intersect`,
into arrays written once before the clock). Each way's best round is reported in ns a query, and
the ratio of each to Mitsuba's preliminary query on one thread, per round (its median and range):
the per-thread comparison. Hit or miss and the primitive are compared with Mitsuba's (the
fraction that agree); t to float32 precision.

    python benchmarks/raw_queries.py [--scenes gaussian_alpha08_lambert spheres_phi030] [--paths 100000]
                                     [--rounds 7] [--json]

Needs the ``render`` extra (Mitsuba 3). Results: docs/developer/performance.md, "Raw queries:
microsim's Embree scene against Mitsuba 3's".
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from throughput import FORMER_MESH_ERROR, fused_trace, load, realization  # noqa: E402

from microsim.core.tally import SEGMENTS  # noqa: E402
from microsim.physics.rng import stream_key  # noqa: E402
from microsim.tracer import embree  # noqa: E402
from microsim.tracer.integrators.records import Beam  # noqa: E402
from microsim.tracer.sensor import Sensor  # noqa: E402

#: microsim's builds: (label, build quality, robust)
BUILDS = (("embree medium robust", embree.BUILD_QUALITY_MEDIUM, True),
          ("embree high robust", embree.BUILD_QUALITY_HIGH, True),
          ("embree high", embree.BUILD_QUALITY_HIGH, False))


def logged_queries(cfg, theta_index: int, paths: int):
    """(triangle scene, origins, directions, tfar) of every query the direct backend makes tracing
    ``paths`` paths at incidence ``theta_index`` of the config's first realization (spheres as
    the generator's icospheres)."""
    _, plan, mesh = realization(cfg, mesh_error=FORMER_MESH_ERROR)
    sensor = Sensor.build(cfg.sensor.cells)
    beam = Beam(np.asarray(plan.incidence_direction(theta_index), np.float64),
                np.uint64(stream_key(cfg.run.seed, 0, 0)), paths, 0)
    _, tally, _ = fused_trace(mesh, sensor, beam, 1)
    _, _, logger = fused_trace(mesh, sensor, beam, 1, log_rays=int(tally.counts[SEGMENTS]))
    log = logger.ray_log
    return mesh, *(np.ascontiguousarray(c) for c in (log[:, :3], log[:, 3:6], log[:, 6]))


def microsim_way(mesh, quality: int, robust: bool, queries):
    """(seconds of one replay, (prim, t)) of a scene of ``mesh``'s triangles built so."""
    scene = embree.Scene(mesh.vertices, mesh.faces, quality=quality, robust=robust)
    hits = scene.intersect(*queries)

    def replay():
        start = time.perf_counter()
        scene.intersect(*queries, out=hits)
        return time.perf_counter() - start

    return replay, hits


def mitsuba_way(mesh, queries):
    """(replays by name, (prim, t) of Mitsuba's preliminary query) on a Mitsuba 3 scene of the
    same triangles."""
    import drjit as dr
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    surface = mi.Mesh("triangles", len(mesh.vertices), len(mesh.faces))
    params = mi.traverse(surface)
    params["vertex_positions"] = mi.Float(np.asarray(mesh.vertices, np.float32).ravel())
    params["faces"] = mi.UInt32(np.asarray(mesh.faces, np.uint32).ravel())
    params.update()
    scene = mi.load_dict({"type": "scene", "triangles": surface})
    origins, directions, tfar = queries
    ray = mi.Ray3f(mi.Point3f(*(mi.Float(origins[:, k]) for k in range(3))),
                   mi.Vector3f(*(mi.Float(directions[:, k]) for k in range(3))), mi.Float(tfar), 0.0,
                   mi.Color0f())
    dr.eval(ray)

    def timed(threads: int, full: bool):
        def replay():
            dr.set_thread_count(threads)
            dr.sync_thread()
            start = time.perf_counter()
            if full:
                si = scene.ray_intersect(ray, mi.RayFlags.All, False)
                dr.eval(si.t, si.prim_index)
            else:
                pi = scene.ray_intersect_preliminary(ray, coherent=False)
                dr.eval(pi.t, pi.prim_index)
            dr.sync_thread()
            return time.perf_counter() - start
        return replay

    ways = {"mitsuba preliminary": timed(1, False), "mitsuba preliminary 2 threads": timed(2, False),
            "mitsuba ray_intersect": timed(1, True)}
    for replay in ways.values():
        replay()  # Dr.Jit compiles each kernel once: before the clock
    dr.set_thread_count(1)
    pi = scene.ray_intersect_preliminary(ray, coherent=False)
    t = pi.t.numpy()
    prim = np.where(np.isfinite(t), pi.prim_index.numpy().astype(np.int64), -1)
    return ways, (prim, t)


def measure(cfg, theta_index: int, paths: int, rounds: int) -> dict:
    mesh, *queries = logged_queries(cfg, theta_index, paths)
    ways, hits = {}, {}
    for label, quality, robust in BUILDS:
        ways[label], hits[label] = microsim_way(mesh, quality, robust, queries)
    mitsuba, hits["mitsuba"] = mitsuba_way(mesh, queries)
    ways.update(mitsuba)
    seconds = {label: [] for label in ways}
    names = list(ways)
    for k in range(rounds):
        for label in names[k % len(names):] + names[:k % len(names)]:  # each round starts elsewhere
            seconds[label].append(ways[label]())
    n = len(queries[0])
    reference = np.array(seconds["mitsuba preliminary"])
    prim_m, t_m = hits["mitsuba"]
    out = {"triangles": int(mesh.n_triangles), "queries": n, "theta_i_deg": float(cfg.illumination.theta_i_deg[theta_index]),
           "ways": {}}
    for label, times in seconds.items():
        times = np.array(times)
        figures = {"ns_per_query": float(times.min() / n * 1e9),
                   "over_mitsuba_median": float(np.median(reference / times)),
                   "over_mitsuba_range": [float((reference / times).min()), float((reference / times).max())]}
        if label in hits:
            prim, t = hits[label][0], hits[label][1]
            both = (prim >= 0) & (prim_m >= 0)
            figures["agree_with_mitsuba"] = float(np.mean(prim == prim_m))
            figures["t_within_float32"] = float(np.mean(np.abs(t[both] - t_m[both]) <= 4e-7 * np.maximum(t_m[both], 1.0)))
        out["ways"][label] = figures
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="+", default=["gaussian_alpha08_lambert", "spheres_phi030"])
    parser.add_argument("--theta-index", type=int, nargs="+", default=None,
                        help="incidences by index in the config (default: the first and, on the heightfield, the last)")
    parser.add_argument("--paths", type=int, default=100_000)
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    results = {}
    for run in args.scenes:
        cfg = load(run, args.paths)
        indices = args.theta_index or ([0, len(cfg.illumination.theta_i_deg) - 1]
                                       if cfg.scene.kind == "heightfield" else [0])
        for index in indices:
            figures = measure(cfg, index, args.paths, args.rounds)
            label = f"{run} at {figures['theta_i_deg']:g} deg"
            results[label] = figures
            print(f"{label}: {figures['triangles']} triangles, {figures['queries']} queries")
            for way, f in figures["ways"].items():
                agree = (f"; hits as Mitsuba's {f['agree_with_mitsuba']:.6f}, t {f['t_within_float32']:.6f}"
                         if "agree_with_mitsuba" in f else "")
                print(f"  {way:30s} {f['ns_per_query']:7.1f} ns/query, Mitsuba's 1-thread time over it "
                      f"{f['over_mitsuba_median']:.3f} ({f['over_mitsuba_range'][0]:.3f}-{f['over_mitsuba_range'][1]:.3f})"
                      + agree, flush=True)
    if args.json:
        print(json.dumps(results))


if __name__ == "__main__":
    main()
