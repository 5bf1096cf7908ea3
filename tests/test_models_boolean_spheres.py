"""The finite-size single-scattering model of Boolean spheres (microsim/models/boolean_spheres.py)."""

import math

import numpy as np
import pytest
from scipy.integrate import quad

from microsim import models
from microsim.core.frames import direction
from microsim.models.boolean_spheres import common_volume, finite_size_ratio, lit_visible_height, shadow_hiding
from microsim.physics.boolean_model import number_density, radius_over_free_path


def test_common_volume_of_perpendicular_rays_is_a_quarter_steinmetz_solid_outside_the_ball():
    a, b = direction(math.radians(45.0), 0.0), direction(math.radians(45.0), math.pi)
    exact = (16.0 / 3.0 - 4.0 * math.pi / 3.0) / 4.0  # (bicylinder - ball) / 4 quadrants
    assert common_volume(a, b, np.array([1e3]), 100, 200)[0] == pytest.approx(exact, rel=1e-3)


@pytest.mark.parametrize("i, o, box_lo, box_hi", [
    ((10, 0), (10, 180), (-3.0, -1.5, -1.5), (3.0, 1.5, 12.0)),   # symmetric, 20 deg apart
    ((20, 0), (50, 90), (-3.5, -3.5, -1.5), (3.5, 3.5, 5.0)),     # tilted frame: e1_z, e2_z != 0
])
def test_common_volume_below_a_height_matches_monte_carlo(i, o, box_lo, box_hi):
    a = direction(math.radians(i[0]), math.radians(i[1]))
    b = direction(math.radians(o[0]), math.radians(o[1]))
    rng = np.random.default_rng(5)
    low, high = np.array(box_lo), np.array(box_hi)
    q = rng.uniform(low, high, size=(2_000_000, 3))
    inside = np.ones(len(q), bool)
    for axis in (a, b):
        along = q @ axis
        inside &= (along >= 0) & (np.einsum("ij,ij->i", q, q) - along**2 < 1.0)
    inside &= np.einsum("ij,ij->i", q, q) > 1.0
    assert not np.any(inside & np.any((np.abs(q - low) < 0.05) | (np.abs(q - high) < 0.05), axis=1))  # box holds it
    box = np.prod(high - low)
    heights = np.array([0.3, 1.0, 2.0, 100.0])
    quadrature = common_volume(a, b, heights, 100, 200)
    for h, value in zip(heights, quadrature):
        p = np.mean(inside & (q[:, 2] < h))
        stderr = box * math.sqrt(p * (1 - p) / len(q))
        assert abs(value - box * p) < 4 * stderr + 1e-3 * value


@pytest.mark.parametrize("i, o", [((0, 0), (0, 0)), ((0, 0), (2, 0)), ((30, 0), (40, 0)), ((60, 0), (85, 180)),
                                  ((80, 0), (85, 0)), ((45, 0), (60, 90))])
def test_shadow_hiding_default_nodes_are_converged(i, o):
    """The model's quadrature (16 x 24 nodes, 64 depths) against a 4x finer one: within 2e-4 of I
    from retro to the grazing hot spot, where the tables' standard errors are >= 5e-3 relative."""
    a = direction(math.radians(i[0]), math.radians(i[1]))
    b = direction(math.radians(o[0]), math.radians(o[1]))
    r_over_l = radius_over_free_path(0.04)
    assert shadow_hiding(a, b, r_over_l) == pytest.approx(shadow_hiding(a, b, r_over_l, 96, 128, 192), abs=2e-4)


@pytest.mark.parametrize("i, o", [((0, 0), (0, 0)), ((0, 0), (60, 90)), ((40, 0), (70, 180)), ((75, 0), (30, 40))])
def test_lit_visible_height_closed_form_matches_a_sphere_quadrature(i, o):
    a = direction(math.radians(i[0]), math.radians(i[1]))
    b = direction(math.radians(o[0]), math.radians(o[1]))
    n = 400_000  # Fibonacci sphere
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    ring = np.sqrt(1 - z * z)
    angle = math.pi * (1 + 5**0.5) * k
    m = np.stack([ring * np.cos(angle), ring * np.sin(angle), z], axis=1)
    weight = np.clip(m @ a, 0, None) * np.clip(m @ b, 0, None)
    assert lit_visible_height(a, b) == pytest.approx(np.sum(weight * m[:, 2]) / np.sum(weight), abs=2e-4)


def test_dilute_limit_is_radiative_transfer_and_retro_doubles():
    wi = direction(math.radians(30.0), 0.0)[None, :]
    away = direction(np.radians([0.0, 45.0, 70.0]), np.radians([0.0, 90.0, 180.0]))
    assert np.allclose(finite_size_ratio(np.repeat(wi, 3, 0), away, 1e-7), 1.0, atol=1e-5)
    assert finite_size_ratio(wi, wi.copy(), 1e-7)[0] == pytest.approx(2.0, abs=1e-5)


def test_normal_retro_matches_the_closed_form_and_grazing_retro_stays_below_the_doubling():
    """At normal retro the two cylinders coincide: V(h) = ball + half-cylinder below the top,
    pi h^3 / 3 for h < 1 and pi h - 2 pi / 3 below, so I = 2 r/l int exp(-n V) dh by quad."""
    r_over_l = radius_over_free_path(0.02)
    n = number_density(0.02)

    def volume(h):
        ball = 4 * math.pi / 3 if h >= 1 else 2 * math.pi / 3 + math.pi * (h - h**3 / 3)
        return ball + (math.pi * h**3 / 3 if h < 1 else math.pi * h - 2 * math.pi / 3)

    exact = 2 * r_over_l * (quad(lambda h: math.exp(-n * volume(h)), 0, 1)[0]
                            + quad(lambda h: math.exp(-n * volume(h)), 1, np.inf)[0])
    up = direction(0.0, 0.0)
    assert shadow_hiding(up, up.copy(), r_over_l) == pytest.approx(exact, abs=2e-4)
    for theta in (60.0, 85.0, 89.5):
        a = direction(math.radians(theta), 0.0)
        assert shadow_hiding(a, a.copy(), r_over_l) <= 2.0


@pytest.mark.parametrize("phi", [0.005, 0.02, 0.08])
def test_model_is_reciprocal(phi):
    rng = np.random.default_rng(2)
    wi = rng.normal(size=(200, 3))
    wo = rng.normal(size=(200, 3))
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]), np.abs(wo[:, 2])
    wi /= np.linalg.norm(wi, axis=1)[:, None]
    wo /= np.linalg.norm(wo, axis=1)[:, None]
    model = models.create("boolean_spheres_single", albedo=0.8, volume_fraction=phi)
    f = model(wi, wo)
    assert np.abs(f - model(wo, wi)).max() <= 1e-12 * f.max()
