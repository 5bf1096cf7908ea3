"""Materials on a flat plane, where their answers are exact."""

import numpy as np
import pytest

from microsim.physics.fresnel import fresnel_conductor, fresnel_dielectric
from microsim.tracer.materials import MATERIALS, Absorber, Conductor, Lambert, codes, row_length, scatter
from microsim.tracer.scene import MaterialTable


def plane(material, theta, paths=200_000, cells=400):
    return {
        "scene": {"kind": "plane"}, "material": material,
        "illumination": {"theta_i_deg": theta}, "sensor": {"cells": cells},
        "run": {"paths": paths, "realizations": 64, "seed": 2},
    }


def test_conductor_plane_is_a_mirror_with_fresnel_weight(simulate):
    t = simulate(plane({"kind": "conductor", "eta": 0.2, "k": 3.0}, [0.0, 40.0, 75.0], paths=2000))
    for i, wi in enumerate(t.wi):
        mirror = t.sensor.lookup(np.array([[-wi[0], -wi[1], wi[2]]]))[0]
        nonzero = np.flatnonzero(t.brdf[i])
        assert list(nonzero) == [mirror]
        # the tracer stores rays in float32: the cosine it sees is that of the rounded direction
        assert t.albedo[i] == pytest.approx(fresnel_conductor(float(np.float32(wi[2])), 0.2, 3.0), rel=1e-12)


def test_white_interfaced_lambert_plane_returns_all_energy(simulate):
    t = simulate(plane({"kind": "interfaced_lambert", "albedo": 1.0, "eta": 1.5}, [0.0, 70.0, 89.0], paths=50_000))
    assert np.all(np.abs(t.albedo + t.truncated - 1.0) <= 1e-12)
    assert np.all(t.truncated < 1e-6)


def test_interfaced_lambert_at_eta_1_is_lambertian(simulate):
    t = simulate(plane({"kind": "interfaced_lambert", "albedo": 0.6, "eta": 1.0}, [30.0]))
    z = (t.brdf - 0.6 / np.pi) / t.brdf_stderr
    assert np.max(np.abs(z)) <= 4.5


def test_interfaced_lambert_diffuse_albedo_matches_the_flat_closed_form(simulate):
    """Directional albedo of a smooth dielectric over a Lambertian body (Meneveaux et al. 2015,
    Eq. 8-10): F(mu_i) + (1 - F(mu_i)) K (1 - r_i) / (1 - K r_i), with r_i the
    hemispherical reflectance of the interface seen from inside (quadrature here)."""
    eta, kd = 1.5, 0.7
    mu, w = np.polynomial.legendre.leggauss(400)
    mu = 0.5 * (mu + 1)
    r_inside = np.sum(w * 0.5 * 2 * mu * np.array([fresnel_dielectric(m, 1 / eta) for m in mu]))
    t = simulate(plane({"kind": "interfaced_lambert", "albedo": kd, "eta": eta}, [0.0, 60.0], paths=400_000))
    for i, wi in enumerate(t.wi):
        f = fresnel_dielectric(wi[2], eta)
        expected = f + (1 - f) * kd * (1 - r_inside) / (1 - kd * r_inside)
        assert abs(t.albedo[i] - expected) <= 4 * t.albedo_stderr[i]


def test_absorber_plane_returns_nothing(simulate):
    t = simulate(plane({"kind": "absorber"}, [20.0], paths=1000))
    assert t.albedo[0] == 0.0 and t.arrays["energy/absorbed"][0] == 1.0


def test_every_defined_material_has_a_scatter_branch():
    """scatter raises for a code it has no branch for: every registered kind must have one."""
    for name, definition in MATERIALS.items():
        row = np.full(row_length(), 0.5)
        direction, factor, cut = scatter(definition.code, row, np.zeros(1, np.uint64), 0, (0.0, 0.0, -1.0),
                                         (0.0, 0.0, 1.0))
        assert 0.0 <= factor <= 1.0 and 0.0 <= cut <= 1.0, name
    unknown = max(codes()) + 1
    with pytest.raises(ValueError, match="unknown material kind code"):
        scatter(unknown, np.zeros(row_length()), np.zeros(1, np.uint64), 0, (0.0, 0.0, -1.0), (0.0, 0.0, 1.0))


def test_an_unknown_material_code_is_refused_when_the_table_is_built():
    table = MaterialTable.of([Lambert(kind="lambert", albedo=0.5)])
    with pytest.raises(ValueError, match="material kind codes \\[99\\] unknown"):
        MaterialTable(np.array([99], np.int32), table.params)


def test_a_material_row_holds_the_parameters_in_declaration_order():
    table = MaterialTable.of([Conductor(kind="conductor", eta=0.2, k=3.0), Absorber(kind="absorber")])
    assert table.code.tolist() == [Conductor.code, Absorber.code]
    assert table.params.tolist() == [[0.2, 3.0, 0.0], [0.0, 0.0, 0.0]]  # rows as long as the longest kind's


def test_mirror_plane_sends_every_path_to_the_specular_cell_with_weight_1(simulate):
    t = simulate(plane({"kind": "mirror"}, [0.0, 40.0, 89.0], paths=2000))
    for i, wi in enumerate(t.wi):
        specular = t.sensor.lookup(np.array([[-wi[0], -wi[1], wi[2]]]))[0]
        assert list(np.flatnonzero(t.brdf[i])) == [specular]
    assert np.all(t.albedo == 1.0) and np.all(t.arrays["energy/absorbed"] == 0.0)


def test_a_closed_scene_of_mirror_spheres_over_a_mirror_base_returns_all_its_energy(simulate):
    t = simulate({
        "scene": {"kind": "poisson_spheres", "volume_fraction": 0.3, "tile": 16.0, "depth": 6.0},
        "material": {"kind": "mirror"}, "base": {"kind": "mirror"},
        "illumination": {"theta_i_deg": [0.0, 60.0, 85.0]}, "sensor": {"cells": 400},
        "run": {"paths": 20_000, "realizations": 4, "seed": 5},
    })
    a = t.arrays
    assert np.all(a["energy/absorbed"] == 0.0) and np.all(t.transmitted == 0.0)
    assert np.all(np.abs(t.albedo + t.truncated - 1.0) <= 1e-12)  # every path keeps weight 1
    assert np.all(t.brdf_order[:, 1:, :].sum(axis=(1, 2)) > 0)  # inter-reflections happen


def test_mirror_takes_no_parameters(simulate):
    from microsim import config

    with pytest.raises(config.ConfigError, match="material.eta: unknown key"):
        simulate(plane({"kind": "mirror", "eta": 1.5}, [0.0]))


# ------------------------------------------------- every kind: sampling against evaluate and pdf

#: p-values below this fail: 45 of them (5 kinds x 3 incidences x 3 statistics) stay above it
#: together with probability 0.995 for correct kernels (Sidak)
SMALLEST_P = 1e-4


@pytest.mark.parametrize("theta_i", [10.0, 45.0, 80.0])
@pytest.mark.parametrize("kind", sorted(MATERIALS))
def test_every_material_draws_what_its_pdf_says_and_weighs_what_it_evaluates(kind, theta_i):
    """Every registered kind passes the chi-square test of Mitsuba 3's chi2.py, with its
    ``example`` parameters, on a tilted shading normal (microsim.testing.material_check)."""
    from microsim.testing import material_check

    check = material_check(MATERIALS[kind].example_instance(), theta_i)
    assert check.smallest_p > SMALLEST_P, check


def _broken_samplers():
    """Samplers broken on purpose: a Lambertian drawn uniformly on the hemisphere (its pdf says
    cosine), and one whose weight is 5 % too large."""
    import math

    import numba

    from microsim.physics.rng import uniform
    from microsim.physics.sampling import from_local, sample_cosine

    @numba.njit
    def uniform_hemisphere(code, prm, states, i, d, n):
        c = uniform(states, i)
        s = math.sqrt(max(0.0, 1.0 - c * c))
        phi = 2.0 * math.pi * uniform(states, i)
        return from_local(s * math.cos(phi), s * math.sin(phi), c, n), prm[0], 0.0

    @numba.njit
    def heavy(code, prm, states, i, d, n):
        return sample_cosine(states, i, n), 1.05 * prm[0], 0.0

    return {"uniform hemisphere": uniform_hemisphere, "weight 5 % high": heavy}


@pytest.mark.parametrize("broken", ["uniform hemisphere", "weight 5 % high"])
def test_the_check_fails_a_material_whose_sampling_is_broken(broken):
    from microsim.testing import material_check

    check = material_check(MATERIALS["lambert"].example_instance(), 45.0, sample=_broken_samplers()[broken])
    assert check.smallest_p < 1e-12, check


def test_evaluate_and_pdf_of_the_flat_interfaced_lambertian_are_its_closed_form():
    """evaluate is the body term K_d T_i T_o / (pi eta^2 (1 - K_d r_i)) cos_o, with r_i by
    quadrature here; pdf is that of a white body (the bounces drawn without their albedo)."""
    import math

    import numba

    from microsim.tracer.materials import evaluate, pdf

    material = MATERIALS["interfaced_lambert"].model_validate({"kind": "interfaced_lambert", "albedo": 0.6, "eta": 1.4})
    row = np.array(material.row())
    critical = math.sqrt(1 - 1 / 1.4**2)  # below it, total internal reflection: F = 1
    x, w = np.polynomial.legendre.leggauss(200)
    t = 0.5 * (x + 1)
    mu = critical + (1 - critical) * t**2  # F - 1 goes as sqrt(mu - critical): smooth in t
    quadrature = np.sum(w * (1 - critical) * t * 2 * mu * np.array([fresnel_dielectric(m, 1 / 1.4) for m in mu]))
    r_i = critical**2 + quadrature
    assert row[2] == pytest.approx(r_i, rel=1e-12)
    n, wi = (0.0, 0.0, 1.0), (math.sin(0.5), 0.0, math.cos(0.5))
    wo = (-math.sin(1.1) * 0.6, math.sin(1.1) * 0.8, math.cos(1.1))
    body = (1 - fresnel_dielectric(wi[2], 1.4)) * (1 - fresnel_dielectric(wo[2], 1.4)) / (math.pi * 1.4**2)
    code = material.code
    call = numba.njit(lambda kernel, wi, wo: kernel(code, row, wi, wo, n))
    assert call(evaluate, wi, wo) == pytest.approx(0.6 * body / (1 - 0.6 * r_i) * wo[2], rel=1e-12)
    assert call(pdf, wi, wo) == pytest.approx(body / (1 - r_i) * wo[2], rel=1e-12)
    assert call(evaluate, wi, (0.0, 0.6, -0.8)) == 0.0 and call(pdf, (0.0, 0.6, -0.8), wo) == 0.0
