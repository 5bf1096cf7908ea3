"""`microsim compare` and `microsim fit` with --points (next-event estimation's f at exact
directions) and --retro (the retro rings), against exact BRDFs.

- A half space of Lambert-sphere scatterers traced to order 1: its BRDF is c p(-wi . wo) /
  (mu_i + mu_o) exactly, at every point and averaged over every ring; the exact model is
  consistent, one of another albedo is not, and a fit finds the albedo.
- A Lambertian plane: every point is exactly albedo / pi with no spread, so the model must equal
  it (to EXACT_POINT), and a fit is exact.
- The points of an incidence share their paths: with their covariance in the table, compare
  judges them by Hotelling's test and fit weighs them by it (generalized least squares). On the
  half space at order 1 (16 realizations, 7 and 8 points): the exact model is consistent, an
  albedo 0.5 % off is rejected where the bounds of one degree of freedom (a table without the
  covariance) are not, the fit's error is a fraction of the bound without it, and over a few
  seeds the p-values of the exact model spread over (0, 1) and the fit's errors hold.
- Bad input (no such datasets, both flags, an order the points do not hold, --plot): one line,
  exit 2.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from scipy import stats

from microsim import tables
from microsim.analysis import compare, fit
from microsim.analysis.averages import QUADRATURE_TOLERANCE, ring_averages
from microsim.analysis.judge_points import compare_points
from microsim.analysis.judge_retro import compare_retro, rings_of
from microsim.app import session
from microsim.cli import main
from microsim.core.table_noise import CHI2_OUTSIDE
from microsim.models.radiative_transfer import single_scattering
from microsim.testing.refusals import assert_refused

ALBEDO = 0.9
#: a user's model of the medium traced to order 1: path.py:Single on the command line
MODEL_FILE = '''
from microsim.models.radiative_transfer import single_scattering


def Single(wi, wo, albedo=0.9):
    return single_scattering(wi, wo, albedo)
'''


def single(wi, wo, albedo=ALBEDO):
    """The medium's BRDF at order 1 (a plain function: compare's model)."""
    return single_scattering(wi, wo, albedo)


def medium_config(**sensor) -> dict:
    return {"scene": {"kind": "halfspace_medium", "phase": "lambert_sphere"},
            "material": {"kind": "lambert", "albedo": ALBEDO},
            "illumination": {"theta_i_deg": [0.0, 60.0]},
            "sensor": {"cells": 100, **sensor},
            "run": {"paths": 200_000, "realizations": 8, "max_order": 1, "seed": 7}}


@pytest.fixture(scope="module")
def medium(tmp_path_factory):
    """(table, the model's spec on the command line): the half space at order 1 with 4 directions,
    2 retro points and 6 retro rings out to 30 degrees, 2 x 200 000 paths."""
    directory = tmp_path_factory.mktemp("points")
    (directory / "single.py").write_text(MODEL_FILE)
    cfg = medium_config(directions_deg=[[0, 0], [45, 90], [60, 180], [80, 0]], retro_points_deg=[0, 5],
                        retro_rings=6, retro_max_deg=30)
    path = session.run(cfg, directory / "medium.h5").tables[0]
    return path, f"{directory / 'single.py'}:Single"


@pytest.fixture(scope="module")
def cells_only(tmp_path_factory):
    """The same half space with cells only: no points, no retro rings."""
    return session.run(medium_config(), tmp_path_factory.mktemp("cells") / "cells.h5").tables[0]


@pytest.fixture(scope="module")
def plane(tmp_path_factory):
    cfg = {"scene": {"kind": "plane"}, "material": {"kind": "lambert", "albedo": 0.5},
           "illumination": {"theta_i_deg": [0.0, 50.0]},
           "sensor": {"cells": 50, "directions_deg": [[0, 0], [30, 45], [89, 270]], "retro_points_deg": [0, 3]},
           "run": {"paths": 64_000, "seed": 2}}  # the default 32 realizations
    return session.run(cfg, tmp_path_factory.mktemp("plane") / "plane.h5").tables[0]


def run_json(capsys, command, *argv) -> dict:
    assert main([command, *map(str, argv), "--json"]) == 0, capsys.readouterr().err
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1
    return json.loads(out[0])


def within(row, unit) -> bool:
    low, high = row["chi2_bounds"]
    return low <= row[f"chi2_per_{unit}"] <= high


# ------------------------------------------------------------------------------- the points


def test_the_exact_model_is_consistent_at_the_points_and_another_albedo_is_not(medium, capsys):
    path, spec = medium
    exact = run_json(capsys, "compare", path, "--model", spec, "--order", "1", "--points")
    assert exact["on"] == "points" and exact["order"] == "1"
    for row in [*exact["per_incidence"], exact["overall"]]:
        assert row["consistent"] and within(row, "point"), row
        assert row["median_abs_rel_err"] < 0.01 and "albedo_sim" not in row
    # normal incidence: the retro point at gamma = 0 is the direction [0, 0], compared once
    assert [row["points_compared"] for row in exact["per_incidence"]] == [5, 6]
    # a bound of one degree of freedom, whatever the number of points (their errors are correlated)
    assert exact["overall"]["chi2_bounds"][1] == pytest.approx(7.879, abs=1e-3)
    off = run_json(capsys, "compare", path, "--model", spec, "--order", "1", "--points", "--param", "albedo=0.88")
    for row in [*off["per_incidence"], off["overall"]]:
        assert not row["consistent"] and row["chi2_per_point"] > row["chi2_bounds"][1], row


def test_the_z_scores_are_the_points_own(medium):
    """z = (table - model) / stderr at each point, model f at the stored directions."""
    path, _ = medium
    table = tables.load(path)
    result = compare_points(table, single, "all")
    sim, stderr = table.arrays["brdf_points"], table.arrays["brdf_points_stderr"]
    wo = table.arrays["sensor/points_direction"]
    exact = np.stack([single_scattering(wi, d, ALBEDO) for wi, d in zip(table.wi, wo)])
    np.testing.assert_allclose(result.model, exact, rtol=1e-12)
    kept = result.judged
    assert kept.sum() == 11 and not kept[0, 4]  # the repeat of [0, 0] at normal incidence
    z = (sim - exact) / stderr
    assert result.as_dict()["overall"]["max_abs_z"] == pytest.approx(np.abs(z[kept]).max(), rel=1e-9)
    assert np.array_equal(table.arrays["brdf_points_order"][:, 0], sim)  # order 1 is all there is


def test_a_fit_at_the_points_finds_the_albedo(medium, capsys):
    path, spec = medium
    result = run_json(capsys, "fit", path, "--model", spec, "--free", "albedo", "--param", "albedo=0.5",
                      "--order", "1", "--points")
    value, error = result["fit"]["albedo"]["value"], result["fit"]["albedo"]["stderr"]
    assert abs(value - ALBEDO) < 3 * error and error < 0.005, result["fit"]
    assert result["on"] == "points" and result["overall"]["consistent"]
    # generalized least squares on the incidences' Hotelling directions (the table holds the covariance)
    assert result["fit_points_weights"] == "covariance"
    assert result["fit_dof"] == sum(row["hotelling_dof"][0] for row in result["per_incidence"]) - 1


# ------------------------------------------------------------------- the points with their covariance

#: the half space at order 1 for Hotelling's test: normal incidence 7 points (the retro point at
#: gamma = 0 repeats [0, 0]), 60 degrees 8 (two of theta_o = 60: an exact relation)
CORRELATED = {"directions_deg": [[0, 0], [30, 0], [45, 90], [60, 180], [70, 45], [80, 0]], "retro_points_deg": [0, 5]}


def correlated_config(seed: int = 3, paths: int = 16_000, realizations: int = 16) -> dict:
    cfg = medium_config(**CORRELATED)
    cfg["sensor"]["cells"] = 20
    cfg["run"].update(paths=paths, realizations=realizations, seed=seed)
    return cfg


def without_covariance(path, out, version="1.0"):
    """A copy of the table at ``path`` without the points' covariance, as tables of format 1.0
    (``version``) may be, written before it existed (the loader checks each dataset's SHA-256:
    whole datasets can go)."""
    import shutil

    import h5py

    shutil.copy(path, out)
    with h5py.File(out, "a") as f:
        del f["brdf_points_covariance"], f["brdf_points_order_covariance"]
        f.attrs["format_version"] = version
    return out


@pytest.fixture(scope="module")
def correlated(tmp_path_factory):
    """(table with the points' covariance, its copy without it): 16 x 16 000 paths."""
    directory = tmp_path_factory.mktemp("correlated")
    path = session.run(correlated_config(), directory / "correlated.h5").tables[0]
    return path, without_covariance(path, directory / "old.h5")


def test_hotelling_judges_the_points_where_the_table_holds_their_covariance(correlated):
    path, _ = correlated
    table = tables.load(path)
    result = compare_points(table, single, "1").as_dict()
    assert result["points_statistic"] == "hotelling" and "Bonferroni" in result["hotelling_rule"]
    r = table.attrs["realizations"]
    assert r == 16
    for row, compared in zip(result["per_incidence"], (7, 8)):
        assert row["points_statistic"] == "hotelling" and row["points_compared"] == compared
        k, rest = row["hotelling_dof"]
        assert rest == r - k and 5 <= k <= compared
        low, high = row["hotelling_bounds"]
        assert [low, high] == pytest.approx(stats.f.ppf([0.005, 0.995], k, r - k), rel=1e-12)
        assert low <= row["hotelling_f"] <= high and row["p_value"] >= CHI2_OUTSIDE, row
        assert row["dropped_max_ratio"] <= 1 and row["consistent"], row
        assert row["chi2_per_point"] > 0 and row["chi2_bounds"][1] == pytest.approx(7.879, abs=1e-3)  # descriptive
    # the two points of theta_o = 60 at 60 degrees are exactly proportional: a direction dropped
    assert result["per_incidence"][1]["points_dropped"] >= 1
    overall = result["overall"]
    assert overall["bonferroni_level"] == pytest.approx(CHI2_OUTSIDE / 2)
    assert overall["p_value_min"] == pytest.approx(min(row["p_value"] for row in result["per_incidence"]))
    assert overall["consistent"] and overall["incidences_chi2_1dof"] == 0


def test_a_table_of_format_1_1_without_the_points_covariance_is_refused_as_damaged(correlated, tmp_path, capsys):
    """Tables of format 1.1 hold the covariance with their points (its ``since``): one without it
    is refused in one line as damaged, where one of format 1.0 is judged by the bounds of one
    degree of freedom (the next test)."""
    damaged = without_covariance(correlated[0], tmp_path / "damaged.h5", version="1.1")
    for command, free in (("compare", []), ("fit", ["--free", "albedo"])):
        assert_refused([command, str(damaged), "--model", "lambert", "--param", "albedo=0.5", *free, "--points"],
                       capsys, "brdf_points_covariance", "format 1.1", "damaged")


def test_hotelling_rejects_an_albedo_half_a_percent_off_that_one_degree_of_freedom_does_not(correlated, capsys):
    """The same table, with and without the covariance: the bounds of one degree of freedom hold
    whatever the correlation and see nothing; Hotelling's test sees the albedo off by 0.5 %."""
    path, old = correlated
    off = {"albedo": ALBEDO * 1.005}
    new = compare_points(tables.load(path), single, "1", **off).as_dict()
    for row in new["per_incidence"]:
        assert row["hotelling_f"] > row["hotelling_bounds"][1] and not row["consistent"], row
    assert not new["overall"]["consistent"] and new["overall"]["p_value_min"] < 1e-6
    before = compare_points(tables.load(old), single, "1", **off).as_dict()
    assert before["points_statistic"] == "chi2_1dof" and "brdf_points_covariance" in before["points_statistic_note"]
    for row in [*before["per_incidence"], before["overall"]]:
        assert row["points_statistic"] == "chi2_1dof" and "hotelling_f" not in row and "p_value" not in row
        assert row["consistent"] and row["chi2_per_point"] < row["chi2_bounds"][1] / 2, row
    # the descriptive chi-square is the same number either way
    assert new["overall"]["chi2_per_point"] == pytest.approx(before["overall"]["chi2_per_point"], rel=1e-12)
    # and on the command line
    for table, statistic in ((old, "chi2_1dof"), (path, "hotelling")):
        result = run_json(capsys, "compare", table, "--model", "lambert", "--param", "albedo=0.5", "--points")
        assert result["points_statistic"] == result["overall"]["points_statistic"] == statistic


def test_an_incidence_with_as_many_points_as_realizations_falls_back(tmp_path, capsys):
    """4 realizations and 7 and 8 points: no Hotelling test; the bounds of 1 degree of freedom,
    and the fit weighs each point by its own error."""
    cfg = correlated_config(paths=4_000, realizations=4)
    path = session.run(cfg, tmp_path / "few.h5").tables[0]
    result = compare_points(tables.load(path), single, "1").as_dict()
    assert result["points_statistic"] == "hotelling" and result["overall"]["incidences_chi2_1dof"] == 2
    for row in result["per_incidence"]:
        assert row["points_statistic"] == "chi2_1dof" and "as many as the realizations" in row["points_statistic_note"]
        assert "hotelling_f" not in row and row["consistent"] == (row["p_value"] >= CHI2_OUTSIDE)
    fitted = fit.fit(tables.load(path), single, ["albedo"], {"albedo": 0.5}, "1", on="points").as_dict()
    assert fitted["fit_points_weights"] == "bounding" and "4 realizations" in fitted["fit_points_weights_note"]


def test_a_fit_weighs_the_points_by_their_covariance(correlated):
    path, old = correlated
    gls = fit.fit(tables.load(path), single, ["albedo"], {"albedo": 0.5}, "1", on="points")
    bounding = fit.fit(tables.load(old), single, ["albedo"], {"albedo": 0.5}, "1", on="points")
    value, error = gls.free["albedo"]
    assert gls.notes["fit_points_weights"] == "covariance" and bounding.notes["fit_points_weights"] == "bounding"
    assert abs(value - ALBEDO) < 3 * error, gls.free
    assert error < bounding.free["albedo"][1] / 5, (gls.free, bounding.free)
    rows = gls.as_dict()["per_incidence"]
    assert gls.dof == sum(row["hotelling_dof"][0] for row in rows) - 1
    # chi-square: the incidences' T^2 at the best fit, each of mean k (R - 1) / (R - k - 2)
    assert 0.2 < gls.chi2_per_dof < 5


def test_hotelling_and_the_fit_over_seeds(tmp_path):
    """The exact model over 6 tables (12 incidences, 16 realizations of 4 000 paths): consistent
    everywhere, the p-values spread over (0, 1); the fit within 3 of its errors each time, an
    albedo 0.5 % off rejected each time."""
    p, pulls = [], []
    for seed in range(6):
        table = tables.load(session.run(correlated_config(seed=20 + seed, paths=4_000),
                                        tmp_path / f"seed{seed}.h5").tables[0])
        result = compare_points(table, single, "1").as_dict()
        assert result["overall"]["consistent"], result["overall"]
        p += [row["p_value"] for row in result["per_incidence"]]
        assert not compare_points(table, single, "1", albedo=ALBEDO * 1.005).as_dict()["overall"]["consistent"]
        value, error = fit.fit(table, single, ["albedo"], {"albedo": 0.5}, "1", on="points").free["albedo"]
        pulls.append((value - ALBEDO) / error)
    assert stats.kstest(p, "uniform").pvalue > 0.01, sorted(p)
    assert max(map(abs, pulls)) < 3, pulls


# ------------------------------------------------------------------------------- the retro rings


def test_the_exact_model_is_consistent_on_the_retro_rings_and_another_albedo_is_not(medium, capsys):
    path, spec = medium
    exact = run_json(capsys, "compare", path, "--model", spec, "--order", "1", "--retro")
    assert exact["on"] == "retro"
    for row in [*exact["per_incidence"], exact["overall"]]:
        assert row["consistent"] and within(row, "ring") and row["rings_with_signal"] >= 5, row
    assert exact["quadrature_max_change_in_stderr"] <= QUADRATURE_TOLERANCE
    off = run_json(capsys, "compare", path, "--model", spec, "--order", "1", "--retro", "--param", "albedo=0.8")
    assert not off["overall"]["consistent"] and off["overall"]["chi2_per_ring"] > off["overall"]["chi2_bounds"][1]


def test_ring_averages_are_the_cos_weighted_mean_over_each_ring(medium):
    """The quadrature against the mean over random directions on the sphere that fall in each
    ring, weighted by cos(theta_o): 60 degrees incidence, rings out to 30 degrees (cut by the
    horizon only where the last ring touches it)."""
    path, _ = medium
    table = tables.load(path)
    rings = rings_of(table)
    wi = table.wi[1]
    averages, _, _ = ring_averages(single, rings, wi, np.full(rings.count, 1e-6))
    rng = np.random.default_rng(4)
    v = rng.normal(size=(2_000_000, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    ring = np.floor(np.linalg.norm(v - wi, axis=1) / rings.step).astype(int)
    keep = (ring < rings.count) & (v[:, 2] > 0)
    ring, f, cos = ring[keep], single(np.broadcast_to(wi, v[keep].shape), v[keep]), v[keep, 2]
    weight = np.bincount(ring, weights=cos)
    mean = np.bincount(ring, weights=f * cos) / weight
    stderr = np.sqrt(np.bincount(ring, weights=(cos * (f - mean[ring])) ** 2)) / weight
    assert np.all(np.abs(averages - mean) < 4 * stderr), (averages - mean) / stderr


def test_a_fit_on_the_retro_rings_finds_the_albedo(medium, capsys):
    path, spec = medium
    result = run_json(capsys, "fit", path, "--model", spec, "--free", "albedo", "--order", "1", "--retro")
    value, error = result["fit"]["albedo"]["value"], result["fit"]["albedo"]["stderr"]
    assert abs(value - ALBEDO) < 3 * error and error < 0.02, result["fit"]
    assert result["on"] == "retro" and result["overall"]["consistent"]


def test_the_text_report_has_no_albedo_rows(medium, capsys):
    path, spec = medium
    for flag, statistic in (("--points", "F or chi2"), ("--retro", "chi2/ring")):
        assert main(["compare", str(path), "--model", spec, "--order", "1", flag]) == 0
        lines = capsys.readouterr().out.splitlines()
        assert "no albedo rows" in lines[0] and statistic in lines[1] and "albedo" not in lines[1]
        assert len(lines) == 2 + 2 + 1 and lines[-1].split()[0] == "overall"
        assert all(line.split()[-1] == "consistent" for line in lines[2:])


# ------------------------------------------------------------------------------- a plane: exact points


def test_a_plane_s_points_are_exact(plane, capsys):
    """Every path adds exactly albedo / pi: no spread, so no chi-square (None, not NaN), and a
    verdict that follows the p-value: 1 where the model equals the points to EXACT_POINT, 0 where
    it is 1e-7 off; a fit meets them with 0 degrees of freedom, not fewer, and no chi^2 / dof."""
    table = tables.load(plane)
    for albedo, consistent, p in ((0.5, True, 1.0), (0.5 * (1 + 1e-7), False, 0.0)):
        result = compare_points(table, "lambert", albedo=albedo).as_dict()
        rows = [*result["per_incidence"], result["overall"]]
        assert all(r["chi2_per_point"] is None and r["chi2_bounds"] is None for r in rows)
        assert all(r["consistent"] is consistent for r in rows)
        assert [r["p_value"] for r in result["per_incidence"]] == [p] * len(result["per_incidence"])
        assert result["overall"]["p_value_min"] == p and result["overall"]["points_statistic"] == "exact"
        assert result["overall"]["points_without_spread"] == result["overall"]["points_compared"] == 9
        assert main(["compare", str(plane), "--model", "lambert", "--param", f"albedo={albedo!r}", "--points"]) == 0
        text = capsys.readouterr().out.split(" vs ", 1)[1].split(")", 1)[1]  # after the table's path
        assert "nan" not in text.lower() and all(line.split()[-1] == ("consistent" if consistent else "inconsistent")
                                                  for line in text.splitlines()[2:]), text
        assert main(["compare", str(plane), "--model", "lambert", "--param", f"albedo={albedo!r}", "--points",
                     "--json"]) == 0
        json.loads(capsys.readouterr().out, parse_constant=lambda name: pytest.fail(f"{name} in the JSON"))
    fitted = fit.fit(table, "lambert", ["albedo"], {"albedo": 0.3}, on="points")
    value, error = fitted.free["albedo"]
    assert value == pytest.approx(0.5, rel=1e-9) and error < 1e-8
    assert fitted.dof == 0 and fitted.chi2_per_dof is None
    assert main(["fit", str(plane), "--model", "lambert", "--free", "albedo", "--points"]) == 0
    header = capsys.readouterr().out.splitlines()[0]
    verdict = header.split("; ", 1)[1]  # after the fitted albedo (and the table's path, which may hold anything)
    assert "nan" not in verdict and not re.search(r"-[\d.]+ dof", verdict) and "(0 dof" in verdict, header


def test_compare_and_fit_take_one_on_keyword_from_python(plane, medium):
    """compare.compare(table, model, on=...) is what fit.fit(..., on=...) takes: the points, the
    retro rings or the cells, each as its own function gives it; another value is refused in
    one line by both."""
    exact, rings = tables.load(plane), tables.load(medium[0])
    for table, on, direct, model, albedo in (
            (exact, "points", compare_points, "lambert", 0.5),
            (exact, "cells", compare.compare_cells, "lambert", 0.5),
            (rings, "retro", compare_retro, "lambert", 0.5)):
        result = compare.compare(table, model, "1" if table is rings else "all", on=on, albedo=albedo).as_dict()
        assert result == direct(table, model, "1" if table is rings else "all", albedo=albedo).as_dict()
        assert result.get("on", "cells") == on
    for call in (lambda: compare.compare(exact, "lambert", on="rings", albedo=0.5),
                 lambda: fit.fit(exact, "lambert", ["albedo"], on="rings")):
        with pytest.raises(ValueError, match=r"^on = 'rings': accepted: ") as refused:
            call()
        assert sorted(str(refused.value).split("accepted: ")[1].split(", ")) == ["'cells'", "'points'", "'retro'"]


# ------------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("command", ["compare", "fit"])
@pytest.mark.parametrize("table, argv, words", [
    ("cells_only", ["--points"], ["--points", "brdf_points", "directions_deg"]),
    ("cells_only", ["--retro"], ["--retro", "brdf_retro", "retro_rings"]),
    ("medium", ["--points", "--retro"], ["--points", "--retro"]),
    ("medium", ["--points", "--order", "1+2"], ["--order 1+2", "--points"]),
    ("medium", ["--retro", "--order", "1+2"], ["--order 1+2", "--retro"]),
    ("medium", ["--points", "--order", "1-base"], ["--order 1-base", "--points"]),
    ("medium", ["--retro", "--plot", "figures"], ["--plot", "--retro"]),
])
def test_bad_input_gives_one_line_and_exit_2(request, tmp_path, capsys, command, table, argv, words):
    path = request.getfixturevalue(table)
    path = path[0] if isinstance(path, tuple) else path
    free = ["--free", "albedo"] if command == "fit" else []
    argv = [str(tmp_path / a) if a == "figures" else a for a in argv]
    assert_refused([command, path, "--model", "lambert", "--param", "albedo=0.5", *free, *argv], capsys, *words)
    assert not (tmp_path / "figures").exists()
