"""``microsim fit``: it recovers the parameters of tables made from a model and
the albedo of a plane table, reports a poor fit honestly, and refuses bad input in one line; on
simulated tables of few paths a cell its fits are unbiased and its errors calibrated."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from microsim import models
from microsim.analysis.averages import refined_cell_averages
from microsim.analysis.fit import fit
from microsim.cli import main
from microsim.testing import trace_table
from microsim.testing.refusals import assert_refused

#: relative standard error of the synthetic tables
NOISE = 0.01
#: synthetic tables fitted per model
DRAWS = 8
#: simulated tables (seeds) per unbiasedness check
SEEDS = 30


@pytest.fixture(scope="module")
def medium_table(tmp_path_factory):
    """A real table (isotropic medium, albedo 0.9, 3 incidences, 400 cells): its sensor and
    incidences carry the synthetic tables, and its values the poor fit."""
    from microsim import config

    cfg = config.validate({"scene": {"kind": "halfspace_medium", "phase": "isotropic"},
                           "material": {"kind": "lambert", "albedo": 0.9},
                           "illumination": {"theta_i_deg": [0.0, 40.0, 70.0]}, "sensor": {"cells": 400},
                           "run": {"paths": 200_000, "realizations": 16, "seed": 3}})
    return trace_table(cfg, tmp_path_factory.mktemp("fit") / "medium.h5")


def cell_values(table, model):
    """The model's cell averages on the table's cells and incidences, converged far below NOISE."""
    return np.stack([refined_cell_averages(model, table.sensor, wi, np.zeros(table.sensor.n_cells), 1e-3)[0]
                     for wi in table.wi])


def synthetic(table, exact, rng):
    """``table`` with its BRDF replaced by the cell averages ``exact`` times (1 + NOISE x a normal
    number), and standard errors NOISE x the averages; ``rng`` None: no noise. Noise independent
    from cell to cell is that of a table of countless paths (each path's exit cell ties the cells
    of a real table; ``fit`` takes that tie from ``paths``), and an albedo error that is the
    cells' alone."""
    stderr = NOISE * exact
    noise = rng.standard_normal(exact.shape) if rng is not None else 0.0
    brdf, projected = exact + stderr * noise, table.projected_solid_angle
    return dataclasses.replace(table, brdf=brdf, brdf_stderr=stderr, paths=np.full_like(table.paths, 10**15),
                               albedo=brdf @ projected, albedo_stderr=np.sqrt(stderr**2 @ projected**2))


@pytest.mark.parametrize("name,truth,start", [
    ("oren_nayar", {"albedo": 0.7, "roughness": 0.4}, {"albedo": "0.5", "roughness": "0.1"}),
    ("rte_isotropic", {"albedo": 0.95}, {"albedo": "0.5"}),
    ("hapke", {"albedo": 0.8, "volume_fraction": 0.3}, {"albedo": "0.5", "volume_fraction": "0.1"}),
])
def test_recovers_the_parameters_of_a_table_made_from_a_model(medium_table, name, truth, start):
    """DRAWS tables made from the model with independent noise:
    - the mean of the fits within two standard errors (of that mean) of the parameters that made
      them;
    - the standard errors calibrated: the sum over fits and parameters of ((best - truth) / error)^2
      is chi^2 with DRAWS x parameters degrees of freedom, so it lies between its 0.05 % and
      99.95 % quantiles (errors 4 times too large or too small fall outside);
    - chi^2 per degree of freedom near 1 (within 5 of its standard deviations, sqrt(2 / dof)).
    Without noise the fit returns the parameters to 1e-9."""
    from scipy.stats import chi2

    exact, rng = cell_values(medium_table, models.create(name, **truth)), np.random.default_rng(7)
    fits = [fit(synthetic(medium_table, exact, rng), name, list(truth), start) for _ in range(DRAWS)]
    z2 = 0.0
    for key, value in truth.items():
        best = np.array([f.free[key][0] for f in fits])
        error = np.array([f.free[key][1] for f in fits])
        assert np.all((error > 0) & (error < 0.05)), (key, error)
        assert abs(best.mean() - value) <= 2 * error.mean() / np.sqrt(DRAWS), (key, best, error)
        z2 += np.sum(((best - value) / error) ** 2)
    dof = DRAWS * len(truth)
    assert chi2.ppf(5e-4, dof) <= z2 <= chi2.ppf(1 - 5e-4, dof), (z2, dof)
    assert all(abs(f.chi2_per_dof - 1.0) <= 5 * np.sqrt(2 / f.dof) for f in fits)
    for key, (best, _) in fit(synthetic(medium_table, exact, None), name, list(truth), start).free.items():
        assert abs(best - truth[key]) <= 1e-9


def test_recovers_the_albedo_of_a_plane_table(simulate):
    table = simulate({"scene": {"kind": "plane"}, "material": {"kind": "lambert", "albedo": 0.6},
                      "illumination": {"theta_i_deg": [0.0, 50.0]}, "sensor": {"cells": 100},
                      "run": {"paths": 400_000, "realizations": 16, "seed": 5}})
    result = fit(table, "lambert", ["albedo"], {})
    best, error = result.free["albedo"]
    assert abs(best - 0.6) <= 2 * error and error < 2e-3


def test_reports_a_poor_fit_honestly(medium_table, capsys):
    """A Lambertian surface cannot describe the medium (its BRDF rises to grazing): chi^2 per
    degree of freedom more than 20 of its standard deviations (sqrt(2 / dof)) above 1, where a
    fitting model stays within 5 (9.4 measured on 200 000 paths, 1200 cells: 150 standard
    deviations), printed, and in the JSON with the best value and its error."""
    assert main(["fit", str(medium_table.path), "--model", "lambert", "--free", "albedo", "--json"]) == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert out["fit_chi2_per_dof"] > 1 + 20 * np.sqrt(2 / out["fit_dof"])
    assert set(out["fit"]["albedo"]) == {"value", "stderr"}
    assert {"model", "per_incidence", "overall"} <= out.keys()
    assert main(["fit", str(medium_table.path), "--model", "lambert", "--free", "albedo"]) == 0
    assert "chi^2 / dof = " in capsys.readouterr().out


@pytest.mark.parametrize("args,key", [
    (["--model", "lambert"], "--free"),
    (["--model", "lambert", "--free", "roughness"], "--free roughness"),
    (["--model", "lambert_sphere", "--free", "method"], "--free method"),
    (["--model", "table", "--free", "path"], "--free path"),
    (["--model", "lambert", "--free", "albedo", "--free", "albedo"], "--free"),
    (["--model", "velvet", "--free", "albedo"], "--model"),
    (["--model", "oren_nayar", "--free", "albedo", "--param", "roughness=3"], "roughness"),
    (["--model", "lambert", "--free", "albedo", "--order", "1-base"], "--order 1-base"),
])
def test_bad_input_gives_one_line_and_exit_2(medium_table, capsys, args, key):
    assert_refused(["fit", medium_table.path, *args], capsys, key)


def test_a_missing_table_gives_one_line(tmp_path, capsys):
    assert main(["fit", str(tmp_path / "none.h5"), "--model", "lambert", "--free", "albedo"]) == 2
    assert "TABLE.h5" in capsys.readouterr().err


def simulated_fits(simulate, kind: str, paths_per_cell: int, cells: int, seeds: int = SEEDS):
    """(z-scores (fit - truth) / error, |fit - truth|) of the albedo over ``seeds`` simulated
    tables: a Lambertian plane of albedo 0.5 fitted with ``lambert``, or an isotropic half space
    of single-scattering albedo 0.9 fitted with ``rte_isotropic``."""
    scene, model, truth, incidences = {
        "plane": ({"kind": "plane"}, "lambert", 0.5, [0.0, 80.0]),
        "medium": ({"kind": "halfspace_medium", "phase": "isotropic"}, "rte_isotropic", 0.9, [0.0, 60.0]),
    }[kind]
    z, off = [], []
    for seed in range(1, seeds + 1):
        table = simulate({"scene": scene, "material": {"kind": "lambert", "albedo": truth},
                          "illumination": {"theta_i_deg": incidences}, "sensor": {"cells": cells},
                          "run": {"paths": paths_per_cell * cells, "realizations": 32, "seed": seed}})
        value, error = fit(table, model, ["albedo"], {}).free["albedo"]
        z.append((value - truth) / error)
        off.append(abs(value - truth))
    return np.array(z), np.array(off)


def assert_unbiased_and_calibrated(z):
    """Mean z within 3.5 of its standard errors (1 / sqrt(seeds)) of 0; the spread of z that of a
    unit normal: (seeds - 1) s^2 between the 0.05 % and 99.95 % quantiles of chi^2(seeds - 1)."""
    from scipy.stats import chi2

    assert abs(z.mean()) <= 3.5 / np.sqrt(len(z)), z
    spread = (len(z) - 1) * z.var(ddof=1)
    assert chi2.ppf(5e-4, len(z) - 1) <= spread <= chi2.ppf(1 - 5e-4, len(z) - 1), (z.std(ddof=1), z)


@pytest.mark.parametrize("paths_per_cell", [30, 125, pytest.param(4000, marks=pytest.mark.slow)])
def test_fits_of_a_medium_are_unbiased_at_few_paths_a_cell(simulate, paths_per_cell):
    """With the variances the model predicts, fits of this medium's albedo are unbiased and their
    errors calibrated at few paths a cell. Weighted by each cell's own error the albedo comes out
    1.55 standard errors low on average at 125 paths a cell (z spread 0.64), 0.38 low at 4000;
    with the cells fitted chosen by their own value, 1.4 high at 32 paths a cell."""
    z, _ = simulated_fits(simulate, "medium", paths_per_cell, cells=100 if paths_per_cell < 1000 else 25)
    assert_unbiased_and_calibrated(z)


@pytest.mark.parametrize("paths_per_cell", [30, 125])
def test_fits_of_a_plane_are_exact(simulate, paths_per_cell):
    """A plane's albedo fit sums every path, each of weight 0.5: sum_C P_C (a / pi - f_C) = 0 is
    a = 0.5 exactly. Weighted by each cell's own error it comes out 1.65 standard errors low on
    average at 125 paths a cell; fitted on the cells with signal only, 3.0 high at 32 paths a cell
    (0.5024 +- 0.0009)."""
    _, off = simulated_fits(simulate, "plane", paths_per_cell, cells=100)
    assert off.max() < 1e-9, off


def test_a_parameter_without_default_starts_at_1_in_a_range_of_decades():
    """A parameter without a default starts at 1 if its range spans decades (beta in [0.001, 1000]
    at its middle, 500, starts a fit of micrograins too far from its answer to end in minutes),
    else at the middle of its range."""
    from microsim import models
    from microsim.analysis import fit as fit_module

    params = {p.name: p for p in models.get("micrograin").params}
    assert fit_module._start(params["beta"], None) == pytest.approx(1.0)
    assert fit_module._start(params["tau0"], None) == pytest.approx(0.5)  # a range of less than two decades
    assert fit_module._start(params["beta"], "3") == 3.0


def test_an_incidence_without_signal_is_left_out(medium_table):
    """Its cells cannot pool a dispersion (all variances 0): fitting it failed as "residuals are not
    finite"; the other incidences fit as they do alone."""
    dark = medium_table.brdf.copy(), medium_table.brdf_stderr.copy()
    for values in dark:
        values[1] = 0.0
    table = dataclasses.replace(medium_table, brdf=dark[0], brdf_stderr=dark[1])
    others = dataclasses.replace(medium_table, brdf=medium_table.brdf[[0, 2]], brdf_stderr=medium_table.brdf_stderr[[0, 2]],
                                 theta_i=medium_table.theta_i[[0, 2]], phi_i=medium_table.phi_i[[0, 2]],
                                 albedo=medium_table.albedo[[0, 2]], albedo_stderr=medium_table.albedo_stderr[[0, 2]],
                                 paths=medium_table.paths[[0, 2]])
    value, error = fit(table, "rte_isotropic", ["albedo"], {"albedo": 0.8}).free["albedo"]
    alone = fit(others, "rte_isotropic", ["albedo"], {"albedo": 0.8}).free["albedo"]
    assert abs(value - alone[0]) <= 1e-3 * error and error == pytest.approx(alone[1], rel=1e-6)


def test_fit_refuses_a_model_made_already(medium_table):
    with pytest.raises(ValueError, match="fit takes a model's name, class or function"):
        fit(medium_table, models.create("rte_isotropic", albedo=0.5), ["albedo"])
