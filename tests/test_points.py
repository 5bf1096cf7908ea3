"""Next-event estimation at exact directions (microsim.tracer.estimators.points), against exact results.

- A Lambertian plane: every path adds albedo / pi, so every point of every incidence is exactly
  albedo / pi with zero spread, also for each albedo of a list traced together.
- The medium's order 1 is c p(-wi . wo) / (mu_i + mu_o); the isotropic medium, all orders, is
  ``rte_isotropic`` (exact); Lambertian V-cavities' order 1 is ``interfaced_lambert`` at eta = 1
  with the Torrance-Sparrow (V-groove) G.
- Points averaged over a cell by its quadrature nodes equal the binned cell (spheres,
  micrograins, V-cavities; order 1 and all orders).

The points of a table share their paths, so their errors are correlated: the statistic over the
points is Hotelling's T^2 of the per-realization deviations (the chi-square of correlated
estimates), (R - K) / (K (R - 1)) T^2 ~ F(K, R - K) for K points and R realizations when the
simulation has the model's mean; the test asserts it inside the two-sided 99.9 % bounds, for
each incidence.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from microsim import config, models, tables
from microsim.app import session
from microsim.core.orders import ORDERS
from microsim.physics.phase import phase_lambert_sphere
from microsim.run.plan import Plan
from microsim.testing import trace_realizations
from microsim.tracer.estimators.points import PointSet

#: two-sided level of the Hotelling bounds
ALPHA = 1e-3


def per_realization(cfg: dict):
    """(plan, every realization's estimates by name) of the config dict ``cfg``."""
    return trace_realizations(config.validate(cfg))


def points_of(plan) -> PointSet:
    """The points a run's config asks for."""
    return PointSet.of(plan.config.sensor.directions_deg, plan.config.sensor.retro_points_deg)


def hotelling(deviations: np.ndarray) -> tuple[float, float, float]:
    """(F statistic, lower, upper bound) of Hotelling's test that the rows of ``deviations``
    (R realizations x K) have mean 0 (module doc), in the span of the directions in which they
    vary: estimates at points can be (nearly) linearly related (on a Lambertian facet seen by
    every point, n . wo is linear in wo), and along a relation whose variance is below 1e-9 of
    the largest, the mean must lie within 5 of its standard errors (plus 1e-9, the rounding of
    an exact relation) instead."""
    r = len(deviations)
    mean = deviations.mean(axis=0)
    spread, axes = np.linalg.eigh(np.atleast_2d(np.cov(deviations, rowvar=False)))
    kept = spread > 1e-9 * spread.max()
    along = axes.T @ mean
    limit = 5.0 * np.sqrt(np.maximum(spread[~kept], 0.0) / r) + 1e-9
    assert np.all(np.abs(along[~kept]) < limit), f"a relation between the points broken in the mean: {along[~kept]}"
    k = int(kept.sum())
    t2 = r * np.sum(along[kept] ** 2 / spread[kept])
    f = (r - k) / (k * (r - 1)) * t2
    return f, stats.f.ppf(ALPHA / 2, k, r - k), stats.f.ppf(1 - ALPHA / 2, k, r - k)


def assert_mean(deviations: np.ndarray, what: str) -> None:
    """Hotelling's test over the points of each incidence of ``deviations`` (R, n_i, K)."""
    for i in range(deviations.shape[1]):
        f, lo, hi = hotelling(deviations[:, i])
        assert lo < f < hi, f"{what}, incidence {i}: Hotelling F = {f:.3g} outside ({lo:.3g}, {hi:.3g})"


# ------------------------------------------------------------------ the plane: exact, zero spread


def test_a_lambertian_plane_is_albedo_over_pi_at_every_point_with_zero_spread(tmp_path):
    cfg = {"scene": {"kind": "plane"}, "material": {"kind": "lambert", "albedo": [0.35, 0.8]},
           "illumination": {"theta_i_deg": [0.0, 40.0, 85.0, 20.0], "phi_i_deg": [0.0, 30.0, 200.0, 90.0]},
           "sensor": {"cells": 50, "directions_deg": [[0, 0], [30, 45], [60, 180], [89, 270], [75, -120]],
                      "retro_points_deg": [0.0, 3.0, 60.0]},
           "run": {"paths": 64_000}}  # 32 realizations: equal values summed 32 times
    outcome = session.run(cfg, tmp_path / "plane.h5")
    for albedo, path in zip((0.35, 0.8), outcome.tables):
        table = tables.load(path)
        points, order = table.arrays["brdf_points"], table.arrays["brdf_points_order"]
        assert points.shape == (4, 8)
        np.testing.assert_allclose(points, albedo / math.pi, rtol=1e-12)
        np.testing.assert_allclose(order[:, 0], albedo / math.pi, rtol=1e-12)
        assert not order[:, 1:].any()
        assert not table.arrays["brdf_points_stderr"].any() and not table.arrays["brdf_points_covariance"].any()
        assert table.attrs["points_delta_lobes"] == ""


def test_the_points_are_where_the_config_puts_them(tmp_path):
    """Directions at phi_i + phi_o (also at normal incidence, where wi has no azimuth); retro
    points turned by gamma towards the normal, past it on the specular side."""
    cfg = {"scene": {"kind": "plane"}, "material": {"kind": "lambert", "albedo": 0.5},
           "illumination": {"theta_i_deg": [0.0, 30.0], "phi_i_deg": [45.0, 90.0]},
           "sensor": {"cells": 50, "directions_deg": [[60, 180]], "retro_points_deg": [10.0, 50.0]},
           "run": {"paths": 100, "realizations": 2}}
    table = tables.load(session.run(cfg, tmp_path / "where.h5").tables[0])
    deg = {name: np.degrees(table.arrays[f"sensor/points_{name}"]) for name in ("theta", "phi", "gamma")}
    np.testing.assert_allclose(deg["theta"], [[60, 10, 50], [60, 20, 20]], atol=1e-12)
    np.testing.assert_allclose(deg["phi"], [[180, 180, 180], [180, 0, 180]], atol=1e-12)
    np.testing.assert_allclose(deg["gamma"][:, 1:], [[10, 50], [10, 50]], atol=1e-9)
    direction = table.arrays["sensor/points_direction"]
    azimuth = np.degrees(np.arctan2(direction[..., 1], direction[..., 0])) % 360
    np.testing.assert_allclose(azimuth[:, 0], [225, 270], atol=1e-9)


# ------------------------------------------------------------------------------- the medium


def medium_config(phase: str, max_order: int, paths: int, realizations: int, seed: int = 3) -> dict:
    return {"scene": {"kind": "halfspace_medium", "phase": phase}, "material": {"kind": "lambert", "albedo": 0.9},
            "illumination": {"theta_i_deg": [0.0, 45.0, 80.0], "phi_i_deg": [0.0, 30.0, 0.0]},
            "sensor": {"cells": 20, "directions_deg": [[0, 0], [30, 0], [30, 90], [60, 180], [60, 45], [85, 0],
                                                       [85, 180], [45, 300]],
                       "retro_points_deg": [0.0, 2.0, 20.0]},
            "run": {"paths": paths, "realizations": realizations, "seed": seed, "max_order": max_order}}


@pytest.mark.slow  # 2.4 M paths
def test_the_media_order_1_is_c_p_over_mu_i_plus_mu_o_at_every_point():
    plan, est = per_realization(medium_config("lambert_sphere", 1, 800_000, 40))
    points = est["brdf_points"][:, :, 0]  # order 1: (R, n_i, K)
    asked = points_of(plan)
    exact = np.zeros(points.shape[1:])
    for i in range(plan.n_incidences):
        wi = plan.incidence_direction(i)
        wo = asked.directions(wi, plan.phi_i[i])
        exact[i] = 0.9 * phase_lambert_sphere(-(wo @ wi)) / (wi[2] + wo[:, 2])
    assert_mean((points - exact) / exact, "order 1 against c p / (mu_i + mu_o)")
    assert not est["brdf_points"][:, :, 1:ORDERS].any()  # max_order = 1: nothing beyond order 1


@pytest.mark.slow  # 3.6 M paths
def test_the_isotropic_media_points_are_rte_isotropic_at_every_point():
    plan, est = per_realization(medium_config("isotropic", 0, 1_200_000, 40))
    points = est["brdf_points"][:, :, ORDERS]  # all orders (the row after the four orders)
    asked = points_of(plan)
    model = models.create("rte_isotropic", albedo=0.9)
    exact = np.array([model(np.broadcast_to(plan.incidence_direction(i), (len(asked), 3)),
                            asked.directions(plan.incidence_direction(i), plan.phi_i[i]))
                      for i in range(plan.n_incidences)])
    assert_mean((points - exact) / exact, "all orders against rte_isotropic")


# ------------------------------------------------------------------------------- V-cavities


@pytest.mark.slow  # 1.8 M paths
def test_lambertian_v_cavities_order_1_is_interfaced_lambert_at_eta_1_with_the_v_groove_g():
    cfg = {"scene": {"kind": "vcavities", "distribution": "beckmann", "roughness": 0.6},
           "material": {"kind": "lambert", "albedo": 0.8},
           "illumination": {"theta_i_deg": [0.0, 50.0, 80.0]},
           "sensor": {"cells": 20, "directions_deg": [[0, 0], [30, 0], [40, 90], [60, 180], [70, 30], [85, 0],
                                                      [85, 180]],
                      "retro_points_deg": [0.0, 5.0]},
           "run": {"paths": 600_000, "realizations": 40, "seed": 5, "max_order": 1}}
    plan, est = per_realization(cfg)
    points = est["brdf_points"][:, :, 0]
    asked = points_of(plan)
    model = models.create("interfaced_lambert", albedo=0.8, eta=1.0, roughness=0.6, distribution="beckmann",
                          gaf="torrance_sparrow")
    exact = np.array([model(np.broadcast_to(plan.incidence_direction(i), (len(asked), 3)),
                            asked.directions(plan.incidence_direction(i), plan.phi_i[i]))
                      for i in range(plan.n_incidences)])
    assert_mean((points - exact) / exact, "order 1 against interfaced_lambert (eta 1, Torrance-Sparrow G)")


# ------------------------------------------------------------------------ points against cells

SCENES = {
    "spheres": ({"kind": "poisson_spheres", "volume_fraction": 0.3}, {"kind": "lambert", "albedo": 0.8}, None),
    "micrograins": ({"kind": "micrograins", "tau0": 0.6, "beta": 1.0}, {"kind": "lambert", "albedo": 0.8},
                    {"kind": "lambert", "albedo": 0.5}),
    "vcavities": ({"kind": "vcavities", "roughness": 0.7}, {"kind": "lambert", "albedo": 0.8}, None),
}


@pytest.mark.parametrize("scene", SCENES)
def test_points_averaged_over_a_cell_are_the_binned_cell(scene):
    """Two cells of a 30-cell sensor (25 deg wide, away from the retro peak), each averaged over
    3 x 3 Gauss-Legendre nodes with the cos weight (Sensor.cell_quadrature): the mean of the
    points equals the cell's binned f, order 1 and all orders, realization by realization
    (the two estimates share their paths: their difference is tested)."""
    from microsim.tracer.sensor import Sensor

    sensor = Sensor.build(30)
    cells = sensor.lookup(np.array([[math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)]
                                    for t, p in np.radians([[60.0, 150.0], [22.0, 230.0]])]))
    nodes, weights = sensor.cell_quadrature(3, 3, cells)
    theta = np.degrees(np.arccos(nodes[..., 2]))
    phi = np.degrees(np.arctan2(nodes[..., 1], nodes[..., 0]))
    shape, material, base = SCENES[scene]
    cfg = {"scene": shape, "material": material, "illumination": {"theta_i_deg": [30.0]},
           "sensor": {"cells": 30, "directions_deg": np.stack([theta, phi], -1).reshape(-1, 2).tolist()},
           "run": {"paths": 320_000, "realizations": 32, "seed": 7}}
    if base is not None:
        cfg["base"] = base
    plan, est = per_realization(cfg)
    assert plan.sensor.n_cells == sensor.n_cells
    points = est["brdf_points"][:, 0].reshape(plan.realizations, ORDERS + 1, len(cells), -1)
    averaged = np.sum(points * weights, axis=-1)  # (R, rows, cells)
    binned = est["brdf"][:, 0][:, :, cells]
    rows = [0, ORDERS]  # order 1; all orders (the row after the orders in both estimators)
    deviation = (averaged[:, rows] - binned[:, rows]) / binned[:, rows].mean(axis=0)
    assert_mean(deviation.reshape(plan.realizations, 1, -1), f"{scene}: points averaged over cells against the cells")


# --------------------------------------------------------------------------------- reciprocity

RECIPROCAL_THETA = (15.0, 35.0, 55.0, 75.0)


@pytest.mark.slow  # 1.6 M paths a scene
@pytest.mark.parametrize("scene", ["spheres", "anisotropic micrograins"])
def test_points_are_reciprocal_at_exact_directions(scene, tmp_path):
    """Incidences and points are the same 8 directions (theta in RECIPROCAL_THETA, azimuth 30
    and 210 deg: a plane that is no symmetry plane of the anisotropic grains): f(a -> b) and
    f(b -> a), two incidences' estimates, agree within 4.5 combined standard errors."""
    shapes = {"spheres": SCENES["spheres"],
              "anisotropic micrograins": ({"kind": "micrograins", "tau0": 0.6, "beta_x": 0.6, "beta_y": 1.6},
                                          {"kind": "lambert", "albedo": 0.8}, {"kind": "lambert", "albedo": 0.5})}
    shape, material, base = shapes[scene]
    incidences = [(t, p) for p in (30.0, 210.0) for t in RECIPROCAL_THETA]
    cfg = {"scene": shape, "material": material,
           "illumination": {"theta_i_deg": [t for t, _ in incidences], "phi_i_deg": [p for _, p in incidences]},
           "sensor": {"cells": 20, "directions_deg": [[t, p] for p in (0.0, 180.0) for t in RECIPROCAL_THETA]},
           "run": {"paths": 200_000, "realizations": 16, "seed": 9}}
    if base is not None:
        cfg["base"] = base
    table = tables.load(session.run(cfg, tmp_path / "reciprocal.h5").tables[0])
    value, stderr = table.arrays["brdf_points"], table.arrays["brdf_points_stderr"]
    index = {direction: k for k, direction in enumerate(incidences)}
    point_of = {}  # (incidence a, incidence b) -> the point of incidence a at b's direction
    for a, (theta_a, phi_a) in enumerate(incidences):
        for k, (theta, relative) in enumerate(cfg["sensor"]["directions_deg"]):
            point_of[a, index[theta, (phi_a + relative) % 360.0]] = k
    mu_o = np.cos(np.radians([theta for theta, _ in cfg["sensor"]["directions_deg"]]))

    def worst_z(weight):  # of weight(point) x f: 1 is reciprocal; mu_o is not (the test's power)
        return max(abs(weight[point_of[a, b]] * value[a, point_of[a, b]]
                       - weight[point_of[b, a]] * value[b, point_of[b, a]])
                   / math.hypot(weight[point_of[a, b]] * stderr[a, point_of[a, b]],
                                weight[point_of[b, a]] * stderr[b, point_of[b, a]])
                   for a in range(len(incidences)) for b in range(a + 1, len(incidences)))

    assert len(point_of) == 64
    assert worst_z(np.ones_like(mu_o)) < 4.5, f"{scene}: worst reciprocity z {worst_z(np.ones_like(mu_o)):.2f}"
    assert worst_z(mu_o) > 4.5  # f cos(theta_o) is not reciprocal, and the table shows it


# ------------------------------------------------------------------- backends and bad input


def test_the_embreex_backend_sees_what_the_direct_one_sees(tmp_path):
    """The embreex backend queues its shadow rays and traces them after each pass (wrapping at
    the tile's sides); the direct one asks Embree at the event: the same paths give the same
    point estimates, to the rounding of the order in which they are added. The points are
    grazing enough that shadow rays cross the small tile's sides."""
    cfg = {"scene": {"kind": "poisson_spheres", "volume_fraction": 0.3, "subdivisions": 1, "tile": 6.0, "depth": 8.0},
           "material": {"kind": "lambert", "albedo": 0.8}, "illumination": {"theta_i_deg": [20.0, 70.0]},
           "sensor": {"cells": 20, "directions_deg": [[0, 0], [50, 90], [80, 180], [88, 30]],
                      "retro_points_deg": [0.0, 4.0]},
           "run": {"paths": 20_000, "realizations": 2}}
    points = {}
    for backend in ("direct", "embreex"):
        table = tables.load(session.run(cfg, tmp_path / f"{backend}.h5", backend=backend).tables[0])
        points[backend] = table.arrays["brdf_points_order"]
    assert points["direct"][:, :2].min() > 0
    np.testing.assert_allclose(points["embreex"], points["direct"], rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize("sensor, key", [
    ("directions_deg = [[90.0, 0.0]]", "sensor.directions_deg[0]"),
    ("directions_deg = [[30.0, 0.0], [-1.0, 0.0]]", "sensor.directions_deg[1]"),
    ("directions_deg = [[30.0]]", "sensor.directions_deg[0]"),
    ("directions_deg = [30.0, 0.0]", "sensor.directions_deg[0]"),
    ("directions_deg = [[30.0, 400.0]]", "sensor.directions_deg[0]"),
    ("retro_points_deg = [0.0, 90.0]", "sensor.retro_points_deg[1]"),
    ("retro_points_deg = 2.0", "sensor.retro_points_deg"),
    ("directions_deg = [" + ", ".join(["[10.0, 0.0]"] * 200) + "]\nretro_points_deg = [1.0] * 57".replace(
        "[1.0] * 57", "[" + ", ".join(["1.0"] * 57) + "]"), "sensor.directions_deg: 200 directions_deg and 57"),
    ("retro_points_deg = [" + ", ".join(["0.2"] * 300) + "]", "sensor.retro_points_deg: 0 directions_deg and 300"),
])
def test_bad_points_are_refused_in_one_line(sensor, key, tmp_path, capsys):
    from microsim.testing.refusals import SMALL_RUN, assert_run_refused

    assert_run_refused("[scene]\nkind = \"plane\"\n" + SMALL_RUN.replace("cells = 100", "cells = 100\n" + sensor),
                       key, tmp_path, capsys)


@pytest.mark.parametrize("materials", [
    '[material]\nkind = "mirror"\n',
    '[material]\nkind = "conductor"\neta = 0.2\nk = 3.0\n',
])
def test_points_on_a_scene_of_delta_lobes_only_are_refused(materials, tmp_path, capsys):
    from microsim.testing.refusals import SMALL_RUN, assert_run_refused

    rest = SMALL_RUN.replace('[material]\nkind = "lambert"\nalbedo = 0.8\n', materials)
    assert_run_refused('[scene]\nkind = "vcavities"\nroughness = 0.5\n' + rest.replace(
        "cells = 100", "cells = 100\nretro_points_deg = [0.0]"), "sensor.retro_points_deg", tmp_path, capsys)


def test_the_table_names_the_delta_lobes_it_leaves_out(tmp_path):
    """Mirror spheres on a Lambertian base: the points see the base (and not the mirrors'
    reflections), and the table says so."""
    cfg = {"scene": {"kind": "micrograins", "tau0": 0.5, "beta": 1.0}, "material": {"kind": "mirror"},
           "base": {"kind": "interfaced_lambert", "albedo": 0.6, "eta": 1.5},
           "illumination": {"theta_i_deg": [30.0]}, "sensor": {"cells": 20, "directions_deg": [[10.0, 0.0]]},
           "run": {"paths": 2_000, "realizations": 2}}
    table = tables.load(session.run(cfg, tmp_path / "delta.h5").tables[0])
    assert table.attrs["points_delta_lobes"] == ("material (mirror): its mirror reflection; base (interfaced_lambert): "
                                                 "the mirror reflection of its smooth interface")
    assert table.arrays["brdf_points"][0, 0] > 0


def test_the_table_keeps_the_covariance_of_its_points(tmp_path):
    """brdf_points_covariance is the covariance of the realizations' estimates over their
    number (the points share paths: strongly correlated in the medium), its diagonal the
    squared standard errors; the realizations traced one by one give the same."""
    cfg = medium_config("lambert_sphere", 0, 40_000, 8)
    table = tables.load(session.run(cfg, tmp_path / "covariance.h5").tables[0])
    _, est = per_realization(cfg)
    for name, values in (("brdf_points", est["brdf_points"][:, :, ORDERS]),
                         ("brdf_points_order", est["brdf_points"][:, :, :ORDERS])):
        covariance = table.arrays[f"{name}_covariance"]
        expected = np.stack([[np.cov(values[:, i, k], rowvar=False) for k in range(values.shape[2])]
                             if values.ndim == 4 else np.cov(values[:, i], rowvar=False)
                             for i in range(values.shape[1])]) / len(values)
        np.testing.assert_allclose(covariance, expected, rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(np.sqrt(np.diagonal(covariance, axis1=-2, axis2=-1)),
                                   table.arrays[f"{name}_stderr"], rtol=1e-9)


def test_every_albedo_of_a_list_has_the_points_of_its_own_run(tmp_path):
    """An albedo list traces at the largest and scales each event of order k by (c_j / c_max)^k,
    as exits are: the largest albedo's points are the single run's bit for bit, and a smaller
    one's equal its own run within 4.5 combined standard errors at every point (all orders of
    the Lambert-sphere medium: the scaling reaches high orders)."""
    cfg = medium_config("lambert_sphere", 0, 64_000, 16)
    joint = session.run({**cfg, "material": {"kind": "lambert", "albedo": [0.5, 0.9]}}, tmp_path / "joint.h5")
    for albedo, path in zip((0.5, 0.9), joint.tables):
        alone = tables.load(session.run({**cfg, "material": {"kind": "lambert", "albedo": albedo}},
                                        tmp_path / f"alone{albedo}.h5").tables[0])
        together = tables.load(path)
        a, b = (t.arrays["brdf_points_order"] for t in (alone, together))
        if albedo == 0.9:
            assert np.array_equal(a, b)
        else:
            se = np.hypot(alone.arrays["brdf_points_order_stderr"], together.arrays["brdf_points_order_stderr"])
            assert np.all(np.abs(a - b) < 4.5 * se + 1e-300) and b[:, 3].min() > 0


def test_a_run_with_points_or_rings_takes_the_kernel_a_run_without_them_compiled():
    """numba specializes the tracer on the estimators' records and setups: a run with points
    gave them a record type of their own, and its first run compiled a second tracer as long as
    the first (11 s here, 51 s on a slower host). Every run now hands the kernels the same types,
    with points or retro rings or neither, so the kernel one compiled is the others'; without
    points or rings nothing of theirs is written."""
    import numba

    from microsim.tracer import estimators

    base = {"scene": {"kind": "poisson_spheres", "volume_fraction": 0.3},
            "material": {"kind": "lambert", "albedo": 0.8},
            "illumination": {"theta_i_deg": [30.0]}, "run": {"paths": 1000}}
    plans = [Plan.from_config(config.validate({**base, "sensor": sensor}))
             for sensor in ({"cells": 100}, {"cells": 100, "directions_deg": [[0.0, 0.0]], "retro_points_deg": [1.0]},
                            {"cells": 100, "retro_rings": 5})]
    assert plans[0].estimator_names == plans[1].estimator_names == plans[2].estimator_names
    types = []
    for plan in plans:
        records = tuple(estimator.allocate(4, 1) for estimator in plan.estimators)
        setups = estimators.setups(plan.estimators, plan.incidence_direction(0), plan.phi_i[0])
        types.append((numba.typeof(records), numba.typeof(setups)))
    assert types[0] == types[1] == types[2]
