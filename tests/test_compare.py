"""`microsim compare` and `microsim models`."""

import json

import numpy as np
import pytest

from microsim import models
from microsim.analysis.averages import cell_averages
from microsim.cli import main
from microsim.testing import trace_table, write_table
from microsim.testing.refusals import assert_refused
from microsim.testing.tables import write_plane_table
from microsim.tracer.sensor import Sensor


@pytest.fixture(scope="module")
def plane_table(tmp_path_factory):
    """Lambertian plane, 4 M paths per incidence: the statistics of compare."""
    return write_plane_table(tmp_path_factory.mktemp("compare"), 4_000_000)


@pytest.fixture(scope="module")
def small_table(tmp_path_factory):
    """The same plane at 6400 paths: a table to give bad input about."""
    return write_plane_table(tmp_path_factory.mktemp("small"), 6400)


def compare_json(capsys, *argv):
    assert main(["compare", *map(str, argv), "--json"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1
    return json.loads(out[0])


@pytest.mark.slow  # a plane table of 2 x 4 M paths
def test_true_albedo_agrees_within_one_percent(plane_table, capsys):
    result = compare_json(capsys, plane_table, "--model", "lambert", "--param", "albedo=0.5")
    assert result["model"] == "lambert" and len(result["per_incidence"]) == 2
    assert set(result["overall"]) >= {"median_abs_rel_err", "rel_rmse", "max_abs_z", "albedo_model", "albedo_sim"}
    assert result["overall"]["median_abs_rel_err"] <= 0.01
    assert result["overall"]["cells_with_signal"] == 2 * Sensor.build(200).n_cells
    assert result["overall"]["max_abs_z"] < 4.5


@pytest.mark.slow  # a plane table of 2 x 4 M paths
def test_ten_percent_wrong_albedo_shows_ten_percent(plane_table, capsys):
    result = compare_json(capsys, plane_table, "--model", "lambert", "--param", "albedo=0.55")
    assert abs(result["overall"]["median_abs_rel_err"] - 0.10) <= 0.005
    for row in result["per_incidence"]:
        assert row["albedo_model"] == pytest.approx(0.55, rel=1e-12)
        assert row["albedo_sim"] == pytest.approx(0.5, abs=1e-12)


@pytest.mark.slow  # a plane table of 2 x 4 M paths
def test_plots_are_written_per_incidence(plane_table, tmp_path, capsys):
    assert main(["compare", str(plane_table), "--model", "lambert", "--param", "albedo=0.5",
                 "--plot", str(tmp_path / "figs")]) == 0
    figures = sorted((tmp_path / "figs").glob("*.png"))
    assert len(figures) == 4  # polar maps and plane of incidence, for 2 incidences
    for f in figures:
        assert f.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and f.stat().st_size > 10_000
    assert "figures written" in capsys.readouterr().out


def test_cell_average_matches_a_dense_cos_weighted_integral():
    sensor = Sensor.build(60)
    model = models.create("oren_nayar", albedo=0.8, roughness=0.6)
    wi = np.array([np.sin(1.1), 0.0, np.cos(1.1)])
    averaged, change = cell_averages(model, sensor, wi, np.full(sensor.n_cells, 1e-4))
    w, weight = sensor.cell_quadrature(48, 48)
    dense = np.sum(model(np.broadcast_to(wi, w.shape), w) * weight, axis=1)
    assert np.max(np.abs(averaged - dense)) < 2e-5
    assert change <= 0.05


def test_models_lists_every_model(capsys):
    assert main(["models"]) == 0
    out = capsys.readouterr().out
    names = {line.split(":")[0] for line in out.splitlines() if not line.startswith(" ")}
    assert names == set(models.available())
    assert {"lambert", "oren_nayar", "lambert_sphere", "lambert_sphere_fast", "vmf_diffuse", "microfacet",
            "interfaced_lambert", "micrograin", "micrograin_smith"} <= names
    for name in models.available():
        for p in models.get(name).params:
            assert p.describe() in out


@pytest.mark.parametrize("argv, key", [
    (["--model", "lambert", "--param", "albedo=2"], "albedo"),
    (["--model", "lambert", "--param", "albedo=dark"], "albedo"),
    (["--model", "lambert", "--param", "colour=1"], "colour"),
    (["--model", "lambert", "--param", "albedo"], "--param"),
    (["--model", "no_such_model"], "no_such_model"),
    (["--model", "oren_nayar", "--param", "albedo=0.5", "--param", "roughness=2"], "roughness"),
    (["--model", "lambert", "--param", "albedo=0.5", "--order", "7"], "--order"),
])
def test_bad_compare_input_gives_one_line_and_exit_2(small_table, argv, key, capsys):
    assert_refused(["compare", small_table, *argv], capsys, key)


def test_compare_on_a_missing_or_foreign_file(tmp_path, capsys):
    foreign = tmp_path / "foreign.h5"
    foreign.write_bytes(b"not hdf5")
    for path in (tmp_path / "missing.h5", foreign):
        assert main(["compare", str(path), "--model", "lambert", "--param", "albedo=0.5"]) == 2
        assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_cells_without_standard_error_are_refined_until_the_albedo_converges():
    """A narrow specular lobe (conductor grains, tau0 = 0.95, beta = 0.2, theta_i = 86 deg) on
    cells that no path reached (standard error 0): the model's albedo from the refined cell
    averages equals a 256 x 256 rule on every cell to ALBEDO_TOLERANCE."""
    from microsim.analysis.averages import ALBEDO_TOLERANCE
    from microsim.core.frames import direction

    model = models.create("micrograin", tau0=0.95, beta=0.2, material="conductor", eta=1.0152, k=6.6273)
    wi = direction(np.radians(86.0), 0.0)
    sensor = Sensor.build(100)
    averages, _ = cell_averages(model, sensor, wi, np.zeros(sensor.n_cells))
    reference = sensor.cell_average(lambda w: model(np.broadcast_to(wi, w.shape), w), 256, 256)
    p = sensor.projected_solid_angle()
    assert abs(averages @ p - reference @ p) <= ALBEDO_TOLERANCE * (reference @ p)
    coarse = sensor.cell_average(lambda w: model(np.broadcast_to(wi, w.shape), w), 8, 8)
    assert abs(coarse @ p - reference @ p) > ALBEDO_TOLERANCE * (reference @ p)  # the lobe needs the refinement


def test_figures_of_every_incidence_and_order_keep_their_own_names(tmp_path, capsys):
    """Two incidences of one theta_i, or two orders, into one directory write figures of their
    own names, none over another."""
    from microsim import config

    cfg = config.validate({"scene": {"kind": "plane"}, "material": {"kind": "lambert", "albedo": 0.5},
                           "illumination": {"theta_i_deg": [60.0, 60.0], "phi_i_deg": [0.0, 90.0]},
                           "sensor": {"cells": 50}, "run": {"paths": 6400, "realizations": 4, "seed": 1}})
    path = tmp_path / "t.h5"
    write_table(cfg, path)
    for order in ("all", "1"):
        assert main(["compare", str(path), "--model", "lambert", "--param", "albedo=0.5", "--order", order,
                     "--plot", str(tmp_path / "figs")]) == 0
        assert "4 figures written" in capsys.readouterr().out
    assert len(list((tmp_path / "figs").glob("*.png"))) == 8


@pytest.mark.parametrize("command", [["compare", "--param", "albedo=0.5"], ["fit", "--free", "albedo"]])
def test_figures_to_a_place_that_cannot_take_them_are_refused_before_the_work(small_table, tmp_path, capsys,
                                                                               command, monkeypatch):
    """A --plot under a file is refused in one line before the comparison is worked out."""
    from microsim.analysis import compare as compare_module

    (tmp_path / "file").write_text("")
    monkeypatch.setattr(compare_module, "compare", lambda *a, **k: pytest.fail("the work ran before the check"))
    verb, *options = command
    assert main([verb, str(small_table), "--model", "lambert", *options, "--plot", str(tmp_path / "file" / "figs")]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "--plot" in lines[0] and "is a file" in lines[0] and captured.out == "", captured.err


def test_a_table_without_signal_is_refused_in_one_line(tmp_path, capsys):
    """A table without a cell with signal (2000 paths over 200 000 cells) is refused in one line,
    exit 2, never compared into NaN."""
    path = tmp_path / "sparse.h5"
    from microsim import config

    cfg = config.validate({"scene": {"kind": "plane"}, "material": {"kind": "lambert", "albedo": 0.5},
                           "illumination": {"theta_i_deg": [0.0]}, "sensor": {"cells": 200_000},
                           "run": {"paths": 2000, "realizations": 4, "seed": 1}})
    write_table(cfg, path)
    assert main(["compare", str(path), "--model", "lambert", "--param", "albedo=0.5"]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "no cell" in lines[0] and "signal" in lines[0] and captured.out == "", captured


def medium_table(directory, seed: int, albedo: float = 0.9):
    """An isotropic half space (exact model: rte_isotropic) at 31 paths a cell: 25 000 paths an
    incidence over 800 cells, 32 realizations."""
    from microsim import config

    cfg = config.validate({
        "scene": {"kind": "halfspace_medium", "phase": "isotropic"},
        "material": {"kind": "lambert", "albedo": albedo},
        "illumination": {"theta_i_deg": [0.0, 45.0, 80.0]},
        "sensor": {"cells": 800},
        "run": {"paths": 25_000, "realizations": 32, "seed": seed},
    })
    return trace_table(cfg, directory / f"medium{seed}.h5")


@pytest.fixture(scope="module")
def media(tmp_path_factory):
    """12 seeds of the medium: 900 000 paths in all."""
    directory = tmp_path_factory.mktemp("media")
    return [medium_table(directory, seed) for seed in range(1, 13)]


def test_chi_square_per_cell_of_an_exact_model_is_1_within_its_bounds_at_few_paths_a_cell(media):
    """Chi-square per cell with the variance the model predicts. Each
    incidence's value falls outside its 99 % bounds with probability 0.01 (4 of 36 or more:
    probability 5e-4), and their mean is 1 within 4 standard deviations of a mean of 36. With
    each cell's own error (mean z^2) 9 of 36 fall outside."""
    from microsim.analysis import compare as compare_module

    rows = [row for table in media
            for row in compare_module.compare(table, "rte_isotropic", albedo=0.9).as_dict()["per_incidence"]]
    chi2 = np.array([row["chi2_per_cell"] for row in rows])
    low, high = np.array([row["chi2_bounds"] for row in rows]).T
    outside = np.count_nonzero((chi2 < low) | (chi2 > high))
    spread = np.mean(high - low) / (2 * 2.576)  # the standard deviation of one value, from its bounds
    assert outside <= 3, chi2
    assert abs(chi2.mean() - 1.0) <= 4 * spread / np.sqrt(len(chi2)), (chi2.mean(), spread)
    assert sum(row["consistent"] for row in rows) >= len(rows) - 4


def test_a_model_3_percent_off_is_inconsistent(media):
    from microsim.analysis import compare as compare_module

    overall = compare_module.compare(media[0], "rte_isotropic", albedo=0.93).as_dict()["overall"]
    assert not overall["consistent"] and overall["albedo_z2"] > overall["albedo_z2_bound"]


def test_compare_prints_chi_square_its_bounds_and_a_verdict(small_table, capsys):
    assert main(["compare", str(small_table), "--model", "lambert", "--param", "albedo=0.5"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "chi2/cell" in lines[1] and "bounds" in lines[1] and "verdict" in lines[1]
    rows = lines[2:]
    assert len(rows) == 3 and rows[-1].split()[0] == "overall"
    for row in rows:
        chi2, low, high = float(row.split("[")[0].split()[-1]), *map(float, row.split("[")[1].split("]")[0].split(","))
        albedo_z2, bound, verdict = row.split("]")[1].split()[:3]
        assert verdict == ("consistent" if low <= chi2 <= high and float(albedo_z2) <= float(bound) else "inconsistent")
        assert verdict == "consistent"  # the exact model
