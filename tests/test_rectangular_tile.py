"""A rectangular periodic tile, [0, L_x) x [0, L_y): the surface tracer wraps x by L_x
and y by L_y, at every place it folds a point or meets a side.

- Exact, the kernels alone: a straight ray through an empty 4 x 1 tile meets the sides in the
  order and at the places of the unfolded line, wrapping in x and y; points just past each side
  fold back by that side's period; a ray at a corner continues from the opposite side, the other
  coordinate folded by its own period.
- A white Lambertian closed surface on a 4 x 1 tile (a ridge along y, tall steep walls) returns
  every path on both backends: a kernel that took L_x for y would start or send paths where the
  tile has no surface, and they would leave through the bottom.
- The same ridge on the 4 x 1 tile and on the 4 x 4 tile (the surface is invariant in y) gives
  the same albedos by order and next-event points to a quarter of a standard error (measured:
  0.015): the paths are the same but for float32 round-off in y, which turns a few of them. A
  kernel that drew x over L_y started every path on a quarter of the ridge's period: 12
  standard errors apart on order 1 (measured).

Swapping L_x and L_y in any one place of the kernels (start_path, prepare_segment, wrap_side,
wrap_point) fails at least one of these tests.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from microsim.core.orders import ORDERS
from microsim.core.tally import TRANSMITTED, TRUNCATED
from microsim.physics.rng import stream_key
from microsim.tracer.estimators import build
from microsim.tracer.estimators.points import Points, PointsKeys
from microsim.tracer.integrators.records import allocate_rays
from microsim.tracer.integrators.surface import SurfaceTracer
from microsim.tracer.integrators.surface_transport import (
    BOTTOM,
    SIDE_X,
    SIDE_Y,
    TOP,
    prepare_segment,
    wrap_point,
    wrap_side,
)
from microsim.tracer.materials import Lambert
from microsim.tracer.scene import SceneBuilder
from microsim.tracer.sensor import Sensor
from microsim.tracer.shapes import Shapes

LX, LY = 4.0, 1.0
#: the ridge's cross-section (x, z): flat, a steep wall up to z = 2, a flat top, a steep wall down
PROFILE = np.array([[0.0, 0.0], [2.0, 0.0], [2.05, 2.0], [2.45, 2.0], [2.5, 0.0], [LX, 0.0]])
#: the surface reaches this far beyond the tile's sides (as periodic_tile's copies do)
MARGIN = 0.01
Z_TOP, Z_BOTTOM = 2.5, -1.0
THETAS = (0.0, 60.0, 85.0)


def ridge_scene(ly: float, albedo: float):
    """The profile extruded along y over the tile [0, LX) x [0, ly) and MARGIN of each side beyond
    it, two triangles (one facet) per segment, Lambertian."""
    x0, x1 = -MARGIN * LX, (1.0 + MARGIN) * LX
    profile = np.vstack([[x0, 0.0], PROFILE, [x1, 0.0]])
    y0, y1 = -MARGIN * ly, (1.0 + MARGIN) * ly
    vertices, faces, points, normals = [], [], [], []
    for (xa, za), (xb, zb) in zip(profile[:-1], profile[1:]):
        if xb <= xa:
            continue
        k = len(vertices)
        vertices += [[xa, y0, za], [xb, y0, zb], [xb, y1, zb], [xa, y1, za]]
        faces += [[k, k + 1, k + 2], [k, k + 2, k + 3]]
        normal = np.array([-(zb - za), 0.0, xb - xa])
        points += [[0.5 * (xa + xb), 0.5 * (y0 + y1), 0.5 * (za + zb)]] * 2
        normals += [normal / np.linalg.norm(normal)] * 2
    builder = SceneBuilder(LX, ly)
    n = len(faces)
    builder.add(np.array(vertices, np.float32), np.array(faces, np.int32), np.arange(n, dtype=np.int32),
                Shapes.planes(np.array(points), np.array(normals), 1.0), Lambert(kind="lambert", albedo=albedo))
    return builder.build(Z_TOP, Z_BOTTOM, {})


def direction(theta_deg: float, phi_deg: float = 0.0) -> np.ndarray:
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])


def trace(scene, backend: str, paths: int, sensor, realization: int = 0, theta: float = 60.0, phi: float = 30.0,
          points=()):
    """The tally of ``paths`` paths, binned on ``sensor`` and, with ``points`` ([theta_o, phi_o]
    pairs, deg), read there by next-event estimation too: a run's estimators, so a run's kernel."""
    estimators = build(("exit_bins", "retro_rings"), sensor) + (Points(sensor, keys=PointsKeys(directions_deg=list(points))),)
    tracer = SurfaceTracer(scene, sensor, backend, estimators=estimators)
    return tracer.trace(direction(theta, phi), paths, stream_key(5, realization, 0), 0)


# --- exact, the kernels alone ---------------------------------------------------------------


def flat_scene(lx: float, ly: float | None = None):
    """A tile with a base plane only (the kernels below never ask Embree)."""
    builder = SceneBuilder(lx, ly)
    builder.add_base_plane(-0.5, Lambert(kind="lambert", albedo=0.5))
    return builder.build(1.0, -1.0, {})


def unfolded_crossings(start: float, end: float, period: float) -> int:
    return abs(math.floor(end / period) - math.floor(start / period))


def periodic_gap(a: float, b: float, period: float) -> float:
    gap = (a - b) % period
    return min(gap, period - gap)


@pytest.mark.parametrize("phi_deg", [17.0, 135.0, 200.0, 290.0, 0.0, 90.0])
def test_a_straight_ray_wraps_as_the_unfolded_line_does(phi_deg):
    """From (0.3, 0.7, z_top) down at 89.4 deg: 3.5 / cos of travel, tens of sides in x and in y;
    every segment starts on the unfolded line folded into the tile, and the sides met are the
    line's crossings of x = k L_x and y = k L_y, each counted once."""
    scene = flat_scene(LX, LY).arrays()._replace(z_top=Z_TOP, z_bottom=Z_BOTTOM)
    assert scene.period == (LX, LY)
    rays = allocate_rays(1)
    d = tuple(-direction(89.4, phi_deg))
    start = (0.3, 0.7, Z_TOP)
    o, travelled, sides = start, 0.0, {SIDE_X: 0, SIDE_Y: 0}
    for _ in range(10_000):
        prepare_segment(rays, 0, o, d, scene)
        origin = rays.origin[0].astype(np.float64)
        line = [start[k] + travelled * d[k] for k in range(3)]
        assert 0.0 <= origin[0] <= LX and 0.0 <= origin[1] <= LY
        assert periodic_gap(origin[0], line[0], LX) < 1e-4 and periodic_gap(origin[1], line[1], LY) < 1e-4
        assert origin[2] == pytest.approx(line[2], abs=1e-4)
        end, t = int(rays.end[0]), float(rays.tfar[0])
        travelled += t
        if end in (TOP, BOTTOM):
            break
        sides[end] += 1
        o = wrap_side(tuple(origin), tuple(rays.direction[0].astype(np.float64)), t, end, scene.period)
    assert end == BOTTOM
    total = (Z_BOTTOM - Z_TOP) / d[2]
    assert travelled == pytest.approx(total, rel=1e-5)
    far = [start[k] + total * d[k] for k in range(2)]
    assert sides[SIDE_X] == unfolded_crossings(start[0], far[0], LX)
    assert sides[SIDE_Y] == unfolded_crossings(start[1], far[1], LY)
    assert sides[SIDE_X] + sides[SIDE_Y] >= (30 if phi_deg % 90 else 20)


def test_a_point_past_a_side_folds_back_by_that_sides_period():
    period = (LX, LY)
    up = (0.0, 0.0, 1.0)
    for p, folded in (((-1e-9, -1e-9, 0.0), (LX - 1e-9, LY - 1e-9)), ((LX + 1e-9, LY + 1e-9, 0.0), (1e-9, 1e-9)),
                      ((3.9, 0.5, 0.0), (3.9, 0.5)), ((0.5, 0.9, 0.0), (0.5, 0.9)), ((LX, LY, 0.0), (0.0, 0.0))):
        x, y, z = wrap_point(p, up, 0.0, period)
        assert (x, y) == pytest.approx(folded, abs=1e-15) and z == 0.0
    x, y, _ = wrap_point((3.9, 0.5, 0.0), (1.0, 1.0, 0.0), 0.2, period)
    assert (x, y) == pytest.approx((0.1, 0.7))
    x, y, _ = wrap_point((0.1, 0.1, 0.0), (-1.0, -1.0, 0.0), 0.2, period)
    assert (x, y) == pytest.approx((3.9, 0.9))


def test_a_ray_at_a_side_continues_from_the_opposite_side_the_other_coordinate_folded_by_its_period():
    """At a corner (the other coordinate a little past its side, as round-off leaves it): the
    side met wraps to the opposite one, the other coordinate folds by its own period."""
    period = (LX, LY)
    # reaches x = L_x at t = 0.5, y just below 0
    assert wrap_side((3.5, 0.25, 0.0), (1.0, -0.5000001, 0.0), 0.5, SIDE_X, period) == pytest.approx(
        (0.0, LY - 5e-8, 0.0), abs=1e-12)
    # reaches x = 0 at t = 0.5, y just past L_y
    assert wrap_side((0.5, 0.75, 0.0), (-1.0, 0.5000001, 0.0), 0.5, SIDE_X, period) == pytest.approx(
        (LX, 5e-8, 0.0), abs=1e-12)
    # reaches y = 0 at t = 0.5, x just below 0; and y = L_y, x just past L_x
    assert wrap_side((0.05, 0.5, 0.0), (-0.1000001, -1.0, 0.0), 0.5, SIDE_Y, period) == pytest.approx(
        (LX - 5e-8, LY, 0.0), abs=1e-12)
    assert wrap_side((3.95, 0.5, 0.0), (0.1000001, 1.0, 0.0), 0.5, SIDE_Y, period) == pytest.approx(
        (5e-8, 0.0, 0.0), abs=1e-12)


def test_a_square_tile_is_the_tile_of_one_side():
    scene = flat_scene(2.5)
    assert scene.tile == scene.tile_y == 2.5 and scene.period == (2.5, 2.5)
    with pytest.raises(ValueError, match="positive"):
        flat_scene(2.5, 0.0)


def test_the_base_plane_covers_the_rectangle_with_its_margin():
    scene = flat_scene(LX, LY)
    lo, hi = scene.vertices.min(axis=0), scene.vertices.max(axis=0)
    assert lo[:2] == pytest.approx([-0.01 * LX, -0.01 * LY]) and hi[:2] == pytest.approx([1.01 * LX, 1.01 * LY])
    assert scene.shapes.size[0] == LX


# --- traced --------------------------------------------------------------------------------


@pytest.mark.parametrize("backend", ["direct", "embreex"])
def test_a_white_ridge_on_a_rectangular_tile_returns_every_path(backend):
    sensor = Sensor.build(100)
    scene = ridge_scene(LY, albedo=1.0)
    for theta, phi in ((0.0, 0.0), (60.0, 30.0), (85.0, 100.0), (80.0, 0.0), (80.0, 90.0)):
        paths = 20_000
        tally = trace(scene, backend, paths, sensor, theta=theta, phi=phi)
        left = tally.estimates[0].weight[0, :ORDERS].sum() / paths
        assert tally.energy[TRANSMITTED] == 0.0, (theta, phi)
        assert left + tally.energy[TRUNCATED] / paths == pytest.approx(1.0, rel=0, abs=1e-12), (theta, phi)
        assert tally.energy[TRUNCATED] <= 1.0, (theta, phi)  # a grazing path or none


def cell_estimates(scene, backend, sensor, realizations, paths, points):
    """Per realization (streams (5, r, 0)): the albedo by order and the f of each point, both
    divided as a table divides them (the same factor for both tiles)."""
    rows = []
    for r in range(realizations):
        tally = trace(scene, backend, paths, sensor, realization=r, points=points)
        rows.append(np.concatenate([tally.estimates[0].weight[0, :ORDERS].sum(axis=1),
                                    tally.estimates[2].weight[0].sum(axis=0)]) / paths)
    return np.array(rows)


@pytest.mark.parametrize("backend", ["direct", "embreex"])
def test_the_ridge_on_the_rectangular_tile_matches_it_on_the_square_tile(backend):
    """Invariant in y, the ridge gives the same paths on 4 x 1 and 4 x 4 but for round-off: the
    albedos by order and the next-event points agree to a quarter of their standard errors."""
    sensor, points = Sensor.build(100), [[50.0, 0.0], [70.0, 180.0], [60.0, 90.0]]
    realizations, paths = 6, 4000
    rect = cell_estimates(ridge_scene(LY, 0.8), backend, sensor, realizations, paths, points)
    square = cell_estimates(ridge_scene(LX, 0.8), backend, sensor, realizations, paths, points)
    stderr = np.hypot(rect.std(axis=0, ddof=1), square.std(axis=0, ddof=1)) / math.sqrt(realizations)
    assert np.all(stderr > 0)
    gap = np.abs(rect.mean(axis=0) - square.mean(axis=0)) / stderr
    assert gap.max() < 0.25, gap
