"""Micrograin visibility (Lucas et al. 2024, Fig. 6) on the real Embree scene the tracer uses.

What is checked. On realizations of the ``micrograins`` scene (geometry/micrograins.py: exact
grains, Embree native spheres in the frame scaled by (beta_x, beta_y), held in an instance),
shadow rays are traced with :meth:`microsim.tracer.embree.Scene.occluded` and compared with the model
(microsim/models/micrograin_geometry.py):

* G1^dist(w, h) (Eq. 16, 19: ``g1_distant``): points on the surface of grains whose centre lies
  in the tile (not periodic images), at unit-space height h (unit-frame normal m' with
  m'.z = h, azimuth uniform over the part of the ring that faces w), pushed OFFSET out along
  the true normal, kept only if they lie in no other grain (the model's condition, tested on a
  periodic KD-tree of the unit-frame centres): the fraction whose ray towards w leaves the
  layer. Other grains are Poisson and independent of the own grain (Slivnyak), so the facing
  restriction does not bias it. tau0 in {0.2, 0.6, 0.9}; h in {0.1, 0.5, 0.9}; theta in
  {0, 45, 70, 85} deg; an isotropic field (beta = 1) and an anisotropic one (beta_x = 0.5,
  beta_y = 2, w at azimuth 0 and 90 deg): 99 cases.
* V_p(i, o) = (1 - tau0) G^dist(i, o, 0) (Eq. 23, App. C: ``pore_visibility``): the fraction of
  uniform base points (lifted BASE_LIFT) that are bare and whose rays towards i and o both leave
  the layer; o = i (and normal incidence: the bare fraction 1 - tau0), o 5 deg from i (near
  retro-reflection, where the shadows are correlated), o specular to i, and out of plane:
  7 pairs x 6 fields = 42 cases.
* Where the model has no shadow at all (sigma_s = 0: theta = 0, or h >= sin theta'; 33 of the
  G1 cases), G1 = 1 exactly: no ray may be blocked (a sharp check, no statistics).
* Power: at a grazing near-retro pair (tau0 = 0.6, theta = 80 deg, o 5 deg from i) the
  uncorrelated product G1(i) G1(o) (Eq. 17) is rejected (|z| > 4) by the same data that the
  correlated Eq. 18 passes.

Shadow rays in a periodic tile. The scene holds one tile [0, L)^2 and the images of grains that
cross its sides, so a ray is traced in segments: from its origin to the nearer of the plane
z = TOP above every grain (reached unblocked: free) and the side of the tile (reached
unblocked: it goes on from the opposite side), vectorised over all rays: the shadow rays of
microsim.geometry.surface_statistics.leaves, which measures the masking of mesh and heightfield scenes.

Sampling. The G1 points of a realization are drawn in proportion to its number of grains, so
that every grain of every realization weighs the same (the Palm distribution the model
averages over): the same number of points in every realization would favour sparse ones, whose
grains see fewer neighbours (G1 = 0.3651 at tau0 = 0.2, theta = 85 deg, h = 0.1 came out 0.3747,
z = 3.6 over 400 realizations; 0.3691, z = 1.5, weighted by grains). Points within VOID_MARGIN
of another grain are left out (float32 rays, see there).

Standard errors. The geometry is random, so errors come from REALIZATIONS independent scenes
(one per tau0, field and realization, reused for every height and direction) taken as batches.
Each realization gives a deviation from the model, mean 0 if the model holds: for G1
(visible - G1 kept) / mean kept, whose sum over realizations is the pooled ratio
sum(visible) / sum(kept) minus G1; for V_p its fraction minus V_p. z is the t statistic of their
mean, with two guards (see :func:`z_score`): its error is floored at the binomial error the
model implies for the points drawn (where the rarer outcome is so rare, G1 ~ 1e-5, that most
realizations see none of it, the batches' spread says nothing), and it carries Hall's (1992)
skewness correction, since the rare-event cases are skewed (plain t: P(t < -4) up to 5e-3).
The plain z is printed beside it. The cases of one field share its scenes, so their z move
together (a denser set of realizations lowers every G1 and V_p of that field).

Why 4. 108 cases are z-tested (66 G1, 42 V_p). With REALIZATIONS = 64 batches, z is about
Student-t with 63 degrees of freedom, and P(|t_63| > 4) = 1.7e-4: were the cases independent,
the chance that any exceeds 4 by chance would be 1.8 % (0.7 % for a normal z); their
correlation makes it smaller. The standard errors are 2e-5 to 7e-3, so a model error of 0.03
fails in every case, one of 0.01 in 74 of the 108 and one of 0.005 in 45. The seeds are fixed,
so a pass or a failure is reproducible. Run with -s for the table of every case.
"""

import functools
import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from microsim import config, geometry
from microsim.core.frames import direction
from microsim.geometry.surface_statistics import leaves
from microsim.models import micrograin_geometry as geo
from microsim.physics.boolean_model import grain_density, grain_extinction, unit_space_direction_array
from microsim.tracer import embree, shapes

REALIZATIONS = 64
#: points kept (in the void) per realization per G1 case, on average
G1_POINTS = 800
#: base points per realization per V_p pair
VP_POINTS = 5000
Z_MAX = 4.0
SEED = 20240610

TAU0S = (0.2, 0.6, 0.9)
#: field name -> (beta_x, beta_y, azimuths of w in deg)
FIELDS = {"isotropic": (1.0, 1.0, (0.0,)), "anisotropic": (0.5, 2.0, (0.0, 90.0))}
HEIGHTS = (0.1, 0.5, 0.9)
THETAS = (0.0, 45.0, 70.0, 85.0)
#: (theta_i, phi_i), (theta_o, phi_o) in deg
VP_PAIRS = (
    ((0.0, 0.0), (0.0, 0.0)),  # normal: the bare fraction, 1 - tau0
    ((70.0, 0.0), (70.0, 0.0)),  # o = i: (1 - tau0) G1(i, 0)
    ((85.0, 0.0), (85.0, 0.0)),
    ((85.0, 90.0), (85.0, 90.0)),
    ((80.0, 0.0), (80.0, 5.0)),  # near retro-reflection: correlated shadows
    ((70.0, 0.0), (70.0, 180.0)),  # specular
    ((60.0, 30.0), (75.0, 120.0)),  # out of plane
)
#: the pair at which the uncorrelated form must be rejected (tau0 = 0.6, isotropic)
RETRO_PAIR = ((80.0, 0.0), (80.0, 5.0))

#: grain points are pushed this far out along the true normal (float32 rays in a tile of up to 64)
OFFSET = 1e-4
#: grain points closer than this (unit frame) to another grain are left out: there the two
#: surfaces meet, and Embree's float32 rays (unit-frame coordinates up to 128) may find the
#: point on the other grain (without it, 8 of 1.2e7 rays of the sharp cases were blocked; the
#: one examined started at unit distance 1 + 9e-8 from another grain and hit it at t = 5e-7);
#: it drops a fraction 2 lambda VOID_MARGIN < 5e-4 of the points
VOID_MARGIN = 1e-4
#: base points are lifted this far above the base plane
BASE_LIFT = 1e-6
#: shadow rays end on this plane, above every grain (unit vertical semi-axis)
TOP = 1.0 + 1e-3


def unit(theta_deg, phi_deg):
    return direction(math.radians(theta_deg), math.radians(phi_deg))


class Field:
    """One realization of the micrograin scene, as built for the tracer, with Embree and a KD-tree."""

    def __init__(self, tau0, beta_x, beta_y, rng):
        cfg = config.validate({
            "scene": {"kind": "micrograins", "tau0": tau0, "beta_x": beta_x, "beta_y": beta_y},
            "material": {"kind": "lambert", "albedo": 0.5},
            "illumination": {"theta_i_deg": [85.0]},
            "run": {"paths": 1000},
        })
        generator = geometry.SCENES["micrograins"]
        scene = generator.generate(generator.resolve(cfg), cfg, rng)
        self.embree = embree.Scene(scene.vertices, scene.faces, scene.spheres, sphere_scale=scene.sphere_scale)
        assert tuple(scene.sphere_scale) == (beta_x, beta_y)
        self.tile = tile = scene.tile
        self.beta = np.array([beta_x, beta_y])
        grains = scene.shapes.params[scene.shapes.code == shapes.ELLIPSOID]
        np.testing.assert_allclose(grains[:, 3:6], np.tile([beta_x, beta_y, 1.0], (len(grains), 1)))  # inverse semi-axes
        centres = grains[:, 0:3]
        own = np.all((centres[:, :2] >= 0.0) & (centres[:, :2] < tile), axis=1)  # not periodic images
        self.centres = centres[own]
        assert len(self.centres) > 0
        self.box = self.beta * tile
        self.tree = cKDTree(self._unit_xy(self.centres), boxsize=self.box)

    def close(self):
        self.embree.close()

    def _unit_xy(self, p):
        """(x, y) of points (n, 3) in the grains' unit frame, wrapped into the periodic box."""
        u = np.mod(p[:, :2] * self.beta, self.box)
        u[u >= self.box] = 0.0
        return u

    def in_grains(self, p):
        """Whether points (n, 3), z >= 0, lie inside a grain: unit-frame distance to a centre < 1."""
        d, _ = self.tree.query(self._unit_xy(p), k=1, distance_upper_bound=1.0)
        return d * d + p[:, 2] ** 2 < 1.0

    def free(self, origins, w):
        """Whether the ray from each origin (n, 3) towards w (3,), w.z > 0, leaves the layer unblocked
        (surface_statistics.leaves: segments to the top or the tile side, wrapped)."""
        return leaves(self.embree.occluded, origins, w, (self.tile, self.tile), TOP)

    def grain_points(self, rng, attempts, h, w):
        """Points at unit-space height h on the grains, facing w, in no other grain, offset OFFSET."""
        bx, by = self.beta
        wp = unit_space_direction_array(w, bx, by)
        r = math.sqrt(1.0 - h * h)
        s = math.hypot(wp[0], wp[1])
        # m' . w' > 0 <=> cos(a - phi') > -h w'_z / (r s): the arc of the ring that faces w
        half = math.pi if s * r == 0.0 else math.acos(min(max(-h * wp[2] / (r * s), -1.0), 1.0))
        a = math.atan2(wp[1], wp[0]) + rng.uniform(-half, half, attempts)
        m = np.column_stack([r * np.cos(a), r * np.sin(a), np.full(attempts, h)])
        grain = rng.integers(0, len(self.centres), attempts)
        points = self.centres[grain] + m / np.array([bx, by, 1.0])
        normal = m * np.array([bx, by, 1.0])
        normal /= np.linalg.norm(normal, axis=1)[:, None]
        assert np.all(normal @ w > 0.0)
        points += OFFSET * normal
        # the nearest centre other than the own grain's: the point must lie outside that grain
        distance, nearest = self.tree.query(self._unit_xy(points), k=2, distance_upper_bound=1.0 + VOID_MARGIN)
        other = np.where(nearest[:, 0] == grain, distance[:, 1], distance[:, 0])
        return points[other**2 + points[:, 2] ** 2 >= (1.0 + VOID_MARGIN) ** 2]


def g1_cases(field):
    _, _, azimuths = FIELDS[field]
    return [(theta, phi, h) for theta in THETAS for phi in (azimuths if theta > 0.0 else (0.0,)) for h in HEIGHTS]


@functools.lru_cache(maxsize=None)
def measure(tau0, field):
    """Per-realization counts: G1 {case: (kept (R,), visible (R,))}, V_p {pair: visible fraction (R,)}."""
    beta_x, beta_y, _ = FIELDS[field]
    key = [SEED, TAU0S.index(tau0), list(FIELDS).index(field)]
    lam = grain_extinction(tau0)
    cases = g1_cases(field)
    kept = {case: np.zeros(REALIZATIONS, np.int64) for case in cases}
    visible = {case: np.zeros(REALIZATIONS, np.int64) for case in cases}
    pore = {pair: np.zeros(REALIZATIONS) for pair in VP_PAIRS}
    for n in range(REALIZATIONS):
        grains = Field(tau0, beta_x, beta_y, np.random.default_rng(key + [n, 0]))
        expected_grains = grain_density(tau0, beta_x, beta_y) * grains.tile**2
        rng = np.random.default_rng(key + [n, 1])
        # points in proportion to the grains: every grain of every realization counts once (Palm
        # weighting; the same number in every realization would favour sparse ones, see the doc)
        share = len(grains.centres) / expected_grains
        for case in cases:
            theta, phi, h = case
            w = unit(theta, phi)
            void = math.exp(-lam * (1.0 - h * h))  # chance that a ring point is in no other grain
            points = grains.grain_points(rng, int(math.ceil(G1_POINTS * share / void)), h, w)
            kept[case][n] = len(points)
            visible[case][n] = np.count_nonzero(grains.free(points, w))
        base = np.column_stack([rng.uniform(0.0, grains.tile, (VP_POINTS, 2)), np.full(VP_POINTS, BASE_LIFT)])
        bare = base[~grains.in_grains(base)]
        for pair in VP_PAIRS:
            wi, wo = unit(*pair[0]), unit(*pair[1])
            lit = bare[grains.free(bare, wi)]
            pore[pair][n] = np.count_nonzero(grains.free(lit, wo)) / VP_POINTS
        grains.close()
    return ({case: (kept[case], visible[case]) for case in cases}, pore)


def z_score(deviations, model, points):
    """(z, plain z, standard error) of per-realization deviations from the model, mean 0 if it holds.

    The standard error of their mean is floored at the binomial error of ``points`` independent
    points, sqrt(p (1 - p) / points): below it the batches carry no usable spread (a case whose
    rarer outcome no realization saw), and z is then the plain ratio. Otherwise z is Student's t
    with Hall's (1992) skewness correction, sqrt(R) [((1 + g U / 3)^3 - 1) / g + g / (6 R)],
    U = mean / sd, g the sample skewness: in the rare-event cases (V_p ~ 1e-4, 30-70 % of the
    realizations see no visible pore) the deviations are skewed (g ~ 1.4-2.3), and the plain t
    of 64 batches then has P(t < -4) = 1e-3 to 5e-3 instead of 8.5e-5 (resampled from 1500
    realizations); corrected, 0 to 1.5e-4. For g -> 0 it is the plain t.
    """
    r = len(deviations)
    mean = deviations.mean()
    sd = deviations.std(ddof=1)
    floor = math.sqrt(model * (1.0 - model) / points)
    stderr = sd / math.sqrt(r)
    if not stderr > floor:
        return mean / floor, mean / floor, floor
    g = np.mean((deviations - mean) ** 3) / sd**3
    u = mean / sd
    corrected = u if abs(g) < 1e-9 else ((1.0 + g * u / 3.0) ** 3 - 1.0) / g + g / (6.0 * r)
    return math.sqrt(r) * corrected, mean / stderr, stderr


def g1_table(tau0, field):
    """Rows (theta, phi, h, model, estimate, stderr, z, plain z, kept points, blocked points).

    Per realization, the deviation (visible - G1 kept) / mean kept has mean 0 if the model holds
    (points are drawn in proportion to the grains); the estimate is sum(visible) / sum(kept).
    """
    beta_x, beta_y, _ = FIELDS[field]
    counts, _ = measure(tau0, field)
    rows = []
    for (theta, phi, h), (kept, visible) in counts.items():
        model = float(geo.g1_distant(unit(theta, phi), h, tau0, beta_x, beta_y))
        estimate = visible.sum() / kept.sum()
        deviations = (visible - model * kept) / kept.mean()
        z, plain, stderr = z_score(deviations, model, kept.sum()) if model < 1.0 else (math.nan, math.nan, 0.0)
        blocked = int(kept.sum() - visible.sum())
        rows.append((theta, phi, h, model, estimate, stderr, z, plain, int(kept.sum()), blocked))
    return rows


def vp_table(tau0, field):
    """Rows (pair, model, uncorrelated model, estimate, stderr, z, plain z, z of the uncorrelated model)."""
    beta_x, beta_y, _ = FIELDS[field]
    _, pore = measure(tau0, field)
    rows = []
    for pair, fractions in pore.items():
        wi, wo = unit(*pair[0]), unit(*pair[1])
        model = float(geo.pore_visibility(wi, wo, tau0, beta_x, beta_y))
        uncorrelated = float(geo.pore_visibility(wi, wo, tau0, beta_x, beta_y, correlated=False))
        points = len(fractions) * VP_POINTS
        z, plain, stderr = z_score(fractions - model, model, points)
        z_uncorrelated, _, _ = z_score(fractions - uncorrelated, uncorrelated, points)
        rows.append((pair, model, uncorrelated, fractions.mean(), stderr, z, plain, z_uncorrelated))
    return rows


PARAMS = [(tau0, field) for tau0 in TAU0S for field in FIELDS]


@pytest.mark.parametrize("tau0, field", PARAMS)
def test_g1_distant_matches_occlusion_rays_on_the_embree_scene(tau0, field):
    rows = g1_table(tau0, field)
    print(f"\nG1dist, tau0 = {tau0}, {field} {FIELDS[field][:2]}, {REALIZATIONS} realizations")
    print("theta   phi    h   model     Embree    stderr      z  plain z     kept  blocked")
    for theta, phi, h, model, estimate, stderr, z, plain, kept, blocked in rows:
        print(f"{theta:5.0f} {phi:5.0f} {h:4.1f}  {model:.5f}  {estimate:.5f}  {stderr:.5f}  {z:6.2f}  {plain:6.2f}"
              f"  {kept:7d}  {blocked:7d}")
    sharp = [(theta, phi, h, blocked) for theta, phi, h, model, *_, blocked in rows if model == 1.0]
    assert all(blocked == 0 for *_, blocked in sharp), f"rays blocked where the model has no shadow: {sharp}"
    bad = [(theta, phi, h, round(z, 2)) for theta, phi, h, model, _, _, z, *_ in rows
           if model < 1.0 and not abs(z) <= Z_MAX]
    assert not bad, f"|z| > {Z_MAX} (theta, phi, h, z): {bad}"


@pytest.mark.parametrize("tau0, field", PARAMS)
def test_pore_visibility_matches_occlusion_rays_on_the_embree_scene(tau0, field):
    rows = vp_table(tau0, field)
    print(f"\nV_p, tau0 = {tau0}, {field} {FIELDS[field][:2]}, {REALIZATIONS} x {VP_POINTS} base points")
    print("   i (theta, phi)     o (theta, phi)   model    uncorr.   Embree    stderr      z  plain z  z_uncorr.")
    for pair, model, uncorrelated, estimate, stderr, z, plain, z_uncorrelated in rows:
        print(f"{str(pair[0]):>18} {str(pair[1]):>18}  {model:.5f}  {uncorrelated:.5f}  {estimate:.5f}  {stderr:.5f}"
              f"  {z:6.2f}  {plain:6.2f}  {z_uncorrelated:8.2f}")
    bad = [(pair, round(z, 2)) for pair, _, _, _, _, z, *_ in rows if not abs(z) <= Z_MAX]
    assert not bad, f"|z| > {Z_MAX} (pair, z): {bad}"


def test_uncorrelated_pore_visibility_is_rejected_near_retro_reflection():
    """The check has power: near retro-reflection the uncorrelated G1(i) G1(o) (Eq. 17) misses."""
    rows = {pair: row for pair, *row in vp_table(0.6, "isotropic")}
    model, uncorrelated, estimate, stderr, z, _, z_uncorrelated = rows[RETRO_PAIR]
    print(f"\nV_p at {RETRO_PAIR}, tau0 = 0.6: Embree {estimate:.5f} +- {stderr:.5f}, Eq. 18 {model:.5f} (z {z:.2f}),"
          f" Eq. 17 {uncorrelated:.5f} (z {z_uncorrelated:.2f})")
    assert abs(z) <= Z_MAX
    assert abs(z_uncorrelated) > Z_MAX
