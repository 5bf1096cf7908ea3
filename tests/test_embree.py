"""The Embree binding (microsim/tracer/embree.py): known hits, the layout check, one-line refusals."""

import numpy as np
import pytest

from microsim.tracer import embree


def test_the_binding_finds_known_hits_on_a_triangle_and_a_sphere():
    scene = embree.Scene(vertices=[[0, 0, 0], [2, 0, 0], [0, 2, 0]], faces=[[0, 1, 2]],
                         spheres=[[5.0, 5.0, 0.0, 1.5]])
    prim, t, normal = scene.intersect([[0.5, 0.5, 3.0], [5.0, 5.0, 4.0], [5.0, 5.0, 0.0], [9.0, 9.0, 9.0]],
                                      [[0, 0, -1], [0, 0, -1], [1, 0, 0], [0, 0, 1]], [10.0, 10.0, 10.0, 10.0])
    assert prim.tolist() == [0, 1, 1, -1]
    assert np.allclose(t, [3.0, 2.5, 1.5, 10.0], rtol=1e-6)  # outside, outside, from the centre (exit), miss
    assert np.allclose(normal[1] / np.linalg.norm(normal[1]), [0, 0, 1], atol=1e-6)
    assert np.allclose(normal[2] / np.linalg.norm(normal[2]), [1, 0, 0], atol=1e-6)  # the exit faces out


def test_intersect_fills_the_hits_of_an_earlier_call_again():
    """``out``: the same hits written into the arrays of an earlier call (a replay that times
    Embree alone); arrays for another number of rays are refused."""
    scene = embree.Scene(spheres=[[5.0, 5.0, 0.0, 1.5], [9.0, 5.0, 0.0, 1.0]])
    rng = np.random.default_rng(5)
    origins = rng.uniform(0.0, 10.0, (400, 3))
    directions = np.array([7.0, 5.0, 0.0]) + rng.uniform(-3.0, 3.0, (400, 3)) - origins  # about half hit
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    tfar = np.full(400, 20.0)
    fresh = scene.intersect(origins, directions, tfar)
    reused = scene.intersect(origins[::-1], directions[::-1], tfar)  # other hits in those arrays first
    filled = scene.intersect(origins, directions, tfar, out=reused)
    assert all(f is r for f, r in zip(filled, reused))
    assert (fresh[0] >= 0).sum() > 50 and (fresh[0] < 0).sum() > 50
    for a, b in zip(fresh, filled):
        assert np.array_equal(a, b)
    with pytest.raises(ValueError, match="out holds hits of 400 rays, not 399"):
        scene.intersect(origins[:399], directions[:399], tfar[:399], out=reused)


def test_a_missing_library_is_one_line(monkeypatch):
    monkeypatch.setattr("importlib.util.find_spec", lambda name: None)
    with pytest.raises(embree.EmbreeUnavailable, match="^embreex is not installed"):
        embree.library_path()


def test_ray_hit_records_are_aligned_and_views_alias_them():
    records = embree.ray_hits(5)
    assert records.ctypes.data % embree.ALIGNMENT == 0 and records.dtype.itemsize == embree.RAYHIT_BYTES
    origin, direction, tfar = embree.ray_views(records)
    origin[3] = (1.0, 2.0, 3.0)
    direction[3] = (0.0, 0.0, -1.0)
    tfar[3] = 7.0
    assert (records[3]["org_x"], records[3]["org_z"], records[3]["dir_z"], records[3]["tfar"]) == (1.0, 3.0, -1.0, 7.0)
    assert np.all(records["mask"] == embree.INVALID_ID) and np.all(records["tnear"] == 0.0)


def test_the_layout_check_refuses_hits_read_from_the_wrong_fields(monkeypatch):
    """What the check would see if RAYHIT put tfar or primID at the wrong offset."""
    wrong = {
        "distances": (np.array([0, 1, -1]), np.array([0.0, 0.0, 10.0], np.float32), np.tile([0.0, 0.0, 1.0], (3, 1))),
        "primitives": (np.array([0, 0, -1]), np.array([2.0, 2.0, 10.0], np.float32), np.tile([0.0, 0.0, 1.0], (3, 1))),
        "normals": (np.array([0, 1, -1]), np.array([2.0, 2.0, 10.0], np.float32), np.tile([2.0, 0.0, 0.0], (3, 1))),
    }
    for name, answer in wrong.items():
        monkeypatch.setattr(embree.Scene, "intersect", lambda self, o, d, t, answer=answer: answer)
        with pytest.raises(embree.EmbreeUnavailable, match="^RTCRayHit layout check failed"):
            embree._check_layout(embree._open())


def test_shadow_rays_are_blocked_by_triangles_and_spheres_only_within_tfar():
    scene = embree.Scene(vertices=[[0, 0, 0], [2, 0, 0], [0, 2, 0]], faces=[[0, 1, 2]],
                         spheres=[[5.0, 5.0, 0.0, 1.5]])
    blocked = scene.occluded([[0.5, 0.5, 3.0], [0.5, 0.5, 3.0], [5.0, 5.0, 4.0], [5.0, 5.0, 4.0], [9, 9, 9]],
                             [[0, 0, -1], [0, 0, -1], [0, 0, -1], [0, 0, -1], [0, 0, 1]],
                             [4.0, 2.9, 3.0, 2.4, 10.0])
    assert blocked.tolist() == [True, False, True, False, False]


def test_spheres_in_a_scaled_frame_are_the_ellipsoids_they_stand_for():
    """Spheres given in the frame scaled by (sx, sy) (an Embree instance): rays from outside hit
    the ellipsoid of semi-axes (r / sx, r / sy, r) at the analytic distance, and the normal
    comes back in the world frame (the ellipsoid's gradient direction)."""
    sx, sy = 0.4, 2.5
    scene = embree.Scene(spheres=[[0.0, 0.0, 0.0, 1.0]], sphere_scale=(sx, sy))
    rng = np.random.default_rng(3)
    target = rng.normal(size=(500, 3))
    target /= np.linalg.norm(target, axis=1)[:, None]
    target *= np.array([1 / sx, 1 / sy, 1.0])  # points of the ellipsoid
    gradient = target * np.array([sx * sx, sy * sy, 1.0])
    normal = gradient / np.linalg.norm(gradient, axis=1)[:, None]
    directions = -normal  # aimed at each point along its inward normal, from 5 units out
    origins = target + 5.0 * normal
    prim, t, ng = scene.intersect(origins, directions, np.full(500, 100.0))
    assert np.all(prim == 0)
    assert np.allclose(t, 5.0, atol=1e-4)
    ng = ng / np.linalg.norm(ng, axis=1)[:, None]
    assert np.all(np.einsum("ij,ij->i", ng, normal) > 1 - 1e-6)
