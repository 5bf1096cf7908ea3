"""The tabulated BRDF: a full-BRDF table read at any pair of
directions, against its source (a plane's exact albedo / pi, a held-out incidence of Boolean
spheres, its own albedos), table against table cell by cell, and its sampling against its pdf."""

import dataclasses

import numpy as np
import pytest
from scipy.stats import chi2 as chi2_distribution

from microsim import config
from microsim.analysis import compare
from microsim.analysis.averages import CellRule
from microsim.cli import main
from microsim.config import full_brdf
from microsim.config.full_brdf import MAX_COS_GAP
from microsim.core import table_noise
from microsim.core.frames import direction
from microsim.models.tabulated import TabulatedBRDF
from microsim.testing import trace_table
from microsim.testing.refusals import assert_run_refused, small_config
from microsim.tracer.sensor import Sensor

SPHERES = {
    "scene": {"kind": "poisson_spheres", "volume_fraction": 0.3},
    "material": {"kind": "lambert", "albedo": 0.8},
    "sensor": {"cells": 400},
}


def traced(directory, name, illumination, paths, seed, base=SPHERES):
    return trace_table({**base, "illumination": illumination, "run": {"paths": paths, "realizations": 8, "seed": seed}},
                       directory / f"{name}.h5")


@pytest.fixture(scope="module")
def full(tmp_path_factory):
    """The full BRDF of Boolean spheres (phi = 0.3): 13 incidences at the 400-cell sensor's rings."""
    return traced(tmp_path_factory.mktemp("full"), "full", {"incidences": 13}, 40_000, seed=1)


def random_directions(n, rng, grazing=False):
    mu = rng.random(n) * (0.05 if grazing else 1.0)
    return direction(np.arccos(mu), rng.uniform(-np.pi, np.pi, n))


def test_a_plane_table_tabulates_albedo_over_pi_everywhere(tmp_path):
    """A Lambertian plane's table holds albedo / pi in every cell in expectation; its cells as a
    run estimates them are noisy, so the plane's exact table (the same cells and incidences) is
    tabulated: the interpolant is a convex combination of its cells, 1e-12 from albedo / pi at any
    pair, and its pdf is the cosine's."""
    plane = {"scene": {"kind": "plane"}, "material": {"kind": "lambert", "albedo": 0.6}, "sensor": {"cells": 400}}
    table = traced(tmp_path, "plane", {"incidences": 13}, 2000, seed=1, base=plane)
    exact = TabulatedBRDF(dataclasses.replace(table, brdf=np.full_like(table.brdf, 0.6 / np.pi)))
    rng = np.random.default_rng(3)
    wi = np.concatenate([random_directions(4000, rng), random_directions(1000, rng, grazing=True), [[0, 0, 1.0]] * 4])
    wo = np.concatenate([random_directions(4000, rng), random_directions(1000, rng), random_directions(4, rng)])
    np.testing.assert_allclose(exact(wi, wo), 0.6 / np.pi, rtol=1e-12, atol=0)
    np.testing.assert_allclose(exact.pdf(wi, wo), wo[:, 2] / np.pi, rtol=1e-12, atol=0)


def test_the_tabulated_brdf_is_reciprocal_and_positive(full):
    tabulated = TabulatedBRDF(full)
    rng = np.random.default_rng(4)
    wi, wo = random_directions(20_000, rng), random_directions(20_000, rng)
    f, reverse = tabulated(wi, wo), tabulated(wo, wi)
    assert np.all(f > 0)
    np.testing.assert_allclose(f, reverse, rtol=1e-14, atol=0)


def test_a_held_out_incidence_is_predicted_within_both_tables_errors(full, tmp_path):
    """Incidences halfway between the full table's, traced with another seed: the tabulated BRDF
    averaged over their cells (its errors propagated) is consistent with them, chi-square per cell
    and albedos within their bounds. The interpolation's own error (docs/guide/tabulated.md:
    0.8 % RMS at 13 incidences, halfway, lambert_sphere) is under these tables' noise (~30 % a
    cell at 40 000 paths an incidence), so the bounds have no share of it."""
    nodes = full_brdf.polar_angles_deg(13, 400)
    halfway = [0.5 * (a + b) for a, b in zip(nodes[:-1], nodes[1:])][::2]
    held_out = traced(tmp_path, "held", {"theta_i_deg": halfway, "phi_i_deg": 40.0}, 40_000, seed=2)
    result = compare.compare(held_out, TabulatedBRDF(full))
    overall = result.metrics()
    assert result.model_errors.startswith("both:")
    low, high = overall["chi2_bounds"]
    assert low <= overall["chi2_per_cell"] <= high, overall
    assert overall["albedo_z2"] <= overall["albedo_z2_bound"], overall


#: the interpolation's largest albedo error at the traced incidences, 13 of them at 400 to 3240
#: cells (benchmarks/tabulated_accuracy.py, docs/guide/tabulated.md: 0.58 % to 1.34 %, at grazing)
INTERPOLATION_ALBEDO = 0.014


def test_its_albedo_at_every_incidence_is_the_tables_within_errors(full):
    """The tabulated BRDF averaged over the table's own cells at its own incidences: the albedos
    differ by what the interpolation and the reciprocal average move (a bias, measured without
    noise), within three of the table's standard errors plus that bias."""
    result = compare.compare_tabulated(full, TabulatedBRDF(full))
    gap = np.abs(result.albedo_model - full.albedo)
    assert np.all(gap <= 3.0 * full.albedo_stderr + INTERPOLATION_ALBEDO * full.albedo), gap / full.albedo_stderr


def test_a_table_against_itself_gives_chi_square_zero(full):
    result = compare.compare(full, TabulatedBRDF(full))
    overall = result.metrics()
    assert overall["chi2_per_cell"] == 0.0 and overall["albedo_z2"] == 0.0
    assert result.model_errors.startswith("both tables', cell by cell")
    assert "by construction" in result.warning


def test_tables_of_one_seed_are_flagged_as_not_independent(full, tmp_path, capsys):
    """compare's bounds are for independent tables: two tables of the same seed share their
    geometry and random numbers, and compare says so (on stderr, and in the JSON); of another
    seed, not."""
    held = {"theta_i_deg": [20.0, 50.0]}
    same, other = (traced(tmp_path, f"seed{seed}", held, 2000, seed=seed) for seed in (1, 2))
    assert "seed 1" in compare.compare(same, TabulatedBRDF(full)).warning
    assert compare.compare(other, TabulatedBRDF(full)).warning is None
    assert main(["compare", str(same.path), "--model", "table", "--param", f"path={full.path}"]) == 0
    assert capsys.readouterr().err.startswith("warning: both tables were traced with seed 1")
    assert main(["compare", str(other.path), "--model", "table", "--param", f"path={full.path}", "--json"]) == 0
    assert "warning" not in capsys.readouterr().out


def test_two_tables_of_a_few_incidences_compare_cell_by_cell(tmp_path):
    """Not full BRDFs (4 incidences), but the same cells and incidences: cell by cell, within the
    bounds of both tables' errors; reading either as a BRDF is refused."""
    few = {"theta_i_deg": [0.0, 30.0, 60.0, 85.0]}
    a, b = (traced(tmp_path, f"few{seed}", few, 20_000, seed=seed) for seed in (1, 2))
    overall = compare.compare(a, TabulatedBRDF(b)).metrics()
    low, high = overall["chi2_bounds"]
    assert low <= overall["chi2_per_cell"] <= high, overall
    with pytest.raises(ValueError, match="not a full BRDF"):
        TabulatedBRDF(b)(a.wi, a.wi)


@pytest.mark.parametrize("flag", ["--points", "--retro"])
def test_points_and_rings_against_a_tabulated_brdf_are_refused(full, capsys, flag):
    assert main(["compare", str(full.path), "--model", "table", "--param", f"path={full.path}", flag]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and flag in err[0] and "--model table" in err[0], err


@pytest.mark.slow
def test_two_seeds_agree_cell_by_cell_with_both_errors(full, tmp_path):
    """Chi-square per cell over the variance of the difference (both tables' errors: twice one
    table's, so 2 in units of one table's) is 1 in expectation."""
    other = traced(tmp_path, "seed2", {"incidences": 13}, 40_000, seed=2)
    result = compare.compare(full, TabulatedBRDF(other))
    overall = result.metrics()
    low, high = overall["chi2_bounds"]
    assert low <= overall["chi2_per_cell"] <= high and overall["consistent"], overall
    assert result.model_errors.startswith("both tables'")
    # the errors a tabulated BRDF propagates from its table: the two seeds' tabulated BRDFs,
    # averaged over the same cells, differ by what they say
    first, second = TabulatedBRDF(full), TabulatedBRDF(other)
    p = full.projected_solid_angle
    chi2, commons, kurtoses, correlated = [], [], [], 0.0
    for wi in full.wi[::3]:
        rule = CellRule(full.sensor, wi, np.full(full.sensor.n_cells, 8))
        one, two = first.cell_average_noise(rule, p), second.cell_average_noise(rule, p)
        lit = (one.averages > 0) & (two.averages > 0)
        variance = one.variance + two.variance
        chi2.append((one.averages[lit] - two.averages[lit]) ** 2 / variance[lit])
        commons.append((one.common[lit] + two.common[lit]) / variance[lit])
        kurtoses.append(np.zeros(lit.sum()))
        correlated += table_noise.correlated_pairs(one.covariance + two.covariance, variance, lit)
    low, high = table_noise.chi2_bounds(np.concatenate(kurtoses), np.concatenate(commons), correlated)
    assert low <= np.mean(np.concatenate(chi2)) <= high, (np.mean(np.concatenate(chi2)), low, high)


@pytest.fixture(scope="module")
def grid(tmp_path_factory):
    """Boolean spheres at 13 polar angles x 3 azimuths (0, 120, 240 deg): a table whose cells lie
    in the scene's frame of incidences at several azimuths."""
    return traced(tmp_path_factory.mktemp("grid"), "grid", {"incidences": 13, "azimuths": 3}, 8000, seed=1)


def test_at_a_traced_incidence_and_a_cells_centre_the_interpolant_is_that_cells_value(full, grid):
    """Before it is made reciprocal: the weights collapse onto the incidence and the cell, whatever
    the incidence's azimuth (the cells lie in the scene's frame: an incidence at phi_i = 120 deg
    has its backscatter cells at phi = 120 deg), and onto the normal incidence near it."""
    for table in (full, grid):
        tabulated = TabulatedBRDF(table)
        centres = table.sensor.directions()
        for k in range(len(table.theta_i)):
            wi = np.broadcast_to(table.wi[k], centres.shape)
            np.testing.assert_allclose(tabulated.interpolated(wi, centres), table.brdf[k], rtol=1e-9,
                                       atol=1e-12 * table.brdf.max(),
                                       err_msg=f"incidence {k}")
        # towards the normal from any azimuth: the normal incidence's cells, in the scene's frame
        for phi in (0.3, 2.0, 3.5, 5.9):
            wi = np.broadcast_to(direction(1e-7, phi), centres.shape)
            normal = int(np.argmin(table.theta_i))
            np.testing.assert_allclose(tabulated.interpolated(wi, centres), table.brdf[normal], rtol=1e-6,
                                       atol=1e-9 * table.brdf.max(), err_msg=f"towards the normal at {phi}")


@pytest.mark.parametrize("which, phi_i", [("full", 0.7), ("grid", 0.7), ("grid", 4.0)])
def test_sampling_follows_its_pdf(full, grid, which, phi_i):
    """Directions sampled for an incidence between the table's, at an azimuth of its own, binned
    in a grid of (cos^2 theta_o, phi_o) cells that cut across the sensor's: chi-square within its
    two-sided 99 % bounds against the pdf's exact integral over each bin (the pdf is cos theta_o
    times a constant in each sensor cell, turned by phi_i: each bin's share is the sum over the
    sensor cells of their overlaps, in projected solid angle)."""
    tabulated = TabulatedBRDF({"full": full, "grid": grid}[which])
    theta_i, n = np.radians(37.0), 200_000
    rng = np.random.default_rng(5)
    wi = np.tile(direction(theta_i, phi_i), (n, 1))
    wo, pdf = tabulated.sample(wi, rng.random(n), rng.random((n, 2)))
    assert np.all(pdf > 0)
    np.testing.assert_allclose(pdf, tabulated.pdf(wi, wo), rtol=1e-12)
    rows, columns = 10, 24
    cos2 = np.clip(wo[:, 2], 0, 1) ** 2
    phi = np.mod(np.arctan2(wo[:, 1], wo[:, 0]), 2 * np.pi)
    observed = np.histogram2d(cos2, phi, bins=[np.linspace(0, 1, rows + 1), np.linspace(0, 2 * np.pi, columns + 1)])[0]
    expected = n * bin_probabilities(tabulated, direction(theta_i, phi_i).reshape(1, 3), rows, columns)
    assert abs(expected.sum() - n) < 1e-6 * n
    statistic = np.sum((observed - expected) ** 2 / expected)
    dof = rows * columns - 1
    assert chi2_distribution.ppf(0.005, dof) <= statistic <= chi2_distribution.ppf(0.995, dof), statistic


def bin_probabilities(tabulated, wi, rows, columns):
    """The pdf's integral over each (cos^2 theta, phi) bin, exactly: sum over the sensor cells of
    the incidences' shares times each cell's overlap with the bin over its own extent (both are
    rectangles in cos^2 theta and phi, and the pdf is uniform in them within a cell)."""
    phi_i = np.arctan2(wi[0, 1], wi[0, 0])
    incidence, weight, azimuth = tabulated.grid.weights(np.array([wi[0, 2]]), np.array([phi_i]))
    lo2, hi2 = tabulated.cos2_hi, tabulated.cos2_lo  # cos^2 runs opposite to theta
    c_edges, p_edges = np.linspace(0, 1, rows + 1), np.linspace(0, 2 * np.pi, columns + 1)
    out = np.zeros((rows, columns))
    for k, w, a in zip(incidence[0], weight[0], azimuth[0]):  # each incidence's cells, turned to wi's frame
        share = w * tabulated.share[k]
        turn = phi_i - a
        p_lo, p_hi = tabulated.phi_lo + turn, tabulated.phi_hi + turn
        for r in range(rows):
            dc = np.clip(np.minimum(hi2, c_edges[r + 1]) - np.maximum(lo2, c_edges[r]), 0, None) / (hi2 - lo2)
            for c in range(columns):
                dp = sum(np.clip(np.minimum(p_hi + m, p_edges[c + 1]) - np.maximum(p_lo + m, p_edges[c]), 0, None)
                         for m in (-4 * np.pi, -2 * np.pi, 0.0, 2 * np.pi, 4 * np.pi)) / (p_hi - p_lo)
                out[r, c] += np.sum(share * dc * dp)
    return out


def test_a_table_of_too_few_incidences_is_refused_in_one_line(full, tmp_path, capsys):
    few = traced(tmp_path, "few", {"theta_i_deg": [0.0, 30.0, 60.0, 85.0]}, 2000, seed=1)
    assert main(["compare", str(full.path), "--model", "table", "--param", f"path={few.path}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a full BRDF" in err[0] and f"at most {MAX_COS_GAP:g}" in err[0] \
        and "illumination.incidences" in err[0], err


@pytest.mark.parametrize("value, words", [("missing.h5", "no such file"), ("config.toml", "not a microsim table"),
                                          ("tables", "is a directory, not a file")])
def test_a_missing_or_foreign_file_is_refused_in_one_line(full, tmp_path, capsys, value, words):
    (tmp_path / "config.toml").write_text("[scene]\n")
    (tmp_path / "tables").mkdir()
    assert main(["compare", str(full.path), "--model", "table", "--param", f"path={tmp_path / value}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0] and "path" in err[0], err


def test_incidences_are_the_rings_that_keep_the_widest_gap_least_then_most_even():
    """Against every choice of 7 of the 400-cell sensor's 13 rings (the first and the last kept):
    the chooser's widest gap in cos theta_i is the least of them all, and its sum of squared
    gaps the least among those of that widest gap."""
    import itertools

    cfg = config.validate({**SPHERES, "illumination": {"incidences": 7}, "run": {"paths": 1000}})
    centres = np.degrees(Sensor.build(400).ring_centres())
    assert Sensor.build(400).n_rings == 13
    chosen = np.cos(np.radians(cfg.illumination.theta_i_deg))
    assert set(cfg.illumination.theta_i_deg) <= set(centres) and cfg.illumination.theta_i_deg[0] == 0.0

    def gaps(cosines):
        return -np.diff(np.concatenate([[1.0], cosines, [0.0]]))

    choices = [np.cos(np.radians(centres[[0, *middle, 12]])) for middle in itertools.combinations(range(1, 12), 5)]
    least = min(gaps(c).max() for c in choices)
    assert gaps(chosen).max() == pytest.approx(least, rel=1e-12)
    evenest = min(np.sum(gaps(c) ** 2) for c in choices if gaps(c).max() <= least * (1 + 1e-12))
    assert np.sum(gaps(chosen) ** 2) == pytest.approx(evenest, rel=1e-12)
    assert cfg.illumination.phi_i_deg == [0.0] * 7
    tilted = config.validate({**SPHERES, "illumination": {"incidences": 7, "azimuths": 4}, "run": {"paths": 1000}})
    assert len(tilted.illumination.theta_i_deg) == 1 + 6 * 4
    assert sorted(set(tilted.illumination.phi_i_deg)) == [0.0, 90.0, 180.0, 270.0]


@pytest.mark.parametrize("cells", [100, 400, 1600, 3240])
def test_every_full_brdf_run_accepted_is_a_full_brdf_to_its_readers(cells):
    """What the run accepts (illumination.incidences = N) is what TabulatedBRDF, export and render
    accept (no gap wider than MAX_COS_GAP), and what it refuses they would refuse: the least N it
    accepts is the least whose rings can keep the gaps within it. (7 incidences at 3240 cells,
    chosen evenly in rings, left 0.261 and were refused by every reader after the run.)"""
    rings = Sensor.build(cells).n_rings
    accepted = []
    for n in range(2, rings + 1):
        try:
            thetas = full_brdf.polar_angles_deg(n, cells)
        except ValueError as err:
            assert "illumination.incidences" in str(err) and "accepted" in str(err)
            continue
        accepted.append(n)
        assert full_brdf.widest_gap(np.cos(np.radians(thetas)))[0] <= MAX_COS_GAP, (n, thetas)
    assert accepted == list(range(accepted[0], rings + 1))
    if accepted[0] > 2:  # one fewer cannot: every choice of that many rings leaves a wider gap
        import itertools

        centres = np.cos(Sensor.build(cells).ring_centres())
        k = accepted[0] - 1
        widest = min(full_brdf.widest_gap(centres[[0, *middle, rings - 1]])[0]
                     for middle in itertools.combinations(range(1, rings - 1), k - 2))
        assert widest > MAX_COS_GAP
    assert cells != 3240 or 7 in accepted


def test_an_anisotropic_table_is_read_on_its_grid_of_polar_angles_and_azimuths(tmp_path):
    """Incidences at 3 azimuths: interpolated in phi_i too, periodically; a constant table gives
    its constant back, and the tabulated BRDF is reciprocal."""
    table = traced(tmp_path, "grid", {"incidences": 13, "azimuths": 3}, 2000, seed=1)
    tabulated = TabulatedBRDF(table)
    assert tabulated.grid.anisotropic and tabulated.grid.index.shape == (13, 3)
    rng = np.random.default_rng(6)
    wi, wo = random_directions(5000, rng), random_directions(5000, rng)
    np.testing.assert_allclose(tabulated(wi, wo), tabulated(wo, wi), rtol=1e-14, atol=0)
    constant = TabulatedBRDF(dataclasses.replace(table, brdf=np.full_like(table.brdf, 0.2)))
    np.testing.assert_allclose(constant(wi, wo), 0.2, rtol=1e-12, atol=0)
    # at a traced incidence the interpolation in phi_i puts all its weight there
    incidence, weight, _ = tabulated.grid.weights(np.cos(table.theta_i[5:9]), table.phi_i[5:9])
    np.testing.assert_allclose(np.max(weight, axis=1), 1.0, rtol=0, atol=1e-12)
    assert np.array_equal(incidence[np.arange(4), np.argmax(weight, axis=1)], np.arange(5, 9))


@pytest.mark.parametrize("illumination, key, words", [
    ('incidences = 20', "illumination.incidences", ("13 rings", "sensor.cells = 400", "2 to 13")),
    ('incidences = 7\ntheta_i_deg = [30.0]', "illumination.theta_i_deg", ("incidences",)),
    ('theta_i_deg = [30.0]\nazimuths = 4', "illumination.azimuths", ("only with illumination.incidences",)),
    ('incidences = 1', "illumination.incidences", ("2",)),
    ('incidences = 4', "illumination.incidences", ("gap of 0.361", "sensor.cells = 400", "6 to 13")),
])
def test_a_full_brdf_config_that_cannot_be_traced_is_refused(tmp_path, capsys, illumination, key, words):
    text = small_config('kind = "plane"').replace("theta_i_deg = [30.0]", illumination).replace("cells = 100",
                                                                                                "cells = 400")
    assert_run_refused(text, key, tmp_path, capsys, *words)
