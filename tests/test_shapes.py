"""Analytic shapes: hits are projected onto the exact surface and get its exact normal."""

import numpy as np
import pytest

from microsim.tracer.shapes import ELLIPSOID, PLANE, SPHERE, Shapes, surface_point


def project(shapes, k, points):
    out = np.array([surface_point(shapes.code[k], shapes.params[k], tuple(p), (0.0, 0.0, -1.0)) for p in points])
    return out[:, 0], out[:, 1]


@pytest.fixture
def points():
    rng = np.random.default_rng(0)
    return rng.normal(size=(500, 3)) * 2.0 + [1.0, -2.0, 0.5]


def test_sphere_projection_lies_on_the_projection_radius_with_the_radial_normal(points):
    shapes = Shapes.spheres(np.array([[1.0, -2.0, 0.5]]), 1.0, 1.01)
    assert shapes.code[0] == SPHERE
    p, n = project(shapes, 0, points)
    radial = p - [1.0, -2.0, 0.5]
    assert np.allclose(np.linalg.norm(radial, axis=1), 1.01, rtol=1e-14)
    assert np.allclose(n, radial / 1.01, atol=1e-14)


def test_plane_projection_drops_the_point_along_the_normal(points):
    normal = np.array([[0.3, -0.2, 0.9]])
    shapes = Shapes.planes(np.array([[0.0, 0.0, -1.0]]), normal, size=10.0)
    assert shapes.code[0] == PLANE
    p, n = project(shapes, 0, points)
    unit = normal[0] / np.linalg.norm(normal)
    assert np.allclose((p - [0.0, 0.0, -1.0]) @ unit, 0.0, atol=1e-13)
    assert np.allclose(np.cross(p - points, unit), 0.0, atol=1e-13)  # moved along the normal only
    assert np.allclose(n, unit)


def test_ellipsoid_projection_lies_on_the_scaled_surface_with_the_gradient_normal(points):
    centre, axes = np.array([1.0, -2.0, 0.5]), np.array([2.0, 0.5, 1.0])
    shapes = Shapes.ellipsoids(centre[None], axes[None], 1.02)
    assert shapes.code[0] == ELLIPSOID
    p, n = project(shapes, 0, points)
    u = (p - centre) / axes
    assert np.allclose(np.linalg.norm(u, axis=1), 1.02, rtol=1e-13)
    gradient = (p - centre) / axes**2
    assert np.allclose(n, gradient / np.linalg.norm(gradient, axis=1)[:, None], atol=1e-13)
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)


def test_an_unknown_shape_kind_is_refused_when_the_shapes_are_built():
    shapes = Shapes.spheres(np.zeros((1, 3)), 1.0, 1.0)
    with pytest.raises(ValueError, match="shape kind codes \\[7\\] unknown"):
        Shapes(np.array([7], np.int32), shapes.params, shapes.material, shapes.size)


def test_plane_rows_and_tile_facets_are_numpys_bit_for_bit():
    """The numba kernels behind ``Shapes.planes`` and ``Tile.of`` give what numpy gives, bit for
    bit: tables traced before them stay the same."""
    from microsim.geometry.periodic_tile import Tile

    rng = np.random.default_rng(3)
    vertices = rng.normal(size=(60, 3)) * rng.uniform(0.01, 100.0, (60, 1))
    faces = np.array([rng.choice(60, 3, replace=False) for _ in range(500)])
    corners = vertices[faces]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(cross, axis=1)
    tile = Tile.of(vertices, faces, 1.0)
    assert np.array_equal(tile.normals, cross / length[:, None]) and np.array_equal(tile.areas, 0.5 * length)
    planes = Shapes.planes(corners.mean(axis=1), cross, 1.0)
    assert np.array_equal(planes.params[:, 3:6], cross / length[:, None]) and (planes.code == PLANE).all()
    assert np.array_equal(planes.params[:, :3], corners.mean(axis=1)) and not planes.params[:, 6:].any()
