"""The Boolean sphere generator: density, void free path, tessellation budget, periodic images."""

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from microsim import config, geometry
from microsim.physics.boolean_model import free_path
from microsim.physics.rng import geometry_rng
from microsim.tracer import embree, materials

SPHERES = geometry.SCENES["poisson_spheres"]


def scene_config(**scene):
    return config.validate({
        "scene": {"kind": "poisson_spheres", **scene},
        "material": {"kind": "lambert", "albedo": 0.8},
        "illumination": {"theta_i_deg": [0.0]},
        "run": {"paths": 1000},
    })


def realize(cfg, realization=0):
    return SPHERES.generate(SPHERES.resolve(cfg), cfg, geometry_rng(1, realization))


@pytest.mark.parametrize("phi", [0.05, 0.3, 0.6])
def test_void_fraction_is_one_minus_phi(phi):
    """A point is in the void when no centre lies within one radius: probability exp(-n 4/3 pi) = 1 - phi."""
    cfg = scene_config(volume_fraction=phi, tile=16.0, depth=12.0)
    rng = np.random.default_rng(0)
    fractions = []
    for r in range(8):
        scene = realize(cfg, r)
        centres = scene.shapes.params[:, :3]
        points = rng.uniform((0, 0, -10.0), (16.0, 16.0, -2.0), size=(20_000, 3))
        distance, _ = cKDTree(centres).query(points)
        fractions.append(np.mean(distance > 1.0))
    stderr = np.std(fractions, ddof=1) / math.sqrt(len(fractions))
    assert abs(np.mean(fractions) - (1 - phi)) <= 4 * stderr


@pytest.mark.parametrize("model", [{"subdivisions": 1}, {}], ids=["icosphere-1", "exact"])
def test_void_free_path_is_exponential_with_mean_l(model):
    """Rays from random void points in random directions: chords of mean l = 4 / (-3 ln(1 - phi)).

    Exact spheres have it by construction. The meshes are scaled to the sphere's area, so by
    Cauchy's formula their mean projected area is pi and the mean free path is exactly l whatever
    the tessellation (randomly rotated).
    """
    phi = 0.3
    cfg = scene_config(volume_fraction=phi, tile=24.0, depth=24.0, **model)
    l = 4.0 / (-3.0 * math.log(1 - phi))
    rng = np.random.default_rng(1)
    cap = 6.0  # rays start 6 radii inside the tile and slab, so distances are observed up to 6
    estimates = []
    for r in range(40):  # the mean chord of one realization scatters by ~6 %: average many
        scene = realize(cfg, r)
        centres = scene.shapes.params[:, :3]
        points = rng.uniform((cap, cap, -24.0 + cap), (24.0 - cap, 24.0 - cap, -cap), size=(10_000, 3))
        points = points[cKDTree(centres).query(points)[0] > scene.shapes.params[0, 4]]  # outside every mesh
        d = rng.normal(size=points.shape)
        d /= np.linalg.norm(d, axis=1)[:, None]
        prim, t, _ = embree.Scene(scene.vertices, scene.faces, scene.spheres).intersect(
            points, d, np.full(len(points), cap))
        # censored exponential: maximum likelihood = total observed length / number of hits
        estimates.append(np.minimum(t, cap).sum() / (prim >= 0).sum())
    stderr = np.std(estimates, ddof=1) / math.sqrt(len(estimates))
    assert abs(np.mean(estimates) - l) <= 4 * stderr
    assert stderr < 0.02 * l  # resolves the 7.5 % bias an unscaled (inscribed) level-1 mesh would have


@pytest.mark.parametrize("budget", [0.05, 0.01, 0.003])
def test_tessellation_is_the_coarsest_within_the_mesh_error_budget(budget):
    info = SPHERES.resolve(scene_config(volume_fraction=0.3, mesh_error=budget))
    assert info["max_mesh_error"] <= budget
    if info["subdivisions"] > 0:
        assert SPHERES.unit_icosphere(info["subdivisions"] - 1)[3] > budget
    # the recorded error is the true largest distance between mesh and sphere
    vertices, faces, radius, error = SPHERES.unit_icosphere(info["subdivisions"])
    assert np.allclose(np.linalg.norm(vertices, axis=1), radius)
    centroids = vertices[faces].mean(axis=1)
    assert error >= 1.0 - np.linalg.norm(centroids, axis=1).min() - 1e-12
    assert error == pytest.approx(max(radius - 1.0, 1.0 - np.linalg.norm(centroids, axis=1).min()), rel=0.05)


def test_every_sphere_reaching_into_the_tile_is_present():
    cfg = scene_config(volume_fraction=0.3, tile=16.0, depth=6.0)
    scene = realize(cfg)
    centres = scene.shapes.params[:, :3]
    reach = scene.shapes.params[0, 4]
    originals = scene.info["spheres"]
    assert len(centres) == originals + scene.info["sphere_images"]
    # each periodic copy of an original that reaches into the tile is among the shapes
    tree = cKDTree(centres)
    for sx in (-1, 0, 1):
        for sy in (-1, 0, 1):
            shifted = centres[:originals] + [sx * 16.0, sy * 16.0, 0.0]
            inside = np.all((shifted[:, :2] > -reach) & (shifted[:, :2] < 16.0 + reach), axis=1)
            distance, _ = tree.query(shifted[inside])
            assert np.all(distance < 1e-9)
    assert len(scene.spheres) == len(centres) and scene.n_triangles == 0  # exact spheres: one primitive each
    assert np.array_equal(scene.spheres[:, :3], centres.astype(np.float32)) and np.all(scene.spheres[:, 3] == 1.0)


def test_defaults_follow_the_free_path_and_are_recorded():
    dense, dilute = (SPHERES.resolve(scene_config(volume_fraction=phi)) for phi in (0.6, 0.05))
    for info in (dense, dilute):
        assert info["depth"] == pytest.approx(info["optical_depth"] * info["free_path"])
        assert info["tile"] == SPHERES.TILE and info["tile_default"]
    assert dilute["depth"] > dense["depth"] and dilute["tile_bias_floor"] > dense["tile_bias_floor"]
    white = SPHERES.resolve(scene_config(volume_fraction=0.3).model_copy(
        update={"material": materials.Lambert(kind="lambert", albedo=1.0)}))
    assert white["optical_depth"] == SPHERES.MAX_OPTICAL_DEPTH


@pytest.mark.parametrize("phi, theta_max", [(0.3, 0.0), (0.6, 85.0), (0.06, 30.0), (0.02, 85.0), (0.45, 88.0),
                                            (0.3, 89.0)])
def test_default_tile_and_its_bias_floor(phi, theta_max):
    """The table records the shortest tile free of periodic bias (3 free paths; a ray at the
    grazing angle back a diameter from its own track), and the default meets it from phi = 0.061
    up to 88 deg (module doc)."""
    cfg = scene_config(volume_fraction=phi).model_copy(update={"illumination": config.validate({
        "scene": {"kind": "plane"}, "material": {"kind": "lambert", "albedo": 0.5},
        "illumination": {"theta_i_deg": [0.0, theta_max]}, "run": {"paths": 100}}).illumination})
    resolved = SPHERES.resolve(cfg)
    floor = max(3.0 * free_path(phi), 2.0 / math.cos(math.radians(max(theta_max, 85.0))))
    assert resolved["tile"] == SPHERES.TILE and resolved["tile_bias_floor"] == pytest.approx(floor)
    assert (resolved["tile"] >= floor) == (phi >= 0.061 and theta_max <= 88.0)
