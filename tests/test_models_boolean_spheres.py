"""The finite-size single-scattering model of Boolean spheres (microsim/models/boolean_spheres.py)."""

import math

import numpy as np
import pytest

from microsim import models
from microsim.frames import direction
from microsim.models.boolean_spheres import common_volume, finite_size_ratio, lit_visible_height, shadow_hiding
from microsim.models.phase import phase_lambert_sphere


def test_common_volume_of_perpendicular_rays_is_a_quarter_steinmetz_solid_outside_the_ball():
    a, b = direction(math.radians(45.0), 0.0), direction(math.radians(45.0), math.pi)
    exact = (16.0 / 3.0 - 4.0 * math.pi / 3.0) / 4.0  # (bicylinder - ball) / 4 quadrants
    assert common_volume(a, b, np.array([1e3]), 100, 200)[0] == pytest.approx(exact, rel=1e-3)


def test_common_volume_below_a_height_matches_monte_carlo():
    half = math.radians(10.0)
    a, b = direction(half, 0.0), direction(half, math.pi)
    rng = np.random.default_rng(5)
    low, high = np.array([-3.0, -1.5, -1.5]), np.array([3.0, 1.5, 12.0])
    q = rng.uniform(low, high, size=(2_000_000, 3))
    inside = np.ones(len(q), bool)
    for axis in (a, b):
        along = q @ axis
        inside &= (along >= 0) & (np.einsum("ij,ij->i", q, q) - along**2 < 1.0)
    inside &= np.einsum("ij,ij->i", q, q) > 1.0
    box = np.prod(high - low)
    heights = np.array([0.5, 2.0, 5.0, 100.0])
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
    r_over_l = -0.75 * math.log1p(-0.04)
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


def test_finite_size_excess_grows_with_volume_fraction_and_is_reciprocal():
    rng = np.random.default_rng(2)
    wi = rng.normal(size=(200, 3))
    wo = rng.normal(size=(200, 3))
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]), np.abs(wo[:, 2])
    wi /= np.linalg.norm(wi, axis=1)[:, None]
    wo /= np.linalg.norm(wo, axis=1)[:, None]
    point = 0.8 * phase_lambert_sphere(-np.einsum("ij,ij->i", wi, wo)) / (wi[:, 2] + wo[:, 2])
    previous = point
    for phi in (0.005, 0.02, 0.08):
        model = models.create("boolean_spheres_single", albedo=0.8, volume_fraction=phi)
        f = model(wi, wo)
        assert np.abs(f - model(wo, wi)).max() <= 1e-12 * f.max()
        assert np.all(f > previous)
        previous = f
