"""The packed-sphere generator: no two spheres overlap (an exact pair check over the periodic
images), the volume fraction is the one asked for, the lognormal radii have their sigma, a
packing is generated once per key and read back from the cache, a table is the same on two
workers, from an empty cache and after a resume, the table is reciprocal at 28 pairs of
incidences, the embreex backend traces icospheres as the direct one does, and bad input is
refused in one line. (The white furnace, reciprocity, thread identity and a bad key: tests/test_scene_kinds.py.)"""

import math
import time

import numpy as np
import pytest

from microsim import config, geometry
from microsim.cli import main
from microsim.geometry import packings
from microsim.physics.rng import geometry_rng
from microsim.run import unit_store
from microsim.run.plan import Plan
from microsim.tables import dict_to_toml
from microsim.testing import example, trace, trace_table
from microsim.testing.bounds import chi2_bound
from microsim.testing.reciprocity import non_reciprocal_z, reciprocity_z, ring_illumination, ring_incidences
from microsim.testing.refusals import assert_run_refused, small_config
from microsim.testing.tables import same_table

PACKED = geometry.SCENES["packed_spheres"]
#: the reciprocity check's sensor, its four rings of cell counts divisible by 4 (at 28.4, 42.2, 55.8
#: and 83.2 deg), each at phi_i 0 and 90: 8 incidences, 28 pairs
RECIPROCITY_CELLS, RECIPROCITY_RINGS, RECIPROCITY_REALIZATIONS = 102, (2, 3, 4, 6), 16


def scene_config(**scene):
    return config.validate({"scene": {"kind": "packed_spheres", **scene},
                            "material": {"kind": "lambert", "albedo": 0.8},
                            "illumination": {"theta_i_deg": [0.0]}, "run": {"paths": 1000}})


def packed(cfg, realization=0):
    """The packing of a realization of ``cfg``, as a run draws it: centres in [0, tile)^2 x [-depth, 0)."""
    return PACKED.draw(PACKED.resolve(cfg), geometry_rng(1, realization), PACKED.cache_directory(cfg))


def smallest_contact_ratio(centres, radii, box) -> float:
    """min over pairs i < j and the 27 periodic images of |c_i - c_j - shift| / (r_i + r_j), every
    pair computed (no neighbour search)."""
    best = math.inf
    shifts = np.array([[a, b, c] for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)]) * np.asarray(box)
    for i in range(len(centres) - 1):
        gap = centres[i] - centres[i + 1:]
        distance = np.linalg.norm(gap[:, None, :] - shifts[None, :, :], axis=2).min(axis=1)
        best = min(best, float(np.min(distance / (radii[i] + radii[i + 1:]))))
    return best


@pytest.mark.parametrize("phi", [0.1, 0.4, 0.6])
def test_no_two_spheres_overlap_and_the_volume_fraction_is_the_one_asked_for(phi):
    """Three realizations a volume fraction, tile 16, depth 12: every pair at least in contact
    (distance / (r_i + r_j) >= 1), and sum 4/3 pi r^3 / (tile^2 depth) within 0.5 % of phi."""
    cfg = scene_config(volume_fraction=phi, tile=16.0, depth=12.0)
    for realization in range(3):
        packing = packed(cfg, realization)
        box = (16.0, 16.0, 12.0)
        assert np.all((packing.centres >= (0, 0, -12)) & (packing.centres < (16, 16, 0)))
        ratio = smallest_contact_ratio(packing.centres, packing.radii, box)
        assert ratio >= 1.0
        measured = np.sum(4 / 3 * math.pi * packing.radii**3) / (16 * 16 * 12)
        assert abs(measured / phi - 1.0) < 0.005


def test_the_slab_holds_every_sphere_and_its_periodic_images():
    """The example's realizations (24 spheres, their radii scaled to 1.006 by the packer): the
    slab's top and bottom beyond the largest sphere of a centre at z = 0 or -depth, and every
    sphere that reaches across a side of the tile there again through its image."""
    cfg = config.validate(example("packed_spheres"))
    resolved = PACKED.resolve(cfg)
    for realization in range(2):
        scene = PACKED.generate(resolved, cfg, geometry_rng(1, realization))
        packing = packed(cfg, realization)
        assert packing.radii.max() > 1.001
        # centres lie anywhere in -depth <= z < 0: the slab clears the largest sphere at either end
        assert scene.info["z_top"] > packing.radii.max()
        assert scene.info["z_bottom"] < -resolved["depth"] - packing.radii.max()
        tile = resolved["tile"]
        crossing = np.any((packing.centres[:, :2] < packing.radii[:, None])
                          | (packing.centres[:, :2] > tile - packing.radii[:, None]), axis=1)
        assert scene.info["sphere_images"] >= crossing.sum() > 0


def test_lognormal_radii_have_their_sigma_and_do_not_overlap():
    """sigma = 0.3: the standard deviation of ln r within 4 of its standard errors (sigma / sqrt(2n))
    of 0.3, and no overlap."""
    cfg = scene_config(volume_fraction=0.3, radius_sigma=0.3, tile=26.0, depth=16.0)
    packing = packed(cfg)
    n, log_r = len(packing.radii), np.log(packing.radii)
    assert n > 300
    assert abs(log_r.std(ddof=1) - 0.3) < 4 * 0.3 / math.sqrt(2 * n)
    assert smallest_contact_ratio(packing.centres, packing.radii, (26.0, 26.0, 16.0)) >= 1.0


def test_a_packing_is_generated_once_per_key_and_then_read_from_the_cache():
    """The same realization twice: generated once (the counter), the second read back, the same
    arrays, and faster; another realization is another packing."""
    cfg = scene_config(volume_fraction=0.55, tile=24.0, depth=16.0)
    before = packings.GENERATED[0]
    start = time.perf_counter()
    first = packed(cfg, 7)
    generating = time.perf_counter() - start
    start = time.perf_counter()
    second = packed(cfg, 7)
    reading = time.perf_counter() - start
    assert packings.GENERATED[0] == before + 1
    assert np.array_equal(first.centres, second.centres) and np.array_equal(first.radii, second.radii)
    assert reading < generating / 5, (reading, generating)
    other = packed(cfg, 8)
    assert packings.GENERATED[0] == before + 2 and not np.array_equal(other.centres, first.centres)


def test_a_table_is_the_same_on_two_workers_after_a_resume_and_from_an_empty_cache(tmp_path, monkeypatch, capsys):
    """The example on one worker; on two (the packings read from the cache); from an empty cache
    (every packing generated again from the run's seed); and resumed with half its units kept (the
    other half's packings read back): the same table, byte for byte."""
    cfg_path = tmp_path / "run.toml"
    cfg_path.write_text(dict_to_toml(example("packed_spheres")))
    for name, flags in (("one", []), ("two", ["--workers", "2"])):
        assert main(["run", str(cfg_path), "--out", str(tmp_path / f"{name}.h5"), *flags]) == 0
    monkeypatch.setenv("MICROSIM_CACHE", str(tmp_path / "empty cache"))
    before = packings.GENERATED[0]
    assert main(["run", str(cfg_path), "--out", str(tmp_path / "fresh.h5")]) == 0
    realizations = example("packed_spheres")["run"]["realizations"]
    assert packings.GENERATED[0] == before + realizations
    resumed = tmp_path / "resumed.h5"
    cfg = config.validate(example("packed_spheres"))
    store = unit_store.UnitStore.open(unit_store.store_path(resumed), Plan.from_config(cfg), resume=False)
    trace(cfg, store=store)
    store.release()
    kept = sorted(unit_store.store_path(resumed).glob("r*_i*.npz"))
    for unit in kept[::2]:
        unit.unlink()
    assert main(["run", str(cfg_path), "--out", str(resumed), "--resume"]) == 0
    assert packings.GENERATED[0] == before + realizations  # the resumed units' packings read back
    capsys.readouterr()
    for name in ("two", "fresh", "resumed"):
        assert same_table(tmp_path / "one.h5", tmp_path / f"{name}.h5"), name


def test_a_packing_is_reciprocal_at_28_pairs_and_the_check_sees_what_is_not(tmp_path):
    """Phi 0.4, tile and depth 16, albedo 0.8, 16 realizations of 6000 paths an incidence: the
    mean z^2 of f(a -> b) - f(b -> a) over the 28 pairs under its bound
    (microsim.testing.bounds.chi2_bound; tests/test_scene_kinds.py says why one-sided), and that
    of f cos(theta_o), which is not reciprocal, above it. Measured over seeds 1-4: 0.66-1.09 against
    the bound 2.89; f cos(theta_o) 376-399."""
    incidences = ring_incidences(RECIPROCITY_CELLS, RECIPROCITY_RINGS)
    data = {"scene": {"kind": "packed_spheres", "volume_fraction": 0.4, "tile": 16.0, "depth": 16.0},
            "material": {"kind": "lambert", "albedo": 0.8}, "illumination": ring_illumination(incidences),
            "sensor": {"cells": RECIPROCITY_CELLS},
            "run": {"paths": RECIPROCITY_REALIZATIONS * 6000, "realizations": RECIPROCITY_REALIZATIONS, "seed": 3}}
    table = trace_table(data, tmp_path / "reciprocity.h5")
    z = reciprocity_z(table, incidences, table.brdf, table.brdf_stderr)
    bound = chi2_bound(len(z), RECIPROCITY_REALIZATIONS)
    assert len(z) == 28 and np.mean(z**2) <= bound, (np.mean(z**2), bound, z.max())
    assert np.mean(non_reciprocal_z(table, incidences) ** 2) > bound


@pytest.mark.parametrize("scene, key, also", [
    ('kind = "packed_spheres"\nvolume_fraction = 0.63', "scene.volume_fraction", ("0.62",)),
    ('kind = "packed_spheres"\nvolume_fraction = 0.3\nradius_sigma = 0.6', "scene.radius_sigma", ("0.5",)),
    ('kind = "packed_spheres"\nvolume_fraction = 0.3\nradius_sigma = 0.5\ntile = 16.0', "scene.tile", ("diameters",)),
    ('kind = "packed_spheres"\nvolume_fraction = 0.3\ntile = 6.0', "scene.tile", ("8",)),
    ('kind = "packed_spheres"\nvolume_fraction = 0.3\ntile = 8.0\ndepth = 4.0\ncache = "/proc/no_cache"',
     "packing cache", ("/proc/no_cache",)),
    ('kind = "packed_spheres"\nvolume_fraction = 0.3\ntile = 8.0\ndepth = 4.0\nsubdivisions = 1\nmesh_error = 0.01',
     "scene.subdivisions", ("not both",)),
], ids=["beyond the packer's reach", "too wide a size distribution", "a tile of too few diameters",
        "a tile of too few diameters of equal spheres", "a cache that cannot be written",
        "two icosphere budgets"])
def test_bad_input_is_refused_in_one_line_and_nothing_is_written(scene, key, also, tmp_path, capsys):
    assert_run_refused(small_config(scene), key, tmp_path, capsys, *also)


def test_on_embreex_the_spheres_are_icospheres_that_trace_the_paths_the_direct_backend_traces():
    """The example with Embree's spheres (``intersector = "embree"``) on the embreex backend: traced
    as icospheres within mesh_error 0.01 (said in the plan's note), the same paths as the direct
    backend traces on the same icospheres (the counts of segments, inside hits and kills equal;
    every estimate to 1e-12); and the icospheres pack the same spheres as the exact scene (one
    packing generated a realization for both)."""
    data = example("packed_spheres")
    data = {**data, "scene": {**data["scene"], "intersector": "embree"}}
    on_embreex = config.validate({**data, "run": {**data["run"], "backend": "embreex"}})
    plan = Plan.from_config(on_embreex)
    assert plan.scene["sphere_model"] == "icosphere" and "icospheres within mesh_error 0.01" in plan.backend_note
    meshed = config.validate({**data, "scene": {**data["scene"], "mesh_error": 0.01}})
    before = packings.GENERATED[0]
    old, new = trace(on_embreex), trace(meshed)
    assert packings.GENERATED[0] - before <= data["run"]["realizations"]
    assert np.array_equal(old.counts, new.counts) and old.counts[:, 0].sum() > 0
    for a, b in zip(old.brdf + old.albedo + old.energy, new.brdf + new.albedo + new.energy):
        assert np.allclose(a.mean, b.mean, rtol=1e-12, atol=1e-15)
