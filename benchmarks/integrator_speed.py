"""Paths/s of each integrator, one thread: the medium, the V-cavities (both intersectors), spheres.

A tracer built from a small config, best of 3 batches of a fixed number of paths (after one
small batch that compiles). Prints one JSON object. To compare two revisions, run it from each
(``PYTHONPATH=<worktree> python benchmarks/integrator_speed.py``) in alternated processes,
several of each (docs/developer/performance.md); against a revision whose random streams are
``microsim.rng``, change the import to that. ``python benchmarks/integrator_speed.py medium`` runs that case only.
About a minute.
"""
import json
import sys
import time

from microsim import config
from microsim.physics.rng import geometry_rng, stream_key
from microsim.run.plan import Plan

CASES = {
    "medium": ({"scene": {"kind": "halfspace_medium"}, "material": {"kind": "lambert", "albedo": 0.9}}, 400_000),
    "vcav_analytic": ({"scene": {"kind": "vcavities", "roughness": 0.8}, "material": {"kind": "lambert", "albedo": 0.9}}, 1_000_000),
    "vcav_embree": ({"scene": {"kind": "vcavities", "roughness": 0.8, "intersector": "embree"}, "material": {"kind": "lambert", "albedo": 0.9}}, 300_000),
    "spheres03": ({"scene": {"kind": "poisson_spheres", "volume_fraction": 0.3}, "material": {"kind": "lambert", "albedo": 0.9}}, 100_000),
}
out = {}
for name, (settings, paths) in CASES.items():
    if len(sys.argv) > 1 and name not in sys.argv[1:]:
        continue
    cfg = config.validate({**settings, "illumination": {"theta_i_deg": [30.0]}, "sensor": {"cells": 400},
                           "run": {"paths": paths, "realizations": 2, "seed": 1}})
    plan = Plan.from_config(cfg)
    scene = plan.generator.generate(plan.scene, plan.config, geometry_rng(1, 0))
    sensor = plan.sensor
    tracer = plan.tracer_class(scene, sensor, backend="direct", threads=1)
    wi = plan.incidence_direction(0)
    tracer.trace(wi, 1000, stream_key(1, 0, 0), 0)
    best = []
    for rep in range(3):
        t = time.perf_counter()
        tracer.trace(wi, paths, stream_key(1, 0, rep), 0)
        best.append(time.perf_counter() - t)
    out[name] = paths / min(best)
print(json.dumps(out))
