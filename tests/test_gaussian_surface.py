"""Random Gaussian heightfields (geometry/gaussian_surface.py, scene heightfield with
generator = "gaussian") and the statistics measured on them (geometry/surface_statistics.py).

What is checked, and against what:

* The facets' slopes are Beckmann's with the requested alpha (their NDF): the slopes of each
  realization's facets, divided by alpha_x / sqrt(2) and alpha_y / sqrt(2), are standard normal
  pairs if they are. Two sets of bins, each with exact probabilities: 8 rings of r^2 = s_x^2 +
  s_y^2 (chi-square with 2 degrees of freedom: P(r^2 < q) = 1 - exp(-q / 2)) and 8 sectors of
  their angle (1/8 each). A realization's shares of facets in the bins are its estimate (every
  facet of a heightfield has the same projected area); their deviations from the exact shares
  over REALIZATIONS realizations are judged by Hotelling's T^2 with the covariance of the
  realizations (the shares of one realization are correlated: they sum to 1, and a realization
  rougher than the mean moves every ring), F(k, R - k), two-sided 99.9 % bounds. One bin of each
  set is left out (the shares sum to 1). An isotropic and an anisotropic surface.
* The shadow rays: on any surface over the tile every line from a direction wo meets the
  surface once, so the visible share of the projected area facing wo is exactly cos(theta_o)
  times the tile's area over that projected area (surface_statistics module doc). Each
  realization's G1 is a binomial count of shadow rays with that probability: z of the pooled
  count against it, per direction, up to 85 deg.
* Bad input is refused in one line naming the key.
"""

import math

import h5py
import numpy as np
import pytest
from scipy import stats

from microsim import config, geometry
from microsim.geometry import gaussian_surface, heightfield
from microsim.physics.rng import geometry_rng
from microsim.run.plan import Plan
from microsim.testing import trace
from microsim.testing.refusals import assert_run_refused
from microsim.tracer.sensor import Sensor

REALIZATIONS = 48
BOUNDS = (0.0005, 0.9995)  # two-sided 99.9 %


def gaussian(**scene):
    return config.validate({"scene": {"kind": "heightfield", "generator": "gaussian", **scene},
                            "material": {"kind": "mirror"}, "illumination": {"theta_i_deg": [0.0]},
                            "sensor": {"cells": 100}, "run": {"paths": 1000}})


def tiles(cfg, count=REALIZATIONS, seed=5):
    """``count`` realizations' tiles of a generated heightfield config, and its resolution."""
    resolved = heightfield.resolve(cfg)
    for r in range(count):
        yield heightfield.realize(resolved, geometry_rng(seed, r)), resolved


def standardized_slopes(tile, alpha_x, alpha_y):
    """The facets' slopes over alpha / sqrt(2) on each axis: standard normal pairs on a Beckmann
    surface of roughness alpha_x x alpha_y."""
    return -tile.normals[:, :2] / tile.normals[:, 2:3] / (np.array([alpha_x, alpha_y]) / math.sqrt(2.0))


def moments(tile, alpha_x, alpha_y):
    """Mean s_x^2 - 1, s_y^2 - 1 and s_x s_y of the standardized slopes (0 on a Beckmann surface)."""
    s = standardized_slopes(tile, alpha_x, alpha_y)
    return np.array([np.mean(s[:, 0] ** 2) - 1.0, np.mean(s[:, 1] ** 2) - 1.0, np.mean(s[:, 0] * s[:, 1])])


def bin_shares(tile, alpha_x, alpha_y):
    """Shares of the facets in 8 rings of r^2 and 8 sectors of the standardized slopes, and the
    exact shares of a Beckmann surface."""
    slopes = standardized_slopes(tile, alpha_x, alpha_y)
    r2 = np.sum(slopes**2, axis=1)
    edges = -2.0 * np.log(1.0 - np.arange(1, 8) / 8)  # 8 rings of probability 1/8 each
    rings = np.bincount(np.searchsorted(edges, r2), minlength=8) / len(r2)
    sectors = np.bincount(((np.arctan2(slopes[:, 1], slopes[:, 0]) + math.pi) / (math.pi / 4)).astype(int) % 8,
                          minlength=8) / len(r2)
    return np.concatenate([rings[:-1], sectors[:-1]]), np.full(14, 1 / 8)


def hotelling(deviations):
    """T^2 of the mean of ``deviations`` (R, k) being 0, as F(k, R - k), and its two-sided bounds."""
    r, k = deviations.shape
    mean = deviations.mean(axis=0)
    covariance = np.cov(deviations, rowvar=False) / r
    t2 = float(mean @ np.linalg.solve(covariance, mean))
    f = t2 * (r - k) / (k * (r - 1))
    return f, stats.f.ppf(BOUNDS, k, r - k)


@pytest.mark.parametrize("alpha_x, alpha_y, pixel", [(0.8, 0.8, 0.125), (0.3, 0.6, 0.125), (0.8, 0.8, 0.5)])
def test_the_facets_slopes_are_beckmann_with_the_requested_alpha(alpha_x, alpha_y, pixel):
    """The scale (second moments of the slopes) and the shape (bins) of the NDF, each by Hotelling's
    T^2; at the default grid and at 2 samples a correlation length, where the grid's slopes would
    have 11.5 % less variance than the continuous field's (the field parameters make up for it)."""
    cfg = gaussian(roughness_x=alpha_x, roughness_y=alpha_y, tile=16.0, pixel=pixel)
    realized = list(tiles(cfg))
    for name, statistic in (("moments", moments), ("bins", lambda *a: np.subtract(*bin_shares(*a)))):
        f, (low, high) = hotelling(np.array([statistic(tile, alpha_x, alpha_y) for tile, _ in realized]))
        print(f"alpha {alpha_x} x {alpha_y}, pixel {pixel}, {name}: F = {f:.3f} in ({low:.3f}, {high:.3f})")
        assert low < f < high


@pytest.mark.parametrize("statistic, off", [(moments, 1.05), (lambda *a: np.subtract(*bin_shares(*a)), 1.1)])
def test_a_wrong_alpha_is_seen(statistic, off):
    """Power: the moments reject an alpha 5 % off, the bins one 10 % off."""
    cfg = gaussian(roughness=0.8, tile=16.0)
    f, (low, high) = hotelling(np.array([statistic(tile, 0.8 * off, 0.8 * off) for tile, _ in tiles(cfg)]))
    print(f"alpha {off} x: F = {f:.3f}, bounds ({low:.3f}, {high:.3f})")
    assert f > high


@pytest.mark.parametrize("alpha_x, alpha_y, pixel", [(0.8, 0.8, 0.125), (0.3, 0.9, 0.25), (1.0, 0.1, 0.25)])
def test_the_grids_covariance_gives_the_facets_the_requested_slopes(alpha_x, alpha_y, pixel):
    """Exactly, from the covariance the heights are drawn with (the inverse DFT of
    gaussian_surface.spectrum, 8 correlation lengths a side, where the periodic images are
    exp(-49) away at a lag of a correlation length): the facets' slope variance along x
    and y is alpha^2 / 2, C falls as exp(-(k pixel / l)^2) along each axis with sqrt(lx ly) the
    correlation length, and a facet's slopes along x and y have the covariance
    -+sigma^2 (1 - q_x)(1 - q_y) / pixel^2 (q = exp(-pixel^2 / l^2)) on the even and odd
    diagonal splits of heightfield.triangulate."""
    field = gaussian_surface.field_parameters(alpha_x, alpha_y, 1.0, pixel)
    sigma, lx, ly = field["sigma"], field["correlation_x"], field["correlation_y"]
    n = math.ceil(8 * max(lx, ly) / pixel)
    c = np.fft.ifft2(gaussian_surface.spectrum(n, pixel, sigma, lx, ly)).real  # c[i, j] = Cov(h(0, 0), h(i, j))
    assert 2 * (c[0, 0] - c[1, 0]) / pixel**2 == pytest.approx(alpha_x**2 / 2, rel=1e-9)
    assert 2 * (c[0, 0] - c[0, 1]) / pixel**2 == pytest.approx(alpha_y**2 / 2, rel=1e-9)
    assert c[0, 0] == pytest.approx(sigma**2, rel=1e-9)
    for k in (1, 2, 3):
        assert c[k, 0] / c[0, 0] == pytest.approx(math.exp(-((k * pixel / lx) ** 2)), rel=1e-9, abs=1e-12)
        assert c[0, k] / c[0, 0] == pytest.approx(math.exp(-((k * pixel / ly) ** 2)), rel=1e-9, abs=1e-12)
    assert math.sqrt(lx * ly) == pytest.approx(1.0, rel=1e-12)
    q_x, q_y = math.exp(-((pixel / lx) ** 2)), math.exp(-((pixel / ly) ** 2))
    coupled = sigma**2 * (1 - q_x) * (1 - q_y)
    even = c[0, 1] - c[0, 0] - c[1, 1] + c[1, 0]  # (h10 - h00)(h11 - h10): the split (i, j)-(i+1, j+1)
    odd = c[1, 1] - c[1, 0] - c[0, 1] + c[0, 0]  # (h10 - h00)(h01 - h00): the split (i+1, j)-(i, j+1)
    assert even == pytest.approx(-coupled, rel=1e-9) and odd == pytest.approx(coupled, rel=1e-9)


@pytest.mark.parametrize("roughness", [0.3, 1.0])
def test_shadow_rays_see_exactly_the_projected_area_of_the_tile(roughness):
    """Per masking direction (0 to 85 deg), the pooled count of shadow rays that leave over 8
    realizations against the exact share cos(theta_o) / facing_area of each: binomial z, |z| < 4
    (10 z, P(any |z| > 4) = 6e-4). And the statistics' normalisation, exactly, per realization:
    sum(ndf dOmega) is the facets' area per tile area (all face up); sum(vndf cos(theta_o)
    dOmega) = g1 facing_area; the rays binned by cell add up to g1."""
    cfg = gaussian(roughness=roughness, tile=6.0, statistics=True, statistics_rays=2000)
    generator = geometry.SCENES["heightfield"]
    resolved = generator.resolve(cfg)
    rays, directions = resolved["statistics_rays"], resolved["statistics_directions_deg"]
    free, expected, variance = (np.zeros(len(directions)) for _ in range(3))
    solid_angle = Sensor.build(cfg.sensor.cells).solid_angle()
    for r in range(8):
        info = generator.generate(resolved, cfg, geometry_rng(9, r)).info
        share = np.cos(np.radians([theta for theta, _ in directions])) / info["facing_area"]
        free += info["g1"] * rays
        expected += share * rays
        variance += share * (1 - share) * rays
        assert np.sum(info["ndf"] * solid_angle) == pytest.approx(info["area"] / resolved["period"] ** 2, rel=1e-12)
        cosines = np.cos(np.radians([theta for theta, _ in directions]))
        assert np.allclose(info["vndf"] @ solid_angle * cosines, info["g1"] * info["facing_area"], rtol=1e-12)
        assert np.array_equal(info["g1_free"].sum(axis=1), info["g1"] * rays)
        assert np.all(info["g1_rays"].sum(axis=1) == rays)
    z = np.divide(free - expected, np.sqrt(variance), out=np.zeros_like(free), where=variance > 0)
    print(f"roughness {roughness}: z = {np.round(z, 2)}")
    assert np.all(np.abs(z) < 4.0) and np.all(free[variance == 0] == expected[variance == 0])


BAD = [
    ('generator = "gaussian"\nroughness = 0.5\ncorrelation_length = 0.5\npixel = 1.0', "scene.correlation_length",
     "below scene.pixel"),
    ('generator = "gaussian"\nroughness = 0.5\ntile = 2.0', "scene.tile", "accepted: tile >= 4"),
    ('generator = "gaussian"\nroughness = 0.5\nroughness_x = 0.5\nroughness_y = 0.4', "scene.roughness", "give one of"),
    ('generator = "gaussian"\nroughness_x = 0.5', "scene.roughness", "give one of"),
    ('generator = "gaussian"', "scene.roughness", "give one of"),
    ('generator = "gaussian"\nroughness = 0.5\nheight_scale = 2.0', "scene.height_scale", "height file only"),
    ('path = "h.npy"\nroughness = 0.5', "scene.roughness", "generator"),
    ('path = "h.npy"\ngenerator = "gaussian"\nroughness = 0.5', "scene.path", "not both"),
    ('generator = "gaussian"\nroughness = 0.5\npixel = 0.001\ntile = 8.0', "scene.tile", "accepted: 2 to 4096"),
    ('generator = "gaussian"\nroughness_x = 1.0\nroughness_y = 0.1\npixel = 1.0', "scene.pixel", "accepted: pixel below"),
    ('generator = "gaussian"\nroughness = 0.5\ncorrelation_length = 1e-8', "scene.correlation_length", "below 1e-06"),
    ('generator = "gaussian"\nroughness = 0.5\npixel = 0.001', "scene.pixel", "default tile of 1024 samples"),
    ('generator = "gaussian"\nroughness = 0.5\nstatistics_rays = 100', "scene.statistics_rays", "only with statistics"),
]


@pytest.mark.parametrize("keys, key, message", BAD)
def test_bad_gaussian_surfaces_are_refused_in_one_line(keys, key, message, tmp_path, capsys):
    text = (f'[scene]\nkind = "heightfield"\n{keys}\n[material]\nkind = "mirror"\n'
            '[illumination]\ntheta_i_deg = [0.0]\n[run]\npaths = 1000\n')
    assert_run_refused(text, key, tmp_path, capsys, message)


def test_a_resumed_run_keeps_every_realizations_statistics_bit_for_bit(tmp_path, capsys):
    """The realizations' arrays (scene/ndf, vndf, g1) pass through the unit store's JSON: a run
    resumed from kept units writes the table a fresh run writes."""
    from microsim.cli import main
    from microsim.run import unit_store
    from microsim.testing.tables import same_table

    path = tmp_path / "run.toml"
    path.write_text('[scene]\nkind = "heightfield"\ngenerator = "gaussian"\nroughness = 0.5\ntile = 4.0\n'
                    'statistics = true\nstatistics_rays = 64\n[material]\nkind = "mirror"\n'
                    '[illumination]\ntheta_i_deg = [0.0, 60.0]\n[sensor]\ncells = 50\n'
                    '[run]\npaths = 4000\nrealizations = 4\n')
    out, fresh = tmp_path / "kept.h5", tmp_path / "fresh.h5"
    plan = Plan.from_config(config.load(path))
    store = unit_store.UnitStore.open(unit_store.store_path(out), plan, resume=False)
    trace(config.load(path), store=store)  # every unit kept, no table
    store.release()
    assert main(["run", str(path), "--out", str(out), "--resume"]) == 0
    assert main(["run", str(path), "--out", str(fresh)]) == 0
    assert same_table(out, fresh)
    with h5py.File(out) as table:
        assert table["scene/vndf"].shape == (4, 5, 50) and table["scene/g1_rays"].shape == (4, 5, 50)


@pytest.mark.parametrize("scene", [
    {"generator": "gaussian", "roughness": 0.5},
    {"generator": "gaussian", "roughness_x": 0.3, "roughness_y": 0.6, "correlation_length": 2.0, "statistics": True},
    {"path": "HEIGHTS"},
    {"path": "HEIGHTS", "height_scale": 2.0, "pixel": 0.5},
])
def test_a_tables_config_reads_back_as_the_same_config(scene, tmp_path):
    """The config a table stores (tables.config_to_toml: every default written out, None left
    out) is accepted again and is the same config: keys of one source only are never written for
    the other."""
    import tomllib

    from microsim.tables import config_to_toml

    heights = tmp_path / "h.npy"
    np.save(heights, np.zeros((4, 4)))
    scene = {key: (str(heights) if value == "HEIGHTS" else value) for key, value in scene.items()}
    cfg = config.validate({"scene": {"kind": "heightfield", **scene}, "material": {"kind": "mirror"},
                           "illumination": {"theta_i_deg": [0.0]}, "run": {"paths": 1000}})
    assert config.validate(tomllib.loads(config_to_toml(cfg))) == cfg
