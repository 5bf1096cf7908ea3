"""The sphere scenes' measured structure: the grid's rays meet the first sphere as a brute-force
search over every periodic image does; a Boolean scene's void chords follow their exact
exponential law and its first flights at normal incidence theirs (Hotelling's test on the
realizations, which a packing fails); a packing's mean chord is 4 (1 - phi) / S_v, as in any
medium; and what a run stores in scene/ is the realization's own (the example, with the
statistics, traced in tests/test_scene_kinds.py and tests/test_packed_spheres.py)."""

import math

import numpy as np
import pytest

from microsim import config, geometry
from microsim.geometry import void_chords
from microsim.geometry.packing_statistics import pair_correlation
from microsim.physics.boolean_model import number_density
from microsim.physics.rng import geometry_rng
from microsim.testing import example, trace
from microsim.testing.bounds import hotelling_f, hotelling_interval

#: Hotelling's tests: realizations of a tile of 16 radii, chords a realization
REALIZATIONS, TILE, RAYS = 24, 16.0, 2048
#: the bins merged: chords in 8 bins of 0.75 mean chords; first flights finer near the top (out to 2)
CHORD_GROUPS, FLIGHT_GROUPS = (6,) * 8, (1, 1, 1, 1, 2, 2, 4, 4)


def brute_first_hits(centres, radii, sides, periodic, origins, directions, t_max):
    """Distance to the first sphere entered, over every image within 2 periods, each pair computed;
    inf beyond ``t_max`` or past the box's side along an axis that is not periodic."""
    shifts = np.array([[a, b, c] for a in range(-2, 3) for b in range(-2, 3)
                       for c in (range(-2, 3) if periodic[2] else (0,))]) * sides
    images = (centres[None] + shifts[:, None]).reshape(-1, 3)
    reach = np.tile(radii, len(shifts))
    best = np.full(len(origins), np.inf)
    for lo in range(0, len(images), 4000):
        gap = origins[:, None, :] - images[None, lo:lo + 4000]
        b = np.einsum("ijk,ik->ij", gap, directions)
        disc = b * b - (np.einsum("ijk,ijk->ij", gap, gap) - reach[None, lo:lo + 4000] ** 2)
        t = np.where(disc > 0, -b - np.sqrt(np.abs(disc)), np.inf)
        best = np.minimum(best, np.where(t > void_chords.T_MIN, t, np.inf).min(axis=1))
    if not periodic[2]:
        with np.errstate(divide="ignore"):
            leave = np.where(directions[:, 2] > 0, (sides[2] - origins[:, 2]) / directions[:, 2],
                             np.where(directions[:, 2] < 0, -origins[:, 2] / directions[:, 2], np.inf))
        best = np.where(best <= leave, best, np.inf)
    return np.where(best <= t_max, best, np.inf)


@pytest.mark.parametrize("periodic", [(True, True, True), (True, True, False)], ids=["torus", "slab"])
def test_the_grid_meets_the_first_sphere_that_every_image_searched_meets(periodic):
    """60 spheres of radii 0.3-1.2 in a box of 10 x 12 x 9, 2000 rays out to 15 (random; along the x
    axis, down the z axis and along the diagonal; from cell corners): the same distance to 1e-9,
    or both none; and the same points covered by a sphere."""
    rng = np.random.default_rng(1)
    sides = np.array([10.0, 12.0, 9.0])
    centres, radii = rng.uniform(0, 1, (60, 3)) * sides, rng.uniform(0.3, 1.2, 60)
    grid = void_chords.build(centres, radii, (0, 0, 0), sides, periodic)
    origins = rng.uniform(0, 1, (2000, 3)) * sides
    directions = rng.standard_normal((2000, 3))
    directions[:50], directions[50:100], directions[100:150] = [1, 0, 0], [0, 0, -1], [1, 1, 1]
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    cell = sides / grid.counts
    origins[150:200] = np.floor(origins[150:200] / cell) * cell
    found = void_chords.first_hits(grid, origins, directions, 15.0)  # two periods hold every image within reach
    expected = brute_first_hits(centres, radii, sides, periodic, origins, directions, 15.0)
    assert 0.02 < np.mean(np.isinf(expected)) < 0.98
    with np.errstate(invalid="ignore"):  # inf - inf
        same = (np.isinf(found) & np.isinf(expected)) | (np.abs(found - expected) < 1e-9)
    assert same.all(), np.nonzero(~same)[0][:10]
    shifts = np.array([[a, b, c] for a in (-1, 0, 1) for b in (-1, 0, 1) for c in ((-1, 0, 1) if periodic[2] else (0,))])
    images = (centres[None] + shifts[:, None] * sides).reshape(-1, 3)
    inside = (np.linalg.norm(origins[:, None] - images[None], axis=2) < np.tile(radii, len(shifts))).any(axis=1)
    assert np.array_equal(void_chords.covered(grid, origins, np.full(2000, -1)), inside)


def realizations(kind: str, phi: float):
    """(resolved, infos) of REALIZATIONS realizations of a ``kind`` scene at ``phi`` with statistics."""
    cfg = config.validate({"scene": {"kind": kind, "volume_fraction": phi, "tile": TILE, "statistics": True,
                                     "statistics_rays": RAYS},
                           "material": {"kind": "lambert", "albedo": 0.8}, "illumination": {"theta_i_deg": [0.0]},
                           "run": {"paths": 1000}})
    scenes = geometry.SCENES[kind]
    resolved = scenes.resolve(cfg)
    return resolved, [scenes.generate(resolved, cfg, geometry_rng(5, r)).info for r in range(REALIZATIONS)]


def merged_fractions(counts: np.ndarray, groups) -> np.ndarray:
    """Each realization's share of its rays in the bins merged ``groups`` at a time, from the first."""
    ends = np.cumsum([0, *groups])
    return np.stack([counts[..., a:b].sum(-1) for a, b in zip(ends[:-1], ends[1:])], -1) / counts.sum(-1, keepdims=True)


def merged_shares(survival, edges: np.ndarray, groups) -> np.ndarray:
    """The shares of a law of ``survival`` P(L > l) in the same merged bins."""
    return -np.diff(survival(edges[np.cumsum([0, *groups])]))


def first_flight_survival(phi: float):
    """The Boolean scene's first flight down from z = 1 (module doc of sphere_statistics)."""
    def survival(t):
        volume = np.where(t <= 1, math.pi * t**2 * (3 - t) / 3, 2 * math.pi / 3 + math.pi * (t - 1))
        return np.exp(-number_density(phi) * volume)
    return survival


@pytest.fixture(scope="module")
def boolean():
    return realizations("poisson_spheres", 0.3)


@pytest.fixture(scope="module")
def packing():
    return realizations("packed_spheres", 0.3)


def test_a_boolean_scene_s_chords_are_exponential_and_a_packing_s_are_not(boolean, packing):
    """Phi 0.3, 24 realizations, 8 bins of 0.75 mean chords: Hotelling's F of the realizations'
    shares against exp(-l / l_mean), l_mean = 4 / (-3 ln(1 - phi)), within its two-sided 99 %
    interval; the packing's shares, against the same law at its own mean chord, beyond it."""
    lo, hi = hotelling_interval(8, REALIZATIONS)
    for (resolved, infos), accepted in ((boolean, True), (packing, False)):
        edges = np.asarray(resolved["chord_edges"])
        shares = merged_fractions(np.array([info["chords"] for info in infos]), CHORD_GROUPS)
        f = hotelling_f(shares, merged_shares(lambda t: np.exp(-t / resolved["free_path"]), edges, CHORD_GROUPS))
        assert (lo <= f <= hi) == accepted, (resolved["kind"], f, lo, hi)


def test_a_boolean_scene_s_first_flights_at_normal_incidence_follow_their_exact_law(boolean, packing):
    """P(T > t) = exp(-n V(t)) from the plane z = 1 (sphere_statistics' module doc), in 8 bins out to
    two mean chords, finest at the top: Hotelling's F in its two-sided 99 % interval; the packing's (denser at the top, where a Boolean scene's
    spheres overlap) far beyond it."""
    lo, hi = hotelling_interval(8, REALIZATIONS)
    for (resolved, infos), accepted in ((boolean, True), (packing, False)):
        edges = np.asarray(resolved["chord_edges"])
        shares = merged_fractions(np.array([info["free_path_top"][0] for info in infos]), FLIGHT_GROUPS)
        f = hotelling_f(shares, merged_shares(first_flight_survival(0.3), edges, FLIGHT_GROUPS))
        assert (lo <= f <= hi) == accepted, (resolved["kind"], f, lo, hi)


@pytest.mark.parametrize("kind", ["poisson_spheres", "packed_spheres"])
def test_the_mean_chord_is_four_void_fractions_over_the_exposed_area(kind, boolean, packing):
    """The mean chord of 24 realizations within 2.58 standard errors (two-sided 99 %) of the exact
    mean: 4 / (-3 ln(1 - phi)) for Boolean spheres (1 / (n pi)), 4 (1 - phi) / (3 phi) for
    equal spheres that do not overlap (4 (1 - phi) / S_v, S_v = 3 phi / r)."""
    resolved, infos = boolean if kind == "poisson_spheres" else packing
    means = np.array([info["mean_chord"] for info in infos])
    exact = 4 / (-3 * math.log(0.7)) if kind == "poisson_spheres" else 4 * 0.7 / 0.9
    assert abs(means.mean() - exact) < 2.58 * means.std(ddof=1) / math.sqrt(len(means)), (means.mean(), exact)


def test_a_run_stores_each_realization_s_own_structure():
    """The packed example, traced: scene/pair_correlation is g(r) of each realization's packing over
    the stored edges; the chords and first flights count statistics_rays each, at every incidence."""
    data = example("packed_spheres")
    cfg = config.validate(data)
    result = trace(cfg)
    resolved = geometry.SCENES["packed_spheres"].resolve(cfg)
    box = (resolved["tile"], resolved["tile"], resolved["depth"])
    for r in range(data["run"]["realizations"]):
        info = result.scene_info[r]
        packed = geometry.SCENES["packed_spheres"].draw(resolved, geometry_rng(data["run"]["seed"], r),
                                                        geometry.SCENES["packed_spheres"].cache_directory(cfg))
        assert np.array_equal(info["pair_correlation"], pair_correlation(packed.centres, box,
                                                                         np.asarray(resolved["pair_edges"])))
        assert info["chords"].sum() == resolved["statistics_rays"]
        assert info["free_path_top"].shape == (2, len(resolved["chord_edges"]))
        assert np.all(info["free_path_top"].sum(axis=1) == resolved["statistics_rays"])
