"""Retro rings (``[sensor] retro_rings``): the fine tally about the retro direction that resolves
the opposition peak (microsim/tracer/estimators/retro_rings.py). Checked against exact BRDFs, on rings that the horizon
cuts as well as whole ones, and shown not to disturb the ordinary tables."""

import math

import numpy as np
import pytest

from microsim import config, tables
from microsim.core.orders import ORDERS
from microsim.models.radiative_transfer import single_scattering
from microsim.testing import trace
from microsim.testing.bounds import chi2_bound, chi2_lower_bound
from microsim.testing.refusals import assert_run_refused, small_config
from microsim.tracer.estimators.retro_rings import RetroRings
from microsim.tracer.sensor_kernels import retro_ring

REALIZATIONS = 32


def run(scene, theta, phi, rings, max_deg, paths, seed=5, albedo=0.6, cells=100):
    cfg = config.validate({
        "scene": scene, "material": {"kind": "lambert", "albedo": albedo},
        "illumination": {"theta_i_deg": theta, "phi_i_deg": phi},
        "sensor": {"cells": cells, "retro_rings": rings, "retro_max_deg": max_deg},
        "run": {"paths": paths, "realizations": REALIZATIONS, "seed": seed},
    })
    return cfg, trace(cfg, threads=2)


def assert_consistent(mean_z2, n):
    assert chi2_lower_bound(n, REALIZATIONS) < mean_z2 < chi2_bound(n, REALIZATIONS), (mean_z2, n)


def test_projected_solid_angle_of_rings_cut_by_the_horizon_matches_monte_carlo():
    rings = RetroRings.reaching(6, 24.0)
    wi = np.array([math.sin(math.radians(84.0)), 0.0, math.cos(math.radians(84.0))])
    exact = rings.projected_solid_angle(wi)
    lo, hi = rings.phase_bounds()
    uncut = math.pi * wi[2] * (np.cos(lo) ** 2 - np.cos(hi) ** 2)
    assert exact[0] == pytest.approx(uncut[0], rel=1e-12)  # ring 0 (gamma < 4 deg) stays above the horizon
    assert np.all(exact[2:] > uncut[2:] * 1.05)  # rings 2-5 reach 6 deg and more below it
    rng = np.random.default_rng(2)
    n = 4_000_000
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    ring = (np.linalg.norm(v - wi, axis=1) / rings.step).astype(int)
    ok = (ring < 6) & (v[:, 2] > 0)
    weights = v[ok, 2] * 4 * math.pi / n
    estimate = np.bincount(ring[ok], weights=weights, minlength=6)
    stderr = np.sqrt(np.bincount(ring[ok], weights=weights**2, minlength=6))
    assert np.all(np.abs(estimate - exact) < 4 * stderr)


@pytest.mark.parametrize("theta, phi", [(0.0, 0.0), (80.0, 30.0)])
@pytest.mark.slow
def test_lambertian_plane_is_albedo_over_pi_on_every_ring(theta, phi):
    _, result = run({"kind": "plane"}, [theta], [phi], rings=12, max_deg=30.0, paths=1_000_000)
    retro = result.estimates["brdf_retro"][0]
    z = (retro.mean[ORDERS] - 0.6 / math.pi) / retro.stderr[ORDERS]
    assert_consistent(np.mean(z * z), len(z))


@pytest.mark.slow
def test_medium_order_one_is_single_scattering_averaged_over_each_ring():
    """The Lambert-sphere phase function varies across the rings (it peaks backwards), so this
    checks the ring geometry and the cos(theta_o) weighting, whole rings and cut ones."""
    scene = {"kind": "halfspace_medium", "phase": "lambert_sphere"}
    _, result = run(scene, [0.0, 75.0], [0.0, 0.0], rings=10, max_deg=25.0, paths=1_000_000, albedo=0.8)
    for i in range(2):
        wi = result.plan.incidence_direction(i)
        w, weight = RetroRings.reaching(10, 25.0).quadrature(wi)
        expected = np.sum(weight * single_scattering(np.broadcast_to(wi, w.shape), w, 0.8), axis=1)
        retro = result.estimates["brdf_retro"][i]
        z = (retro.mean[0] - expected) / retro.stderr[0]
        assert_consistent(np.mean(z * z), len(z))


def test_rings_leave_the_ordinary_table_bit_identical(tmp_path):
    scene = {"kind": "poisson_spheres", "volume_fraction": 0.3}
    cfg_plain, plain = run(scene, [0.0, 60.0], [0.0, 0.0], rings=0, max_deg=10.0, paths=20_000)
    cfg_rings, rings = run(scene, [0.0, 60.0], [0.0, 0.0], rings=40, max_deg=10.0, paths=20_000)
    for a, b in zip(plain.brdf + plain.albedo + plain.energy, rings.brdf + rings.albedo + rings.energy):
        assert np.array_equal(a.mean, b.mean) and np.array_equal(a.stderr, b.stderr)
    assert "brdf_retro" not in plain.estimates and len(rings.estimates["brdf_retro"]) == 2
    assert rings.estimates["brdf_retro"][0].mean[ORDERS].sum() > 0
    table = tables.load(tables.write(tmp_path / "rings.h5", rings, cfg_rings))
    assert table.arrays["brdf_retro"].shape == (2, 40)
    assert table.arrays["brdf_retro_order"].shape == (2, 4, 40)
    assert table.arrays["sensor/retro_projected_solid_angle"].shape == (2, 40)
    assert np.array_equal(table.brdf, tables.load(tables.write(tmp_path / "plain.h5", plain, cfg_plain)).brdf)


@pytest.mark.parametrize("line, key", [("retro_rings = -1", "sensor.retro_rings"),
                                       ("retro_max_deg = 95.0", "sensor.retro_max_deg")])
def test_bad_retro_keys_are_refused(line, key, tmp_path, capsys):
    text = small_config('kind = "plane"').replace("cells = 100", f"cells = 100\n{line}")
    assert_run_refused(text, key, tmp_path, capsys)


def test_float32_exit_directions_near_retro_land_in_their_ring():
    """Exit directions come from float32 rays (length off 1 by ~1e-7): the ring of a direction
    must come from its chord to wi, not from 1 - d.wi, whose error would be a chord error of
    sqrt(2e-7) = 0.03 deg, more than a ring of 0.005 deg (ring 0 then took 2.4 times its share)."""
    rings = RetroRings.reaching(100, 0.5)
    wi = np.array([math.sin(0.7), 0.0, math.cos(0.7)])
    lo, hi = rings.phase_bounds()
    rng = np.random.default_rng(4)
    ring = rng.integers(0, 100, 20_000)
    gamma = lo[ring] + (hi[ring] - lo[ring]) * rng.uniform(0.05, 0.95, ring.size)
    psi = rng.uniform(0.0, 2.0 * math.pi, ring.size)
    u, v = np.array([-math.cos(0.7), 0.0, math.sin(0.7)]), np.array([0.0, 1.0, 0.0])
    d = (np.cos(gamma)[:, None] * wi + np.sin(gamma)[:, None] * (np.cos(psi)[:, None] * u + np.sin(psi)[:, None] * v))
    d = d.astype(np.float32).astype(np.float64)  # as the tracer reads an exit back
    about = rings.about(wi)
    found = np.array([retro_ring((x[0], x[1], x[2]), about) for x in d])
    assert np.mean(found == ring) > 0.999
