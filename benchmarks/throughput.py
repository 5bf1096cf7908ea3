"""Tracer throughput against raw Embree, and the speed-up of two workers over one.

On one sphere scene (runs/spheres_phi030.toml unless --config is given):

1. trace batches with one worker and count path segments per second of tracing (scene
   building excluded), recording every ray batch handed to Embree;
2. replay exactly those ray batches through ``embreex`` alone (same calls, same sizes), in the
   same process right after, for the raw intersection rate;
3. run the whole config with 2 and 1 workers, three times, alternating (builds included), and
   take the best time of each for the speed-up (the machine's speed drifts by tens of percent).

``ratio`` = segments_per_s / raw_rays_per_s: the share of Embree's own speed the tracer keeps
after its numba kernels. ``outside_embree_ns_per_segment`` is the traced time less the time
inside the Embree calls of the same trace, per segment: what the tracer adds to Embree, measured
without the drift between two runs that makes the ratio noisy on a shared machine. Prints a table, and with --json one JSON object on the last line.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import geometry
from microsim import config as config_module
from microsim import runner
from microsim.integrators.records import SEGMENTS
from microsim.integrators.surface import SurfaceTracer
from microsim.rng import geometry_rng, stream_key
from microsim.sensor import Sensor

ROOT = Path(__file__).resolve().parent.parent


class RecordingScene:
    """Forwards ``run`` to an Embree scene, keeps a copy of every ray batch, times both."""

    def __init__(self, scene):
        self.scene = scene
        self.batches = []
        self.seconds = 0.0

    def run(self, origins, directions, dists, output):
        start = time.perf_counter()  # the copies are the recorder's, not the tracer's: timed with Embree
        self.batches.append((origins.copy(), directions.copy(), dists.copy()))
        hits = self.scene.run(origins, directions, dists=dists, output=output)
        self.seconds += time.perf_counter() - start
        return hits


def tracer_vs_embree(cfg, paths: int, repeats: int = 3):
    plan = runner.Plan.from_config(cfg)
    generator = geometry.SCENES[cfg.scene.kind]
    scene = generator.generate(plan.scene, cfg, geometry_rng(cfg.run.seed, 0))
    tracer = SurfaceTracer(scene, Sensor.build(plan.sensor_cells))
    embree_scene = tracer.embree
    wi = plan.incidence_direction(0)
    tracer.trace(wi, 1000, stream_key(0, 0, 0), 0)  # compile
    best_trace, best_raw, best_outside, segments = np.inf, np.inf, np.inf, 0
    for k in range(repeats):
        tracer.embree = recorder = RecordingScene(embree_scene)
        start = time.perf_counter()
        tally = tracer.trace(wi, paths, stream_key(cfg.run.seed, 0, k), 0)
        elapsed = time.perf_counter() - start
        best_trace = min(best_trace, elapsed)
        best_outside = min(best_outside, elapsed - recorder.seconds)
        segments = int(tally.counts[SEGMENTS])
        start = time.perf_counter()
        for origins, directions, dists in recorder.batches:
            embree_scene.run(origins, directions, dists=dists, output=1)
        best_raw = min(best_raw, time.perf_counter() - start)
    return segments / best_trace, segments / best_raw, best_outside / segments, segments, scene.n_triangles


def worker_speedup(cfg, repeats: int = 3):
    """Best wall time of whole runs with 2 and 1 workers, alternated so both see the same machine."""
    timings = {1: np.inf, 2: np.inf}
    for _ in range(repeats):
        for workers in (2, 1):
            start = time.perf_counter()
            runner.run(cfg, workers=workers)
            timings[workers] = min(timings[workers], time.perf_counter() - start)
    return timings[1] / timings[2], timings


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default=str(ROOT / "runs" / "spheres_phi030.toml"))
    parser.add_argument("--paths", type=int, default=200_000, help="paths of the traced batch")
    parser.add_argument("--run-paths", type=int, default=400_000, help="paths per incidence of the worker runs")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    cfg = config_module.load(args.config)
    run_cfg = config_module.load(args.config, {"run.paths": args.run_paths, "run.realizations": 8})
    speedup, timings = worker_speedup(run_cfg)
    segments_per_s, raw_per_s, outside, segments, triangles = tracer_vs_embree(cfg, args.paths)
    result = {
        "segments_per_s": segments_per_s,
        "raw_rays_per_s": raw_per_s,
        "ratio": segments_per_s / raw_per_s,
        "speedup_2_workers": speedup,
        "outside_embree_ns_per_segment": outside * 1e9,
    }
    print(f"scene: {args.config} ({triangles} triangles), {segments} segments traced")
    print(f"tracer      {segments_per_s / 1e6:8.3f} M segments/s (1 worker)")
    print(f"raw embreex {raw_per_s / 1e6:8.3f} M rays/s on the same ray batches")
    print(f"ratio       {result['ratio']:8.3f}")
    print(f"outside Embree {outside * 1e9:6.1f} ns per segment (numba kernels and Python, best of 3)")
    print(f"run, 1 worker {timings[1]:.1f} s, 2 workers {timings[2]:.1f} s: speed-up {speedup:.2f}")
    if args.json:
        print(json.dumps(result))


if __name__ == "__main__":
    main()
