"""Throughput of both Embree backends against raw Embree, on the sphere scenes phi = 0.1, 0.3, 0.6,
a micrograin field and a Gaussian heightfield.

For each scene (runs/spheres_phi0XX.toml, runs/micrograins_fig18_conductor_on_lambert.toml,
runs/gaussian_alpha08_lambert.toml: its first realization and incidence, --scenes picks others),
measured side by side in one run, best of --repeats:

1. old backend (``embreex``: one embreex.run per segment of every live path) on the spheres
   tessellated at mesh error 0.01 (icosphere level 2): one thread traces
   --paths paths, recording every ray batch handed to Embree; the batches are replayed through
   embreex alone: raw embreex rays/s, the tracer's segments/s and paths/s, their ratio, and the
   tracer's time outside Embree per segment (from the same trace, free of run-to-run drift);
2. new backend (``direct``: numba calls Embree, fused kernel) on exact native spheres (grains:
   native spheres in the instance of their unit frame): the same
   number of paths with 1 and 2 threads, segments/s and paths/s. One more trace logs every query
   in the order the kernel makes them (``DirectBackend(log_rays=...)``); they are replayed
   through rtcIntersect1 alone, in that order: raw direct rays/s, and
   ``direct_ratio_per_thread`` = segments/s with 1 thread / raw direct rays/s on the same rays,
   and ``direct_outside_embree_ns_per_segment``, the tracer's time beyond the replay's per segment
   (what the ratio charges to the kernel, whatever Embree costs on the scene).
   (Order matters: the same rays shuffled run 1.5 times slower in Embree.) On a micrograin
   scene, also ``direct_ratio_absorbing``: that ratio with grains and base absorbing, the
   kernel's floor (a path is its start, one query and one absorption).
3. the sphere grid (``intersector = "grid"``, microsim/tracer/integrators/sphere_grid.py; sphere
   scenes only) on the same exact spheres, the cells built from the same realization: segments/s
   with 1 and 2 threads, ``grid_over_direct_per_thread`` (segments/s on one thread against the
   direct backend's), the walk alone replayed on the direct backend's logged queries (ns a query,
   beside raw direct Embree's on the same rays: ``grid_walk_ns_per_query``) and the tracer's time
   beyond the walk (``grid_outside_walk_ns_per_segment``).
4. whole runs, builds included (--run-paths per incidence, 8 realizations, all the run's
   incidences: 4 on the spheres and grains, 5 on the heightfield): old backend with 1 and 2
   worker processes, new backend (Embree's spheres) with 1 and 2 threads, and on sphere scenes
   the sphere grid with 1 and 2 threads, alternated.

A triangle scene (``kind = "heightfield"``, or ``"mesh"`` given with --scenes) has nothing to
tessellate: both backends trace the same realization's triangles (``spheres`` is 0), so the raw
embreex and raw direct figures are Embree on the same triangles, in the wavefront's batches and
in the kernel's order. The heightfield (label ``gaussian alpha = 0.8, lambert``: a periodic
Gaussian surface of Beckmann alpha 0.8, about 100 000 triangles with the default tile,
Lambertian albedo 0.8 with multiple scattering, drawn afresh each realization) is traced with
``statistics`` off (a conductor run's NDF and masking measurements are shadow rays at scene
generation, not tracing); it also reports ``direct_ratio_absorbing``. Its time outside Embree a
segment grows with the triangles (the per-facet shape data read at each hit): 14, 24, 69 and
153 ns a segment at 2 300, 8 700, 35 000 and 103 000 triangles (tile 4, 8, 16 and the default),
ratio 0.89, 0.83, 0.71 and 0.58, against 73 ns and 0.78 on exact spheres phi = 0.3 in the same
process (load 1.5 on 2 cores). Its whole runs generate a surface a realization (0.3 to 0.45 s,
once per realization on any number of threads, in parallel on 2 workers): there builds weigh as
much as tracing.

Prints a table and writes benchmarks/out/throughput.png; with --json, one JSON object on the
last line. Its top-level keys ``segments_per_s``, ``raw_rays_per_s``, ``ratio``,
``speedup_2_workers`` and ``outside_embree_ns_per_segment`` are those of the old backend on
phi = 0.3, as before; ``scenes`` holds every figure per scene. About 10 minutes on 2 cores
before the heightfield, which adds about a fifth of what phi = 0.3 takes (95 against 484 s,
load about 2); ``--scenes spheres_phi010 spheres_phi030 spheres_phi060
micrograins_fig18_conductor_on_lambert`` leaves it out.

The replay writes its hits into arrays written once before the clock starts. Into fresh arrays
it would also time the first writes to their pages: 10 ns a ray on the micrograin scene (95
against 105 ns), or nothing where the allocator hands back pages already touched. Replays into
fresh arrays made the same code and scene read 0.75 to 0.84 in different processes, and short
scripts read higher ratios than this benchmark: their reference was slower, not the tracer
faster. Compare versions by alternating whole processes, several of each, not one run of each.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from microsim import config as config_module
from microsim.core.tally import SEGMENTS
from microsim.geometry import sphere_cells
from microsim.physics.rng import geometry_rng, stream_key
from microsim.run.plan import Plan
from microsim.testing import trace
from microsim.tracer.estimators import DEFAULT, build, setups
from microsim.tracer.integrators.direct import DirectBackend
from microsim.tracer.integrators.embreex import EmbreexBackend, embree_scene
from microsim.tracer.integrators.records import Beam
from microsim.tracer.integrators.sphere_grid import SphereCells
from microsim.tracer.integrators.surface import walker_of
from microsim.tracer.sensor import Sensor

ROOT = Path(__file__).resolve().parent.parent
SPHERE_RUNS = ("spheres_phi010", "spheres_phi030", "spheres_phi060")
MICROGRAIN_RUN = "micrograins_fig18_conductor_on_lambert"
HEIGHTFIELD_RUN = "gaussian_alpha08_lambert"
OUT = Path(__file__).resolve().parent / "out"
FORMER_MESH_ERROR = 0.01


class Recorder:
    """embreex's ``run`` contract in front of either backend's Embree: keeps a copy of every ray
    batch and times the calls (copies included: they are the recorder's, not the tracer's)."""

    def __init__(self, run):
        self._run = run
        self.batches = []
        self.seconds = 0.0

    def run(self, origins, directions, dists, output):
        start = time.perf_counter()
        self.batches.append((origins.copy(), directions.copy(), dists.copy()))
        hits = self._run(origins, directions, dists)
        self.seconds += time.perf_counter() - start
        return hits


def embreex_run(scene):
    committed = embree_scene(scene.vertices, scene.faces)
    return lambda o, d, dists: committed.run(o, d, dists=dists, output=1)


def tessellated(cfg) -> bool:
    """Whether the scene has spheres that the old backend traces tessellated (``mesh_error``): a
    triangle scene (heightfield, mesh) is the same triangles on both backends."""
    return "mesh_error" in type(cfg.scene).model_fields


def realization(cfg, **scene_keys):
    if not tessellated(cfg):
        scene_keys = {}  # nothing to tessellate: its triangles as they are
    cfg = cfg.model_copy(update={"scene": cfg.scene.model_copy(update=scene_keys)})
    plan = Plan.from_config(cfg)
    return cfg, plan, plan.generator.generate(plan.scene, cfg, geometry_rng(cfg.run.seed, 0))


def wavefront_trace(scene, sensor, run, beam):
    """Trace ``beam`` with the wavefront loop on ``run``; (seconds, tally, recorder)."""
    recorder = Recorder(run)
    estimators = build(DEFAULT, sensor)
    backend = EmbreexBackend(scene, estimators, embree=recorder)
    kernel_setups = setups(estimators, beam.wi, 0.0)
    start = time.perf_counter()
    tally = backend.trace(beam, scene.arrays(), kernel_setups)
    return time.perf_counter() - start, tally, recorder


def replay(batches, run) -> float:
    """Seconds ``run`` takes on every batch; the copies of their distances (which embreex
    overwrites) are made before the clock starts."""
    dists = [d.copy() for _, _, d in batches]
    start = time.perf_counter()
    for (origins, directions, _), d in zip(batches, dists):
        run(origins, directions, d)
    return time.perf_counter() - start


def replay_direct(logger) -> float:
    """Seconds raw Embree takes on the queries of ``logger`` (a DirectBackend that kept a ray log),
    in their order: the log is copied into columns and the hits written once before the clock,
    so that the replay times Embree alone (module doc)."""
    log = [np.ascontiguousarray(c) for c in (logger.ray_log[:, :3], logger.ray_log[:, 3:6], logger.ray_log[:, 6])]
    hits = logger.embree.intersect(*log)
    return replay([log], lambda o, d, t: logger.embree.intersect(o, d, t, out=hits))


def fused_trace(scene, sensor, beam, threads: int, log_rays: int = 0):
    """(seconds, tally, backend) of the direct backend tracing ``beam``."""
    estimators = build(DEFAULT, sensor)
    backend = DirectBackend(scene, estimators, threads, log_rays)
    kernel_setups = setups(estimators, beam.wi, 0.0)
    start = time.perf_counter()
    tally = backend.trace(beam, scene.arrays(), kernel_setups)
    return time.perf_counter() - start, tally, backend


def grid_trace(scene, sensor, beam, threads: int):
    """(seconds, tally) of the backend that walks ``scene.grid`` (sphere cells or a height grid)
    tracing ``beam`` through ``scene``."""
    estimators = build(DEFAULT, sensor)
    backend = walker_of(scene.grid).backend(scene, threads, estimators)
    kernel_setups = setups(estimators, beam.wi, 0.0)
    start = time.perf_counter()
    tally = backend.trace(beam, scene.arrays(), kernel_setups)
    return time.perf_counter() - start, tally


def replay_walk(cells, logger) -> float:
    """Seconds the grid's walk (a sphere grid's or a height grid's) takes on the queries of
    ``logger``, in their order, into arrays written before the clock."""
    log = [np.ascontiguousarray(c) for c in (logger.ray_log[:, :3], logger.ray_log[:, 3:6], logger.ray_log[:, 6])]
    walker = walker_of(cells)
    hits = walker.first_hits(cells, *log)  # compiled (or loaded), and the hits written, before the clock
    return replay([log], lambda o, d, t: walker.fill_first_hits(cells, o, d, t, *hits))


def gridded(cfg) -> bool:
    """Whether the scene can be walked by a grid: exact spheres or grains (``intersector``
    "grid"), or a heightfield."""
    return cfg.scene.kind == "heightfield" or ("intersector" in type(cfg.scene).model_fields and tessellated(cfg))


def grid_cells(cfg, plan, exact):
    """The cells a grid walks for the realization ``exact`` of ``cfg``: a heightfield's height grid
    (the same realization generated with ``intersector = "grid"``), the sphere cells of spheres or
    grains as their generators build them."""
    if cfg.scene.kind == "heightfield":
        return realization(cfg.model_copy(update={"scene": cfg.scene.model_copy(update={"intersector": "grid"})}))[2].grid
    if cfg.scene.kind == "micrograins":
        return sphere_cells.build(exact, sphere_cells.GRAIN_SIDE)
    return sphere_cells.build(exact, sphere_cells.void_side(exact, plan.scene["free_path"]))


def measure_scene(cfg, paths: int, repeats: int, old: bool = True) -> dict:
    """Figures 1 and 2 of the module docstring for one config (``old`` False: not figure 1)."""
    sensor = Sensor.build(cfg.sensor.cells)
    _, plan, mesh = realization(cfg, mesh_error=FORMER_MESH_ERROR)
    exact = realization(cfg, mesh_error=None, subdivisions=None)[2] if tessellated(cfg) else mesh
    wi = plan.incidence_direction(0)
    out = {"triangles": mesh.n_triangles, "spheres": len(exact.spheres)}
    warm = Beam(np.asarray(wi, np.float64), np.uint64(0), 1000, 0)  # compile (or load) every kernel first
    if old:
        embreex = embreex_run(mesh)
        replay(wavefront_trace(mesh, sensor, embreex, warm)[2].batches, embreex)
    _, _, logger = fused_trace(exact, sensor, warm, 1, log_rays=1)
    logger.embree.intersect(logger.ray_log[:, :3], logger.ray_log[:, 3:6], logger.ray_log[:, 6])
    grid = gridded(cfg)
    if grid:
        exact.grid = grid_cells(cfg, plan, exact)
        grid_trace(exact, sensor, warm, 1)
    best = {}
    for k in range(repeats):
        b = Beam(np.asarray(wi, np.float64), np.uint64(stream_key(cfg.run.seed, 0, k)), paths, 0)
        if old:
            seconds, tally, recorder = wavefront_trace(mesh, sensor, embreex, b)
            old_segments = int(tally.counts[SEGMENTS])
            best["old"] = min(best.get("old", np.inf), seconds)
            best["old_outside"] = min(best.get("old_outside", np.inf), seconds - recorder.seconds)
            best["raw_embreex"] = min(best.get("raw_embreex", np.inf), replay(recorder.batches, embreex))
        for threads in (1, 2):
            seconds, fused_tally, _ = fused_trace(exact, sensor, b, threads)
            best[f"new_{threads}"] = min(best.get(f"new_{threads}", np.inf), seconds)
        new_segments = int(fused_tally.counts[SEGMENTS])
        _, _, logger = fused_trace(exact, sensor, b, 1, log_rays=new_segments)
        best["raw_direct"] = min(best.get("raw_direct", np.inf), replay_direct(logger))
        if grid:
            for threads in (1, 2):
                seconds, grid_tally = grid_trace(exact, sensor, b, threads)
                best[f"grid_{threads}"] = min(best.get(f"grid_{threads}", np.inf), seconds)
            best["walk"] = min(best.get("walk", np.inf), replay_walk(exact.grid, logger))
    out.update({"new_segments": new_segments, "raw_direct_rays_per_s": new_segments / best["raw_direct"]})
    if old:
        out.update({
            "old_segments": old_segments, "raw_embreex_rays_per_s": old_segments / best["raw_embreex"],
            "old_segments_per_s": old_segments / best["old"], "old_paths_per_s": paths / best["old"],
            "old_ratio": best["raw_embreex"] / best["old"],
            "old_outside_embree_ns_per_segment": best["old_outside"] / old_segments * 1e9,
        })
    for threads in (1, 2):
        out[f"new_segments_per_s_{threads}_threads"] = new_segments / best[f"new_{threads}"]
        out[f"new_paths_per_s_{threads}_threads"] = paths / best[f"new_{threads}"]
    out["direct_ratio_per_thread"] = out["new_segments_per_s_1_threads"] / out["raw_direct_rays_per_s"]
    out["direct_outside_embree_ns_per_segment"] = (best["new_1"] - best["raw_direct"]) / new_segments * 1e9
    if grid:
        grid_segments = int(grid_tally.counts[SEGMENTS])
        if isinstance(exact.grid, SphereCells):
            out["grid_cells"] = int(np.prod(exact.grid.counts))
            out["grid_cell_side"] = float(exact.grid.side.min())
        else:
            out["grid_cells"] = int(exact.grid.heights.size)
            out["grid_cell_side"] = float(exact.grid.pixel)
        for threads in (1, 2):
            out[f"grid_segments_per_s_{threads}_threads"] = grid_segments / best[f"grid_{threads}"]
        out["grid_over_direct_per_thread"] = out["grid_segments_per_s_1_threads"] / out["new_segments_per_s_1_threads"]
        out["grid_walk_ns_per_query"] = best["walk"] / new_segments * 1e9
        out["grid_outside_walk_ns_per_segment"] = (best["grid_1"] / grid_segments - best["walk"] / new_segments) * 1e9
        out["grid_ns_per_segment"] = best["grid_1"] / grid_segments * 1e9
        out["direct_ns_per_segment"] = best["new_1"] / new_segments * 1e9
    return out


def absorbing_floor(cfg, paths: int, repeats: int) -> float:
    """``direct_ratio_per_thread`` of the same scene with every surface absorbing: a path is its
    start, one query and one absorption, the least the kernel does around a query."""
    data = cfg.model_dump(exclude_unset=True)  # the keys given (a heightfield refuses some defaults given)
    data["material"] = {"kind": "absorber"}
    if "base" in data:
        data["base"] = {"kind": "absorber"}
    _, plan, exact = realization(config_module.validate(data), mesh_error=None, subdivisions=None)
    sensor = Sensor.build(cfg.sensor.cells)
    wi = np.asarray(plan.incidence_direction(0), np.float64)
    best_trace = best_replay = np.inf
    for k in range(repeats):
        b = Beam(wi, np.uint64(stream_key(cfg.run.seed, 0, k)), paths, 0)
        seconds, tally, _ = fused_trace(exact, sensor, b, 1)
        best_trace = min(best_trace, seconds)
        _, _, logger = fused_trace(exact, sensor, b, 1, log_rays=int(tally.counts[SEGMENTS]))
        best_replay = min(best_replay, replay_direct(logger))
    return best_replay / best_trace


def measure_runs(cfg, run_paths: int, repeats: int, old: bool = True) -> dict:
    """Figure 3: best paths/s of whole runs, alternating the ways of running (``old`` False:
    without the old backend's)."""
    ways = {"new_1_thread": (cfg, 1, 1), "new_2_threads": (cfg, 1, 2)}
    if old:
        old_cfg, _, _ = realization(cfg, mesh_error=FORMER_MESH_ERROR)
        old_cfg = old_cfg.model_copy(update={"run": old_cfg.run.model_copy(update={"backend": "embreex"})})
        ways.update({"old_1_worker": (old_cfg, 1, 1), "old_2_workers": (old_cfg, 2, 1)})
    if gridded(cfg):
        grid_cfg = cfg.model_copy(update={"scene": cfg.scene.model_copy(update={"intersector": "grid"})})
        ways.update({"grid_1_thread": (grid_cfg, 1, 1), "grid_2_threads": (grid_cfg, 1, 2)})
    best = dict.fromkeys(ways, np.inf)
    for _ in range(repeats):
        for name, (c, workers, threads) in ways.items():
            start = time.perf_counter()
            trace(c, workers=workers, threads=threads)
            best[name] = min(best[name], time.perf_counter() - start)
    paths = cfg.run.paths * len(cfg.illumination.theta_i_deg)
    return {f"run_paths_per_s_{name}": paths / seconds for name, seconds in best.items()}


def load(run: str, run_paths: int):
    """runs/RUN.toml with --run-paths and 8 realizations; a heightfield's NDF and masking
    measurements (``statistics``: shadow rays at scene generation, not tracing) turned off, and
    its triangles met by Embree (``intersector = "triangles"``: this benchmark measures the
    tracer against Embree; benchmarks/heightfield_tracing.py, the grid walk against both);
    spheres met by Embree too (``intersector = "embree"``; the sphere grid is figure 3's)."""
    overrides = {"run.paths": run_paths, "run.realizations": 8}
    cfg = config_module.load(ROOT / "runs" / f"{run}.toml", overrides)
    if gridded(cfg) and cfg.scene.kind != "heightfield":
        cfg = config_module.load(ROOT / "runs" / f"{run}.toml", {**overrides, "scene.intersector": "embree"})
    if cfg.scene.kind == "heightfield":
        cfg = config_module.load(ROOT / "runs" / f"{run}.toml",
                                 {**overrides, "scene.statistics": False, "scene.intersector": "triangles"})
    return cfg


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="+", default=[*SPHERE_RUNS, MICROGRAIN_RUN, HEIGHTFIELD_RUN],
                        help="runs/NAME.toml (default: %(default)s)")
    parser.add_argument("--paths", type=int, default=200_000, help="paths of the traced batch")
    parser.add_argument("--run-paths", type=int, default=400_000, help="paths per incidence of the whole runs")
    parser.add_argument("--repeats", type=int, default=5, help="best of this many, for every figure")
    parser.add_argument("--without-embreex", action="store_true",
                        help="leave out the old backend (figure 1 and its whole runs): the grids against Embree alone")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    old = not args.without_embreex
    scenes = {}
    for run in args.scenes:
        start = time.perf_counter()
        cfg = load(run, args.run_paths)
        figures = measure_scene(cfg, args.paths, args.repeats, old)
        if cfg.scene.kind in ("micrograins", "heightfield"):
            figures["direct_ratio_absorbing"] = absorbing_floor(cfg, args.paths, args.repeats)
        figures.update(measure_runs(cfg, args.run_paths, args.repeats, old))
        figures["speedup_2_threads"] = figures["run_paths_per_s_new_2_threads"] / figures["run_paths_per_s_new_1_thread"]
        if old:
            figures["speedup_2_workers"] = (figures["run_paths_per_s_old_2_workers"]
                                            / figures["run_paths_per_s_old_1_worker"])
            figures["new_2_threads_over_old_2_workers"] = (figures["run_paths_per_s_new_2_threads"]
                                                           / figures["run_paths_per_s_old_2_workers"])
        if "run_paths_per_s_grid_1_thread" in figures:
            figures["grid_speedup_2_threads"] = (figures["run_paths_per_s_grid_2_threads"]
                                                 / figures["run_paths_per_s_grid_1_thread"])
            figures["grid_over_new_run_1_thread"] = (figures["run_paths_per_s_grid_1_thread"]
                                                     / figures["run_paths_per_s_new_1_thread"])
        label = scene_label(run)
        scenes[label] = figures
        report(label, figures)
        print(f"  ({time.perf_counter() - start:.0f} s for this scene)")
    chart(scenes)
    if args.json and not old:
        print(json.dumps({"scenes": scenes}))
    elif args.json:
        main_scene = scenes.get("phi = 0.30") or next(iter(scenes.values()))
        print(json.dumps({
            "segments_per_s": main_scene["old_segments_per_s"], "raw_rays_per_s": main_scene["raw_embreex_rays_per_s"],
            "ratio": main_scene["old_ratio"], "speedup_2_workers": main_scene["speedup_2_workers"],
            "outside_embree_ns_per_segment": main_scene["old_outside_embree_ns_per_segment"], "scenes": scenes,
        }))


def scene_label(run: str) -> str:
    """'phi = 0.30' for runs/spheres_phi030.toml, 'gaussian alpha = 0.8, lambert' for
    runs/gaussian_alpha08_lambert.toml, else the run's name."""
    if run.startswith("spheres_phi"):
        digits = run[len("spheres_phi"):]
        return f"phi = {digits[0]}.{digits[1:]}"
    if run.startswith("gaussian_alpha") and "_" in run[len("gaussian_alpha"):]:
        digits, rest = run[len("gaussian_alpha"):].split("_", 1)
        return f"gaussian alpha = {digits[0]}.{digits[1:]}, {rest}"
    return run


def report(label: str, f: dict) -> None:
    old = "old_segments" in f
    segments = f"{f['new_segments']} / {f['old_segments']}" if old else f"{f['new_segments']}"
    if f["spheres"]:
        print(f"{label}: {f['spheres']} spheres (exact) / {f['triangles']} triangles (tessellated), {segments} segments")
    else:
        print(f"{label}: {f['triangles']} triangles (both backends), {segments} segments")
    if old:
        print(f"  raw Embree          embreex {f['raw_embreex_rays_per_s'] / 1e6:6.3f} M rays/s (triangles)")
        print(f"  old backend 1 thr   {f['old_segments_per_s'] / 1e6:6.3f} M segments/s, "
              f"{f['old_paths_per_s'] / 1e3:7.1f} k paths/s, ratio {f['old_ratio']:.3f}, outside Embree "
              f"{f['old_outside_embree_ns_per_segment']:.1f} ns/segment")
    print(f"  raw Embree          direct {f['raw_direct_rays_per_s'] / 1e6:6.3f} M rays/s "
          f"({'spheres' if f['spheres'] else 'triangles'})")
    for t in (1, 2):
        print(f"  new backend {t} thr   {f[f'new_segments_per_s_{t}_threads'] / 1e6:6.3f} M segments/s, "
              f"{f[f'new_paths_per_s_{t}_threads'] / 1e3:7.1f} k paths/s")
    print(f"  new, 1 thread / raw direct on the same rays: {f['direct_ratio_per_thread']:.3f}, outside Embree "
          f"{f['direct_outside_embree_ns_per_segment']:.1f} ns/segment (raw direct "
          f"{1e9 / f['raw_direct_rays_per_s']:.1f} ns/ray)")
    if "grid_over_direct_per_thread" in f:
        print(f"  grid ({f['grid_cells']} cells of {f['grid_cell_side']:.3g}) 1 thr "
              f"{f['grid_segments_per_s_1_threads'] / 1e6:6.3f}, 2 thr {f['grid_segments_per_s_2_threads'] / 1e6:6.3f} "
              f"M segments/s; over the direct backend a thread: x{f['grid_over_direct_per_thread']:.2f} "
              f"({f['grid_ns_per_segment']:.0f} against {f['direct_ns_per_segment']:.0f} ns/segment)")
        print(f"  the walk alone {f['grid_walk_ns_per_query']:.0f} ns/query against raw direct Embree "
              f"{1e9 / f['raw_direct_rays_per_s']:.0f} ns/ray on the same queries; beyond the walk "
              f"{f['grid_outside_walk_ns_per_segment']:.0f} ns/segment")
    if "direct_ratio_absorbing" in f:
        print(f"  the same with every surface absorbing (start, one query, absorb): {f['direct_ratio_absorbing']:.3f}")
    line = (f"new 1 thread {f['run_paths_per_s_new_1_thread'] / 1e3:.1f}, 2 threads "
            f"{f['run_paths_per_s_new_2_threads'] / 1e3:.1f} (x{f['speedup_2_threads']:.2f})")
    if old:
        line = (f"old 1 worker {f['run_paths_per_s_old_1_worker'] / 1e3:.1f}, 2 workers "
                f"{f['run_paths_per_s_old_2_workers'] / 1e3:.1f} (x{f['speedup_2_workers']:.2f}); {line}; "
                f"new 2 threads / old 2 workers = {f['new_2_threads_over_old_2_workers']:.2f}")
    print(f"  whole runs (k paths/s): {line}")
    if "grid_speedup_2_threads" in f:
        print(f"  whole runs on the grid (k paths/s): 1 thread {f['run_paths_per_s_grid_1_thread'] / 1e3:.1f} "
              f"(x{f['grid_over_new_run_1_thread']:.2f} the new backend's), 2 threads "
              f"{f['run_paths_per_s_grid_2_threads'] / 1e3:.1f} (x{f['grid_speedup_2_threads']:.2f})")


def chart(scenes: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    OUT.mkdir(exist_ok=True)
    phis = list(scenes)
    x = np.arange(len(phis))
    fig, (left, right) = plt.subplots(1, 2, figsize=(13, 4.5))
    bars = [("raw embreex (triangles)", "raw_embreex_rays_per_s"), ("old backend, 1 thread", "old_segments_per_s"),
            ("raw direct (spheres; heightfield: triangles)", "raw_direct_rays_per_s"),
            ("new backend, 1 thread", "new_segments_per_s_1_threads"),
            ("new backend, 2 threads", "new_segments_per_s_2_threads"),
            ("grid, 1 thread", "grid_segments_per_s_1_threads"),
            ("grid, 2 threads", "grid_segments_per_s_2_threads")]
    for k, (label, key) in enumerate(bars):
        left.bar(x + (k - 3) * 0.12, [scenes[p].get(key, 0.0) / 1e6 for p in phis], 0.12, label=label)
    left.set_ylabel("M rays or segments / s")
    left.set_ylim(top=1.3 * max(max(scenes[p]["new_segments_per_s_2_threads"], scenes[p].get(
        "grid_segments_per_s_2_threads", 0.0)) for p in phis) / 1e6)
    left.set_title("segments per second against raw Embree, same rays")
    runs = [("old, 1 worker", "run_paths_per_s_old_1_worker"), ("old, 2 workers", "run_paths_per_s_old_2_workers"),
            ("new, 1 thread", "run_paths_per_s_new_1_thread"), ("new, 2 threads", "run_paths_per_s_new_2_threads"),
            ("grid, 1 thread", "run_paths_per_s_grid_1_thread"),
            ("grid, 2 threads", "run_paths_per_s_grid_2_threads")]
    for k, (label, key) in enumerate(runs):
        right.bar(x + (k - 2.5) * 0.14, [scenes[p].get(key, 0.0) / 1e3 for p in phis], 0.14, label=label)
    right.set_ylabel("k paths / s (whole runs, builds included)")
    right.set_title("whole runs")
    for ax in (left, right):
        ax.set_xticks(x, [p.replace("micrograins_", "micrograins\n").replace(", ", "\n") for p in phis], fontsize=8)
        ax.legend(fontsize=8, loc="upper left", ncol=2)
    fig.tight_layout()
    fig.savefig(OUT / "throughput.png", dpi=110)
    print(f"chart written to {OUT / 'throughput.png'}")


if __name__ == "__main__":
    main()
