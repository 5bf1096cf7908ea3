"""The visibility query of every transport (microsim.tracer.integrators.walk.VISIBILITY), against an
independent computation: exp(-tau) in the medium, the groove's aperture in the cross-section, and
rays against every periodic image of every sphere in numpy."""

import math

import numba
import numpy as np

from microsim import config
from microsim.physics.rng import geometry_rng
from microsim.run.plan import Plan
from microsim.tracer import embree
from microsim.tracer.estimators import DEFAULT, build
from microsim.tracer.integrators.direct import DirectWorld
from microsim.tracer.integrators.medium import Medium
from microsim.tracer.integrators.scheduler import workspace
from microsim.tracer.integrators.vcavity import (
    CANONICAL_FACES,
    CANONICAL_VERTICES,
    LEFT,
    RIGHT,
    EmbreeGrooveWorld,
    Grooves,
    GrooveWorld,
)
from microsim.tracer.integrators.walk import visibility
from microsim.tracer.sensor import Sensor


@numba.njit
def visible(world, work, state, wo):
    return visibility(world, work, 0, state, wo)


def upward(rng, n=None, min_z=0.05):
    """A unit direction with z > min_z (and above the plane of normal n, if given)."""
    while True:
        wo = rng.normal(size=3)
        wo /= np.linalg.norm(wo)
        if wo[2] > min_z and (n is None or wo @ n > 0):
            return wo


def work():
    return workspace(1, build(DEFAULT, Sensor.build(10)))


def test_the_medium_transmits_exp_minus_its_optical_path():
    rng = np.random.default_rng(1)
    for _ in range(200):
        z, wo = -3.0 * rng.random(), upward(rng)
        assert visible(Medium(0, 0.5), work(), z, tuple(wo)) == math.exp(z / wo[2])
    assert visible(Medium(0, 0.5), work(), -1.0, (0.6, 0.0, -0.8)) == 0.0


def test_a_groove_sees_out_exactly_where_its_aperture_is_in_the_way():
    """From a point of a facet, a direction is visible iff the line reaches z = 0 within the
    aperture x in [-1, 1] (the groove is convex), with the analytic and the Embree intersector."""
    rng = np.random.default_rng(2)
    grooves = Grooves(0, 0.5, 0.5, 0, np.zeros(3))
    canonical = embree.Scene(CANONICAL_VERTICES, CANONICAL_FACES)  # kept: the world holds its handle only
    worlds = [GrooveWorld(grooves), EmbreeGrooveWorld(grooves, canonical.arrays())]
    counts = {True: 0, False: 0}
    for _ in range(600):
        h, azimuth = 3.0 * rng.random() + 0.05, 2 * math.pi * rng.random()
        cu, su = math.cos(azimuth), math.sin(azimuth)
        cos_m = 1 / math.sqrt(1 + h * h)
        sin_m = h * cos_m
        facet = LEFT if rng.random() < 0.5 else RIGHT
        x = -rng.random() if facet == LEFT else rng.random()
        z = -h * (x + 1) if facet == LEFT else -h * (1 - x)
        side = 1.0 if facet == LEFT else -1.0
        n = np.array([side * sin_m * cu, side * sin_m * su, cos_m])
        wo = upward(rng, n)
        du = wo[0] * cu + wo[1] * su
        top = x + (-z / wo[2]) * du
        if abs(abs(top) - 1.0) < 1e-9:
            continue
        expected = float(abs(top) <= 1.0)
        counts[bool(expected)] += 1
        state = ((x, z), facet, tuple(n), (cu, su, h, cos_m, sin_m))
        for world in worlds:
            assert visible(world, work(), state, tuple(wo)) == expected, (h, x, facet, wo)
    assert min(counts.values()) > 100  # both answers are tested


def sphere_scene():
    cfg = config.validate({
        "scene": {"kind": "poisson_spheres", "volume_fraction": 0.3, "tile": 8.0, "depth": 4.0},
        "material": {"kind": "lambert", "albedo": 0.5}, "illumination": {"theta_i_deg": [0.0]},
        "sensor": {"cells": 10}, "run": {"paths": 100, "realizations": 2, "seed": 4}})
    plan = Plan.from_config(cfg)
    return plan.generator.generate(plan.scene, plan.config, geometry_rng(4, 0))


def blocked_by_spheres(p, wo, spheres, tile, z_top):
    """(blocked, margin): whether the ray p + t wo, 0 < t, up to z_top, meets a periodic image of a
    sphere (p on a sphere's surface, wo leaving it: its own sphere ends at t = 0, within
    rounding); margin: the smallest |distance from the line to a centre - r| / r over the images it
    passes near (a ray that grazes a sphere is not judged)."""
    length = (z_top - p[2]) / wo[2]
    end = p + length * wo
    centres, radii = spheres[:, :3].astype(np.float64), spheres[:, 3].astype(np.float64)
    blocked, margin = False, np.inf
    ranges = [range(int(math.floor((min(p[k], end[k]) - radii.max() - tile) / tile)),
                    int(math.ceil((max(p[k], end[k]) + radii.max()) / tile)) + 1) for k in (0, 1)]
    for kx in ranges[0]:
        for ky in ranges[1]:
            c = centres + np.array([kx * tile, ky * tile, 0.0])
            along = (c - p) @ wo
            closest = np.linalg.norm(c - p - along[:, None] * wo, axis=1)
            near = (along > -radii) & (along < length + radii)
            gap = np.abs(closest - radii) / radii
            margin = min(margin, gap[near & (gap < 1.0)].min(initial=np.inf))
            half = np.sqrt(np.maximum(radii**2 - closest**2, 0.0))
            hit = (closest < radii) & (along + half > 1e-9) & (along - half < length)
            blocked |= bool(np.any(hit))
    return blocked, margin


def inside_another(p, k, spheres, tile):
    """Whether p (on sphere k) is inside another sphere or image of one: not on the surface of
    the union (the spheres of a Boolean model overlap), where no path interacts."""
    shifts = np.array([[kx * tile, ky * tile, 0.0] for kx in (-1, 0, 1) for ky in (-1, 0, 1)])
    centres = spheres[None, :, :3].astype(np.float64) + shifts[:, None, :]
    inside = np.linalg.norm(centres - p, axis=2) < spheres[None, :, 3] * (1.0 + 1e-4)
    inside[4, k] = False  # its own sphere (shift 0)
    return bool(inside.any())


def test_a_surface_point_sees_out_unless_a_periodic_image_of_a_sphere_is_in_the_way():
    """Native spheres: the occluded queries through the wrapped tile against the line met with
    every image of every sphere (the own sphere: only where the ray leaves it, t = 0)."""
    scene = sphere_scene()
    committed = embree.Scene(scene.vertices, scene.faces, scene.spheres, sphere_scale=scene.sphere_scale)
    world = DirectWorld(scene.arrays(), committed.arrays())
    rng = np.random.default_rng(5)
    counts, judged = {True: 0, False: 0}, 0
    for _ in range(4000):
        k = rng.integers(len(scene.spheres))
        centre, radius = scene.spheres[k, :3].astype(np.float64), float(scene.spheres[k, 3])
        n = upward(rng, min_z=-0.9)
        p = centre + radius * n
        wo = upward(rng, n, min_z=0.2)
        blocked, margin = blocked_by_spheres(p, wo, scene.spheres, scene.tile, scene.z_top)
        if margin < 1e-4 or inside_another(p, k, scene.spheres, scene.tile):
            continue
        judged += 1
        counts[blocked] += 1
        state = (tuple(p), tuple(n), int(scene.sphere_shape[k]))
        assert visible(world, work(), state, tuple(wo)) == float(not blocked), (k, p, wo)
    assert judged > 800 and min(counts.values()) > 200, counts
