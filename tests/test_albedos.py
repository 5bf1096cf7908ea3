"""Every albedo from one run (docs/conventions.md §4): paths traced once at the
largest albedo, each exit tallied for every listed albedo with its weight times (c_j / c_max)^k.

A run of several albedos is judged against separate runs of one albedo each, made with another
seed (independent): the mean over cells of z^2 = (a - b)^2 / (se_a^2 + se_b^2) within the
two-sided bounds of ``microsim.testing.bounds`` (conservative for a difference of two tables). The table of
the largest albedo is the single run's, bit for bit, with the same seed: its weights are scaled
by 1.
"""

from __future__ import annotations

import numpy as np
import pytest

from microsim import config
from microsim.run.plan import PlanError
from microsim.testing import trace, trace_albedos
from microsim.testing.bounds import chi2_bound, chi2_lower_bound
from microsim.testing.refusals import assert_run_refused, small_config

ALBEDOS = [0.3, 0.6, 0.9, 0.99]
REALIZATIONS = 16
SCENES = {
    "medium": {"kind": "halfspace_medium", "phase": "lambert_sphere"},
    "spheres": {"kind": "poisson_spheres", "volume_fraction": 0.3, "tile": 12.0, "depth": 8.0},
}


def settings(scene, albedo, seed, paths=200_000):
    return config.validate({"scene": SCENES[scene], "material": {"kind": "lambert", "albedo": albedo},
                            "illumination": {"theta_i_deg": [0.0, 60.0]}, "sensor": {"cells": 100},
                            "run": {"paths": paths, "realizations": REALIZATIONS, "seed": seed}})


@pytest.mark.parametrize("scene", sorted(SCENES))
@pytest.mark.slow
def test_four_albedos_from_one_run_equal_four_runs(scene):
    together = trace_albedos(settings(scene, ALBEDOS, seed=1))
    assert [r.albedo_value for r in together] == ALBEDOS
    for albedo, joint in zip(ALBEDOS, together):
        alone = trace(settings(scene, albedo, seed=2))
        for i in range(2):
            a, b = joint.brdf[i], alone.brdf[i]
            se2 = a.stderr[4] ** 2 + b.stderr[4] ** 2
            ok = se2 > 0
            z2 = float(np.mean((a.mean[4][ok] - b.mean[4][ok]) ** 2 / se2[ok]))
            n = int(ok.sum())
            assert n >= 90 and chi2_lower_bound(n, REALIZATIONS) <= z2 <= chi2_bound(n, REALIZATIONS), (albedo, i, z2)
            energy = joint.energy[i].mean
            assert abs(energy[3] - 1.0) <= 4 * joint.energy[i].stderr[3] + 1e-12  # albedo + lost = 1


def test_the_largest_albedo_is_the_single_run_bit_for_bit():
    joint = trace_albedos(settings("medium", [0.5, 0.9], seed=3, paths=50_000))[1]
    alone = trace(settings("medium", 0.9, seed=3, paths=50_000))
    for a, b in zip(joint.brdf + joint.albedo + joint.energy, alone.brdf + alone.albedo + alone.energy):
        assert np.array_equal(a.total, b.total) and np.array_equal(a.squares, b.squares)


def test_the_check_sees_a_wrong_scale():
    """Power: the table of albedo 0.6 from the joint run against a separate run of 0.58 fails."""
    joint = trace_albedos(settings("medium", ALBEDOS, seed=1))[1]
    alone = trace(settings("medium", 0.58, seed=2))
    a, b = joint.brdf[0], alone.brdf[0]
    z2 = np.mean((a.mean[4] - b.mean[4]) ** 2 / (a.stderr[4] ** 2 + b.stderr[4] ** 2))
    assert z2 > chi2_bound(100, REALIZATIONS)


def test_run_refuses_a_list_and_run_albedos_takes_one():
    with pytest.raises(PlanError, match="material.albedo"):
        trace(settings("medium", [0.5, 0.9], seed=1, paths=100))
    assert len(trace_albedos(settings("medium", 0.5, seed=1, paths=100))) == 1


@pytest.mark.parametrize("base,key", [('kind = "lambert"\nalbedo = 0.5', "material.albedo"),
                                      ('kind = "lambert"\nalbedo = [0.5, 0.6]', "base.albedo")])
def test_a_list_where_another_surface_scatters_is_refused(base, key, tmp_path, capsys):
    text = small_config('kind = "poisson_spheres"\nvolume_fraction = 0.3').replace("albedo = 0.8", "albedo = [0.4, 0.8]")
    assert_run_refused(text + f"[base]\n{base}\n", key, tmp_path, capsys)


def test_the_cli_writes_one_table_per_albedo(tmp_path, capsys):
    from microsim import tables
    from microsim.cli import main

    path = tmp_path / "run.toml"
    path.write_text(small_config('kind = "halfspace_medium"').replace("albedo = 0.8", "albedo = [0.4, 0.8]"))
    assert main(["run", str(path), "--out", str(tmp_path / "t.h5")]) == 0
    for albedo in (0.4, 0.8):
        table = tables.load(tmp_path / f"t_albedo{albedo:g}.h5")
        assert f"albedo = {albedo}" in table.attrs["config_toml"] and table.attrs["albedo_traced"] == 0.8
    assert not (tmp_path / "t.h5").exists()


@pytest.mark.parametrize("force", [[], ["--force"]])
def test_albedos_that_print_alike_name_distinct_tables(tmp_path, capsys, force):
    """Albedos that print alike (0.1 and 0.1000001) name distinct tables: neither is lost."""
    from microsim import tables
    from microsim.cli import main

    path = tmp_path / "run.toml"
    path.write_text(small_config('kind = "halfspace_medium"').replace("albedo = 0.8", "albedo = [0.1, 0.1000001]"))
    assert main(["run", str(path), "--out", str(tmp_path / "t.h5"), *force]) == 0
    assert "2 tables written" in capsys.readouterr().out
    for name, albedo in (("t_albedo0.1.h5", 0.1), ("t_albedo0.1000001.h5", 0.1000001)):
        assert f"albedo = {albedo}" in tables.load(tmp_path / name).attrs["config_toml"]
