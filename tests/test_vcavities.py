"""V-cavity surfaces: the scene, exact single scattering against the microfacet models
with the Torrance-Sparrow G, energy, reciprocity, limits, the two intersectors and bad input.

Single scattering. With ``max_order = 1`` the table's order 1 is the single
scattering of the explicit grooves. For a groove of facet m, light from i lights its facet m from
the rim down to the fraction G1(i, m) = min(1, 2 (n.m)(n.i) / (i.m)) of its length, and the
viewer o sees it from the rim down to G1(o, m); a direction on the other side of the groove sees
all of it (G1 = 1 there). Both fractions start at the same rim, so the lit and seen part is
min(G1(i, m), G1(o, m)): the Torrance-Sparrow G (Eq. 14) is exact for V-cavities at every azimuth,
including out of the incidence plane and at grazing angles, and the checks below find no
disagreement. Each case is judged over the cells with signal (table > 3 standard errors) by the
mean z^2 per cell, within ``microsim.testing.bounds.chi2_bound`` / ``chi2_lower_bound`` (each z is Student-t
with R - 1 degrees of freedom; the bounds are the expected mean z^2 +- 5 standard deviations of
that mean over the cells). A realization is an independent batch of paths (nothing random is
drawn per realization), so the cells' z's are independent but for the shared normalisation.
"""

from __future__ import annotations

import json
import math

import numba
import numpy as np
import pytest

from microsim import config, geometry, models
from microsim.core.tally import SEGMENTS
from microsim.physics import distributions as nd
from microsim.physics.fresnel import fresnel_array
from microsim.physics.rng import path_state
from microsim.run import executors
from microsim.run.plan import Plan
from microsim.testing import trace, trace_table
from microsim.testing.bounds import chi2_bound, chi2_lower_bound
from microsim.testing.reciprocity import RECIPROCITY_CELLS, reciprocity_z, ring_incidences
from microsim.testing.refusals import assert_run_refused, small_config
from microsim.testing.threads import assert_bit_identical_for_threads
from microsim.testing.vcavities import (
    CELLS,
    CONDUCTOR,
    DIELECTRIC,
    DIFFUSE_FACETS,
    DIFFUSE_PATHS,
    DIFFUSE_PHI,
    DIFFUSE_THETA,
    REALIZATIONS,
    SIGNAL,
    assert_order1_matches,
    order1_agreement,
    vcavity_config,
)
from microsim.tracer.integrators.vcavity import VCavityTracer
from microsim.tracer.sensor import Sensor

# ---------------------------------------------------------------- the facet slopes

@numba.njit(cache=True)
def _slopes(code, ax, ay, n, key):
    out = np.empty((n, 2))
    states = np.empty(1, np.uint64)
    for j in range(n):
        states[0] = path_state(key, j)
        out[j] = nd.sample_slope(code, ax, ay, states, 0)
    return out


@pytest.mark.parametrize("distribution,roughness", [("beckmann", 0.3), ("ggx", 0.7), ("gaussian", 0.05),
                                                     ("gaussian", 0.2), ("gaussian", 1.2), ("gaussian", 3.0)])
def test_facet_tilts_follow_the_projected_area_density(distribution, roughness):
    """The tilt of the sampled facets falls in 20 bins of equal probability under D(m)(m.n) (the
    bin edges from the models' own inverse map, distributions.sample) with chi^2 below the
    0.999 quantile for 19 degrees of freedom (43.8). Gaussian: cut at 12 sigma (0.05), Rayleigh
    proposal (0.2), uniform-in-cosine proposal (1.2, 3)."""
    code = nd.DISTRIBUTIONS.index(distribution)
    slopes = _slopes(code, roughness, roughness, 200_000, np.uint64(7))
    tilt = np.arctan(np.hypot(slopes[:, 0], slopes[:, 1]))
    edges = nd.sample(distribution, roughness, roughness, np.arange(1, 20) / 20.0, 0.0)
    counts = np.bincount(np.searchsorted(np.arccos(edges[:, 2]), tilt), minlength=20)
    expected = len(tilt) / 20.0
    assert np.sum((counts - expected) ** 2 / expected) < 43.8


def test_anisotropic_slopes_have_the_variance_of_each_axis():
    """Beckmann slopes are Gaussian with variance roughness^2 / 2 along each axis (Eq. 15)."""
    slopes = _slopes(0, 0.2, 0.6, 400_000, np.uint64(3))
    var = slopes.var(axis=0)
    # the sample variance of n Gaussian values has relative standard error sqrt(2 / n)
    assert np.all(np.abs(var / np.array([0.02, 0.18]) - 1.0) < 5 * math.sqrt(2 / len(slopes)))


def test_anisotropic_ggx_slopes_are_the_isotropic_ones_stretched():
    """Anisotropic GGX (Eq. 20): the slopes divided by (alpha_x, alpha_y) are isotropic GGX of
    alpha 1, whose squared slope s^2 has P(s^2 < q) = q / (1 + q): 20 equiprobable bins, chi^2 below
    43.8; and their azimuth is uniform (8 bins, chi^2 below the 0.999 quantile for 7, 24.3)."""
    scaled = _slopes(1, 0.3, 1.2, 200_000, np.uint64(5)) / np.array([0.3, 1.2])
    s2 = np.sum(scaled**2, axis=1)
    p = np.arange(1, 20) / 20.0
    counts = np.bincount(np.searchsorted(p / (1 - p), s2), minlength=20)
    assert np.sum((counts - len(s2) / 20) ** 2 / (len(s2) / 20)) < 43.8
    azimuth = np.bincount(((np.arctan2(scaled[:, 1], scaled[:, 0]) + np.pi) / (2 * np.pi) * 8).astype(int) % 8)
    assert np.sum((azimuth - len(s2) / 8) ** 2 / (len(s2) / 8)) < 24.3


# ---------------------------------------------------------------- a: specular facets

@pytest.mark.parametrize("distribution", ["beckmann", "ggx"])
@pytest.mark.parametrize("roughness", [0.1, 0.3, 0.7])
@pytest.mark.slow
def test_conductor_facets_single_scattering_is_torrance_sparrow(distribution, roughness):
    result = trace(vcavity_config(CONDUCTOR, distribution, (roughness, roughness)))
    model = models.create("microfacet", distribution=distribution, roughness=roughness, gaf="torrance_sparrow",
                          eta=0.2, k=3.9)
    assert_order1_matches(result, model)


@pytest.mark.slow
def test_anisotropic_conductor_facets_at_phi_0_and_90():
    result = trace(vcavity_config(CONDUCTOR, "beckmann", (0.2, 0.6), theta=[45.0, 45.0, 85.0, 85.0],
                                       phi=[0.0, 90.0, 0.0, 90.0]))
    model = models.create("microfacet", distribution="beckmann", roughness_x=0.2, roughness_y=0.6,
                          gaf="torrance_sparrow", eta=0.2, k=3.9)
    assert_order1_matches(result, model)


@pytest.mark.parametrize("distribution", ["beckmann", "ggx"])
@pytest.mark.slow
def test_dielectric_reflection_facets_single_scattering_is_torrance_sparrow(distribution):
    result = trace(vcavity_config(DIELECTRIC, distribution, (0.3, 0.3)))
    model = models.create("microfacet", distribution=distribution, roughness=0.3, gaf="torrance_sparrow", eta=1.5)
    assert_order1_matches(result, model)


@pytest.mark.slow
def test_the_check_sees_a_wrong_masking_function():
    """Power: the same table against the Smith G (the V-cavity surface is not a Smith surface)
    lies above the upper bound at grazing incidence, while the Torrance-Sparrow G is within it."""
    result = trace(vcavity_config(CONDUCTOR, "beckmann", (0.7, 0.7), theta=[85.0]))
    for gaf, consistent in (("torrance_sparrow", True), ("smith", False)):
        model = models.create("microfacet", distribution="beckmann", roughness=0.7, gaf=gaf, eta=0.2, k=3.9)
        n, z2, _ = order1_agreement(result, model, 0)
        assert (z2 <= chi2_bound(n, REALIZATIONS)) == consistent, (gaf, n, z2)


# ---------------------------------------------------------------- b: diffuse facets



@pytest.mark.parametrize("material,eta,distribution,roughness", DIFFUSE_FACETS)
@pytest.mark.slow
def test_diffuse_facets_single_scattering_is_the_eq_2_integral(material, eta, distribution, roughness):
    result = trace(vcavity_config(material, distribution, roughness, theta=DIFFUSE_THETA, phi=DIFFUSE_PHI,
                                       paths=DIFFUSE_PATHS))
    model = models.create("interfaced_lambert", albedo=0.7, eta=eta, distribution=distribution,
                          roughness_x=roughness[0], roughness_y=roughness[1], gaf="torrance_sparrow")
    assert_order1_matches(result, model)


# ---------------------------------------------------------------- c: energy

@pytest.mark.parametrize("material", [{"kind": "lambert", "albedo": 1.0}, {"kind": "mirror"}])
@pytest.mark.parametrize("distribution", ["beckmann", "ggx", "gaussian"])
def test_white_and_mirror_facets_return_every_unit_of_energy(material, distribution):
    """albedo + truncated = 1 to 1e-6 up to theta_i = 89 deg and roughness 1.5 (nothing is absorbed
    and nothing goes through the facets); and nothing is truncated, so no path is lost, except for
    white Lambertian facets of the gaussian D at sigma = 1.5 rad. That D keeps a finite density at
    theta_m = 90 deg, so grooves of any depth occur, and the few paths deep in them are cut at
    MAX_INTERACTIONS bounces: 10 of 40 000 at theta_i = 0 (2.5e-4), 1 at 60 deg, measured; a lost
    path would count as truncated, so the bound there, 1e-3, still catches any loss of more than
    about 40 paths."""
    deep = material["kind"] == "lambert" and distribution == "gaussian"
    for roughness, most_truncated in ((0.2, 0.0), (1.5, 1e-3 if deep else 0.0)):
        cfg = vcavity_config(material, distribution, (roughness, roughness), theta=[0.0, 60.0, 85.0, 89.0],
                             paths=40_000, realizations=4, max_order=0, cells=100)
        result = trace(cfg)
        for i in range(4):
            transmitted, truncated, absorbed, balance = result.energy[i].mean
            assert abs(result.albedo[i].mean[4] + truncated - 1.0) <= 1e-6
            assert transmitted == 0.0 and absorbed == 0.0 and truncated <= most_truncated


# ---------------------------------------------------------------- multiple scattering, brute force

def brute_force_mirror_grooves(n, rng, ax, ay, wi, orders):
    """Exit directions of n paths in mirror V-grooves by order (1 .. orders), written apart from
    the tracer: Beckmann slopes as Gaussian numbers (variance a^2 / 2 per axis), the groove as
    two facet planes in 3D, a path's crossings with them and with the rim plane by numpy."""
    slopes = rng.normal(size=(n, 2)) * np.array([ax, ay]) / math.sqrt(2.0)
    m = np.column_stack([slopes, np.ones(n)])
    m /= np.linalg.norm(m, axis=1, keepdims=True)
    mirror = m * np.array([-1.0, -1.0, 1.0])
    across = slopes / np.linalg.norm(slopes, axis=1, keepdims=True)  # horizontal unit vector of m
    # the groove: aperture of half-width 1 across, z = 0; facet m passes through the rim point
    # at -1 across, facet m' through the one at +1
    rim_left = np.column_stack([-across, np.zeros(n)])
    rim_right = -rim_left
    p = np.column_stack([rng.uniform(-1, 1, n)[:, None] * across, np.zeros(n)])
    d = np.tile(-np.asarray(wi, float), (n, 1))
    exits = {k: np.zeros((0, 3)) for k in range(1, orders + 1)}
    alive = np.ones(n, bool)
    for bounce in range(orders + 1):
        t = np.full(n, np.inf)
        hit = np.full(n, -1)
        up = d[:, 2] > 0
        t[up] = -p[up, 2] / d[up, 2]
        for facet, (normal, point) in enumerate(((m, rim_left), (mirror, rim_right))):
            rate = np.sum(d * normal, axis=1)
            toward = rate < 0
            reach = np.where(toward, np.sum((point - p) * normal, axis=1) / np.where(toward, rate, 1.0), np.inf)
            closer = toward & (reach >= -1e-12) & (reach < t)
            t[closer], hit[closer] = np.maximum(reach[closer], 0.0), facet
        leaving = alive & (hit < 0)
        if bounce > 0:
            exits[bounce] = d[leaving]
        alive &= hit >= 0
        normal = np.where((hit == 0)[:, None], m, mirror)
        p = p + np.where(alive, t, 0.0)[:, None] * d
        d = d - 2.0 * np.sum(d * normal, axis=1)[:, None] * normal
    return exits


@pytest.mark.slow
def test_two_mirror_bounces_match_an_independent_brute_force():
    """Orders 1 and 2 of anisotropic mirror grooves at an incidence off both axes, against the
    exit directions of :func:`brute_force_mirror_grooves` binned on the same sensor: mean z^2 per
    cell (errors of both combined) within the two-sided bounds. Order 2 carries the specular
    caustic of geometry/vcavities.py, which the brute force shows as well."""
    theta, phi = 30.0, 40.0
    realizations, paths = 16, 1_600_000
    result = trace(vcavity_config({"kind": "mirror"}, "beckmann", (0.5, 1.0), theta=[theta], phi=[phi],
                                       paths=paths, realizations=realizations, max_order=2, cells=100, seed=4))
    sensor = result.sensor
    wi = result.plan.incidence_direction(0)
    rng = np.random.default_rng(11)
    per_batch = {1: [], 2: []}
    for _ in range(realizations):
        exits = brute_force_mirror_grooves(paths // realizations, rng, 0.5, 1.0, wi, 2)
        for order in (1, 2):
            counts = np.bincount(sensor.lookup(exits[order]), minlength=sensor.n_cells)
            per_batch[order].append(counts / (paths // realizations) / sensor.projected_solid_angle())
    for order in (1, 2):
        batches = np.array(per_batch[order])
        brute, brute_se = batches.mean(axis=0), batches.std(axis=0, ddof=1) / math.sqrt(realizations)
        sim, sim_se = result.brdf[0].mean[order - 1], result.brdf[0].stderr[order - 1]
        signal = (sim > SIGNAL * sim_se) & (brute > SIGNAL * brute_se)
        z2 = np.mean((sim[signal] - brute[signal]) ** 2 / (sim_se[signal] ** 2 + brute_se[signal] ** 2))
        n = int(signal.sum())
        assert n >= 20 and chi2_lower_bound(n, realizations) <= z2 <= chi2_bound(n, realizations), (order, n, z2)


# ---------------------------------------------------------------- orders as the paper reports them

@pytest.mark.slow  # 2 x 400 000 paths, traced twice (once by executors.trace_units)
def test_orders_1_and_2_give_f2_with_their_own_error_and_compare_reads_them(simulate, tmp_path, capsys):
    """brdf_orders12 is order 1 + order 2 (the paper's f2), with the standard error of the
    per-realization sums (the two orders are correlated, so it is not their errors in quadrature);
    ``compare --order 1+2`` judges a model against it; a table without it is refused in one line."""
    import h5py

    from microsim.cli import main

    settings = {"scene": {"kind": "vcavities", "distribution": "gaussian", "roughness": 0.6},
                "material": {"kind": "lambert", "albedo": 0.8},
                "illumination": {"theta_i_deg": [30.0, 70.0]}, "sensor": {"cells": 100},
                "run": {"paths": 400_000, "realizations": 16, "seed": 2}}
    table = simulate(settings)
    a = table.arrays
    f2 = table.brdf_order[:, 0] + table.brdf_order[:, 1]
    assert np.allclose(a["brdf_orders12"], f2, rtol=1e-12, atol=0.0)
    assert np.allclose(a["albedo_orders12"], a["albedo_order"][:, :2].sum(axis=1), rtol=1e-12)
    # the error of each realization's f2, recomputed from the units' own tallies
    plan = Plan.from_config(config.validate(settings))
    per_unit = {0: [], 1: []}
    executors.trace_units(plan, plan.units, lambda unit, tally, info: per_unit[unit[1]].append(
        (tally.estimates[0].weight[0, 0] + tally.estimates[0].weight[0, 1]) / tally.paths / table.projected_solid_angle))
    for i, estimates in per_unit.items():
        spread = np.std(estimates, axis=0, ddof=1) / math.sqrt(len(estimates))
        assert np.allclose(a["brdf_orders12_stderr"][i], spread, rtol=1e-6, atol=1e-9 * spread.max())
    quadrature = np.hypot(a["brdf_order_stderr"][:, 0], a["brdf_order_stderr"][:, 1])
    assert not np.allclose(a["brdf_orders12_stderr"], quadrature, rtol=1e-3)
    args = ["compare", str(table.path), "--model", "oren_nayar", "--param", "albedo=0.8", "--param", "roughness=0.6",
            "--order", "1+2", "--json"]
    assert main(args) == 0
    row = json.loads(capsys.readouterr().out.strip().splitlines()[-1])["per_incidence"][0]
    assert row["albedo_sim"] == pytest.approx(a["albedo_orders12"][0])
    old = tmp_path / "old.h5"
    with h5py.File(table.path, "r") as source, h5py.File(old, "w") as target:
        for key, value in source.attrs.items():
            target.attrs[key] = value
        for name in source:
            if "orders12" not in name:
                source.copy(source[name], target, name)
    args[1] = str(old)
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "has no brdf_orders12" in err[0]


# ---------------------------------------------------------------- d: reciprocity

@pytest.fixture(scope="module")
def reciprocity_table(tmp_path_factory):
    """All orders on anisotropic Lambertian grooves, incidences at ring centres x phi_i {0, 90} deg."""

    incidences = ring_incidences()
    cfg = vcavity_config({"kind": "lambert", "albedo": 0.8}, "beckmann", (0.4, 1.0),
                         theta=[t for _, t, _ in incidences], phi=[p for _, _, p in incidences],
                         paths=2_000_000, realizations=16, max_order=0, cells=RECIPROCITY_CELLS)
    return trace_table(cfg, tmp_path_factory.mktemp("vcavity_reciprocity") / "table.h5"), incidences


@pytest.mark.slow
def test_anisotropic_table_is_reciprocal(reciprocity_table):
    table, incidences = reciprocity_table
    assert np.all(table.brdf_stderr > 0)
    z = reciprocity_z(table, incidences, table.brdf, table.brdf_stderr)
    assert len(z) == 45 and z.max() <= 4.5


@pytest.mark.slow
def test_a_non_reciprocal_quantity_is_detected(reciprocity_table):
    table, incidences = reciprocity_table
    mu = np.cos(0.5 * (table.sensor.cell_bounds()[0] + table.sensor.cell_bounds()[1]))
    assert reciprocity_z(table, incidences, table.brdf * mu, table.brdf_stderr * mu).max() > 4.5


@pytest.mark.slow
def test_isotropic_table_is_reciprocal():
    incidences = ring_incidences()[::2]
    cfg = vcavity_config({"kind": "interfaced_lambert", "albedo": 0.8, "eta": 1.5}, "ggx", (0.6, 0.6),
                         theta=[t for _, t, _ in incidences], paths=1_000_000, realizations=16, max_order=0,
                         cells=RECIPROCITY_CELLS)
    result = trace(cfg)

    class Cells:  # the two arrays reciprocity_z reads, from the run's estimates
        sensor = result.sensor
    brdf = np.stack([e.mean[4] for e in result.brdf])
    stderr = np.stack([e.stderr[4] for e in result.brdf])
    assert reciprocity_z(Cells, incidences, brdf, stderr).max() <= 4.5


# ---------------------------------------------------------------- e: limits

@pytest.mark.slow
def test_nearly_flat_lambertian_grooves_are_the_lambertian_plane():
    """Every cell against albedo / pi: mean z^2 within the two-sided bounds, and the largest |z| of
    the 300 cells below the Student-t quantile that one cell exceeds with probability 1e-3 / 300."""
    from scipy.stats import t as student

    realizations = 16
    result = trace(vcavity_config({"kind": "lambert", "albedo": 0.6}, "beckmann", (0.001, 0.001),
                                       theta=[0.0, 45.0, 80.0], paths=1_000_000, realizations=realizations,
                                       max_order=0, cells=100))
    z = np.concatenate([(e.mean[4] - 0.6 / math.pi) / e.stderr[4] for e in result.brdf])
    assert chi2_lower_bound(z.size, realizations) <= np.mean(z**2) <= chi2_bound(z.size, realizations)
    assert np.max(np.abs(z)) <= student.ppf(1 - 1e-3 / (2 * z.size), realizations - 1)


def test_nearly_flat_conductor_grooves_put_all_energy_in_the_specular_cell():
    """Beckmann: facets tilted by more than the cell's half-width (about 1.5 deg) have probability
    exp(-(tan 1.5 deg / 0.001)^2), nothing. (GGX is not a limit test of this strength: its slope tail
    P(tan theta_m > s) = alpha^2 / (alpha^2 + s^2) leaves 1e-3 of the light outside that cell at
    roughness 0.001, as the table shows: 0.9512 of 0.9520 at normal incidence.)"""
    sensor = Sensor.build(CELLS)
    theta = np.degrees(sensor.ring_centres()[[0, 4, 8]])
    result = trace(vcavity_config(CONDUCTOR, "beckmann", (0.001, 0.001), theta=theta, paths=200_000,
                                       realizations=8, max_order=0))
    for i in range(3):
        wi = result.plan.incidence_direction(i)
        specular = sensor.lookup(np.array([[-wi[0], -wi[1], wi[2]]]))[0]
        albedo = result.albedo[i].mean[4]
        cell = result.brdf[i].mean[4][specular] * sensor.projected_solid_angle()[specular]
        assert cell >= (1.0 - 1e-6) * albedo
        assert abs(albedo - fresnel_array(np.array([wi[2]]), 0.2, 3.9)[0]) <= 4 * result.albedo[i].stderr[4] + 1e-6


# ---------------------------------------------------------------- the two intersectors, threads

def test_embree_and_analytic_intersectors_trace_the_same_grooves():
    """Same streams, same grooves: the Embree intersector (float32, canonical groove) finds the
    same facets as the analytic one for all but a few paths, so the tables agree far inside their
    errors and the segment counts within 1e-4."""
    from microsim.tracer import embree

    try:
        embree.load()
    except embree.EmbreeUnavailable as err:
        pytest.skip(f"the embree intersector needs the direct Embree binding: {err}")
    results = {name: trace(vcavity_config({"kind": "lambert", "albedo": 0.8}, "beckmann", (0.5, 0.5),
                                               theta=[0.0, 80.0], paths=200_000, realizations=4, max_order=0,
                                               cells=100, intersector=name))
               for name in ("analytic", "embree")}
    a, e = results["analytic"], results["embree"]
    assert a.plan.scene["intersector"] == "analytic" and e.plan.scene["intersector"] == "embree"
    assert np.all(np.abs(a.counts[:, SEGMENTS] / e.counts[:, SEGMENTS] - 1.0) <= 1e-4)
    for i in range(2):
        z = (a.brdf[i].mean[4] - e.brdf[i].mean[4]) / a.brdf[i].stderr[4]
        assert np.max(np.abs(z)) <= 0.5


def test_tallies_are_bit_identical_for_any_number_of_threads():
    cfg = vcavity_config({"kind": "lambert", "albedo": 0.8}, "ggx", (0.5, 0.5), theta=[30.0], paths=50_000,
                         realizations=2, max_order=0, cells=100)
    assert_bit_identical_for_threads(VCavityTracer, cfg, 50_000)


def test_resolved_scene_records_what_was_used():
    resolved = geometry.SCENES["vcavities"].resolve(vcavity_config(CONDUCTOR, "ggx", (0.2, 0.4)))
    assert resolved["layout"] == geometry.vcavities.LAYOUT and resolved["intersector"] == "analytic"
    assert (resolved["roughness_x"], resolved["roughness_y"]) == (0.2, 0.4) and resolved["triangles"] == 0
    assert "base" not in resolved


# ---------------------------------------------------------------- g: bad input

GROOVES = small_config('kind = "vcavities"\ndistribution = "beckmann"\nroughness = 0.5')

BAD_GROOVES = {
    "unknown distribution": (("beckmann", "phong"), "scene.distribution"),
    "zero roughness": (("roughness = 0.5", "roughness = 0.0"), "scene.roughness"),
    "negative roughness": (("roughness = 0.5", "roughness = -0.1"), "scene.roughness"),
    "roughness_x alone": (("roughness = 0.5", "roughness_x = 0.5"), "scene.roughness_y"),
    "both roughness forms": (("roughness = 0.5", "roughness = 0.5\nroughness_x = 0.5"), "scene.roughness"),
    "anisotropic gaussian": (('"beckmann"\nroughness = 0.5', '"gaussian"\nroughness_x = 0.2\nroughness_y = 0.4'),
                             "scene.roughness_x"),
    "a base under the facets": (("[illumination]", '[base]\nkind = "absorber"\n[illumination]'), "base"),
    "an albedo list of interfaced facets": (('kind = "lambert"\nalbedo = 0.8', 'kind = "interfaced_lambert"\n'
                                                                             'albedo = [0.3, 0.8]'), "material.albedo"),
    "an unknown facet material": (('kind = "lambert"', 'kind = "velvet"'), "material.kind"),
    "an unknown intersector": (("roughness = 0.5", 'roughness = 0.5\nintersector = "optix"'), "scene.intersector"),
}


@pytest.mark.parametrize("case", sorted(BAD_GROOVES))
def test_bad_grooves_give_one_line_naming_the_key_and_exit_2(case, tmp_path, capsys):
    (old, new), key = BAD_GROOVES[case]
    assert old in GROOVES
    assert_run_refused(GROOVES.replace(old, new, 1), key, tmp_path, capsys)
