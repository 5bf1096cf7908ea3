"""The two Embree backends, threads, and the choice between them.

On the same tessellated scene the direct backend (numba calling Embree, fused per-path kernel)
must trace exactly the paths the embreex backend traces (both build robust scenes, so every hit
is the same): every event count equal, and tables equal but for the order in which chunk sums
are added (a few ulp). Its tables must not depend on the number of threads.
"""

import numpy as np
import pytest

from microsim import config, embree, runner
from microsim.cli import main
from microsim.integrators import fused


def spheres(backend: str, paths: int = 24_000, **scene) -> dict:
    return {
        "scene": {"kind": "poisson_spheres", "volume_fraction": 0.4, "tile": 12.0, "depth": 6.0, **scene},
        "material": {"kind": "lambert", "albedo": 0.9},
        "base": {"kind": "interfaced_lambert", "albedo": 0.6, "eta": 1.5},
        "illumination": {"theta_i_deg": [0.0, 75.0]},
        "sensor": {"cells": 200},
        "run": {"paths": paths, "realizations": 2, "seed": 13, "backend": backend},
    }


def test_direct_backend_traces_the_same_paths_as_embreex_on_triangles():
    old = runner.run(config.validate(spheres("embreex", subdivisions=1)))
    new = runner.run(config.validate(spheres("direct", subdivisions=1)))
    assert np.array_equal(old.counts, new.counts) and old.counts[:, 1].sum() > 0  # segments, inside hits, kills
    for a, b in zip(old.brdf + old.albedo + old.energy, new.brdf + new.albedo + new.energy):
        assert np.allclose(a.mean, b.mean, rtol=1e-12, atol=1e-15)


def test_tables_are_bit_identical_for_any_thread_count():
    paths = 2 * fused.WAVE_CHUNKS * fused.CHUNK_PATHS + 3 * fused.CHUNK_PATHS + 17  # 3 waves, a partial chunk
    cfg = config.validate(spheres("direct", paths=2 * paths))
    one, two = runner.run(cfg, threads=1), runner.run(cfg, threads=2)
    assert np.array_equal(one.counts, two.counts)
    for a, b in zip(one.brdf + one.albedo + one.energy, two.brdf + two.albedo + two.energy):
        assert a.total.tobytes() == b.total.tobytes() and a.squares.tobytes() == b.squares.tobytes()


def test_auto_falls_back_to_embreex_when_the_binding_cannot_load(monkeypatch):
    def unavailable():
        raise embree.EmbreeUnavailable("no library here")

    monkeypatch.setattr(embree, "load", unavailable)
    plan = runner.Plan.from_config(config.validate(spheres("auto", subdivisions=1)))
    assert plan.backend == "embreex" and plan.backend_note == "no library here"
    with pytest.raises(runner.PlanError, match="^run.backend = 'direct': no library here$"):
        runner.Plan.from_config(config.validate(spheres("direct", subdivisions=1)))
    with pytest.raises(runner.PlanError, match="exact spheres need the direct Embree backend"):
        runner.Plan.from_config(config.validate(spheres("auto")))


def test_exact_spheres_on_the_embreex_backend_are_refused_in_one_line(tmp_path, capsys):
    with pytest.raises(config.ConfigError, match="^run.backend = 'embreex' traces triangles only"):
        config.validate(spheres("embreex"))
    path = tmp_path / "c.toml"
    path.write_text('[scene]\nkind = "poisson_spheres"\nvolume_fraction = 0.3\n[material]\nkind = "absorber"\n'
                    '[illumination]\ntheta_i_deg = 0.0\n[run]\npaths = 100\n')
    assert main(["run", str(path), "--backend", "embreex", "--out", str(tmp_path / "t.h5")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "scene.subdivisions" in err[0] and not (tmp_path / "t.h5").exists()
