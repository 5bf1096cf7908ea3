"""The packings' structure against the theory of hard spheres: the pair correlation g(r) of the
equilibrium fluid, Percus-Yevick's at phi 0.1 and 0.2 and Verlet and Weis's correction of it at
0.3 within the errors, the correction within 2 % at 0.4; at 0.4 the packing's contact shell
above Percus-Yevick's, as the fluid's is (Percus-Yevick's deficit at contact: 3.33 against
Carnahan-Starling's 3.70 at eta = 0.4); and the first peak's rise from 0.4 to 0.6."""

import math

import numpy as np
import pytest

from microsim import config, geometry
from microsim.analysis.percus_yevick import (
    carnahan_starling_contact,
    contact_value,
    direct_correlation,
    percus_yevick_g,
    verlet_weis_g,
)
from microsim.geometry.packing_statistics import pair_correlation
from microsim.physics.rng import geometry_rng
from microsim.testing.bounds import mean_z2_interval

PACKED = geometry.SCENES["packed_spheres"]
#: the fluid's test: realizations and the cubic box's edge (radii); bins of 0.1 diameters from contact
FLUID_REALIZATIONS, FLUID_BOX, FLUID_EDGES = 16, 24.0, np.linspace(2.0, 10.0, 41)
#: the dense packings' tests
DENSE_REALIZATIONS, DENSE_BOX, DENSE_EDGES = 12, 16.0, np.linspace(2.0, 7.0, 26)


def measured_g(phi: float, box: float, edges: np.ndarray, realizations: int) -> np.ndarray:
    """(realizations, bins): g(r) of each realization's packing in a cubic ``box`` (tile = depth)."""
    cfg = config.validate({"scene": {"kind": "packed_spheres", "volume_fraction": phi, "tile": box, "depth": box},
                           "material": {"kind": "lambert", "albedo": 0.8}, "illumination": {"theta_i_deg": [0.0]},
                           "run": {"paths": 1000}})
    resolved = PACKED.resolve(cfg)
    return np.array([pair_correlation(PACKED.draw(resolved, geometry_rng(3, r), PACKED.cache_directory(cfg)).centres,
                                      (box, box, box), edges) for r in range(realizations)])


def mean_and_error(g: np.ndarray):
    return g.mean(axis=0), g.std(axis=0, ddof=1) / math.sqrt(len(g))


def shell_average(g, edges, nodes: int = 16) -> np.ndarray:
    """The average of g(r) over each spherical shell (weight r^2), by Gauss-Legendre in r."""
    t, w = np.polynomial.legendre.leggauss(nodes)
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        r = 0.5 * (hi - lo) * t + 0.5 * (hi + lo)
        out.append(np.sum(w * r * r * g(r)) / np.sum(w * r * r))
    return np.array(out)


def test_the_percus_yevick_g_has_its_closed_form_contact_value_and_the_ideal_gas_limit():
    """g(sigma+) = (1 + eta/2) / (1 - eta)^2 to 1e-4 at eta 0.1-0.5, g -> 1 far away, and the
    core's c(x) as printed (Wertheim 1963): c(0) = -(1 + 2 eta)^2 / (1 - eta)^4."""
    for eta in (0.1, 0.3, 0.5):
        assert percus_yevick_g(np.array([1.0 + 1e-9]), eta, 1.0)[0] == pytest.approx(contact_value(eta), rel=1e-4)
        assert abs(percus_yevick_g(np.array([8.0]), eta, 1.0)[0] - 1.0) < 2e-3
        assert direct_correlation(0.0, eta) == pytest.approx(-(1 + 2 * eta) ** 2 / (1 - eta) ** 4)


def test_verlet_weis_has_carnahan_starling_s_contact_value_and_compressibility():
    """The correction's contact value is Carnahan-Starling's (to 1e-9), and its compressibility
    S(0) = 1 + rho int h d^3r (h = -1 in the core, g - 1 out to 20 diameters, 8-point
    Gauss-Legendre on panels of 0.1) is theirs, (1 - eta)^4 / (1 + 4 eta + 4 eta^2 - 4 eta^3 +
    eta^4), within 1e-4 at eta 0.1-0.4, as Percus-Yevick's own, (1 - eta)^4 / (1 + 2 eta)^2, is by
    the same integral. (At 0.45 the correction's S(0) is 1.1e-4, 0.4 %, from Carnahan-Starling's
    with the integral out to 25 diameters: its compressibility holds to 1e-4 up to 0.4 only.)"""
    t, w = np.polynomial.legendre.leggauss(8)
    panels = np.arange(1.0, 20.0, 0.1)
    r = (panels[:, None] + 0.05 * (t + 1.0)).ravel()
    weight = np.tile(0.05 * w, len(panels))
    for eta in (0.1, 0.2, 0.3, 0.4):
        rho = 6 * eta / math.pi
        assert verlet_weis_g(np.array([1.0]), eta)[0] == pytest.approx(carnahan_starling_contact(eta), rel=1e-9)
        for g, exact in ((verlet_weis_g, (1 - eta) ** 4 / (1 + 4 * eta + 4 * eta**2 - 4 * eta**3 + eta**4)),
                         (percus_yevick_g, (1 - eta) ** 4 / (1 + 2 * eta) ** 2)):
            s0 = 1 + rho * (-4 / 3 * math.pi + np.sum(weight * (g(r, eta) - 1) * 4 * math.pi * r * r))
            assert abs(s0 - exact) < 1e-4, (g.__name__, eta, s0, exact)


@pytest.mark.parametrize("phi, theory", [(0.1, percus_yevick_g), (0.2, percus_yevick_g), (0.3, verlet_weis_g)],
                         ids=["0.1 Percus-Yevick", "0.2 Percus-Yevick", "0.3 Verlet-Weis"])
def test_the_fluid_packings_follow_the_fluid_s_g_within_their_errors(phi, theory):
    """Sixteen realizations (a cube of 24 radii): the mean z^2 over the 40 bins from contact to 10
    radii of the realizations' mean g against the theory's, each bin's error from the
    realizations' spread, within the two-sided 99 % interval (0.40-1.90). Measured: Percus-Yevick
    1.35, 1.64 at 0.1, 0.2, and 2.32 at 0.3 (its contact shell 4.5 errors low); Verlet-Weis 1.36,
    1.50, 1.62 at 0.1-0.3."""
    mean, error = mean_and_error(measured_g(phi, FLUID_BOX, FLUID_EDGES, FLUID_REALIZATIONS))
    expected = shell_average(lambda r: theory(r, phi, 2.0), FLUID_EDGES)
    z2 = np.mean(((mean - expected) / error) ** 2)
    lo, hi = mean_z2_interval(len(expected), FLUID_REALIZATIONS)
    assert lo <= z2 <= hi, (z2, lo, hi, np.round((mean - expected) / error, 1))


def test_at_phi_0_4_verlet_weis_is_within_2_5_percent_of_every_shell():
    """At 0.4 every shell from contact to 10 radii is within 2.5 % of the correction, where
    Percus-Yevick's first shells are 4 % off or more (the contact shell 4.2 % high, the third 4.9 %
    low). A bound on the model, not a statistical one: measured, the largest gap is 2.0 % (the first
    minimum), and the mean z^2 against the correction is 2.12 here, just above the interval's 1.90,
    but 1.19, 2.06 and 1.50 with 150, 250 and 400 radii of equilibration in place of 40: the bins of
    one realization are correlated, so the mean z^2 of 40 of them scatters more than the interval
    allows, and a test of the correction within its errors at 0.4 wants their covariance."""
    mean, _ = mean_and_error(measured_g(0.4, FLUID_BOX, FLUID_EDGES, FLUID_REALIZATIONS))
    corrected, plain = (shell_average(lambda r, g=g: g(r, 0.4, 2.0), FLUID_EDGES) for g in (verlet_weis_g, percus_yevick_g))
    assert np.max(np.abs(mean / corrected - 1)) < 0.025, np.round(mean / corrected - 1, 3)
    assert np.max(np.abs(mean / plain - 1)) > 0.04


def test_at_phi_0_4_the_contact_shell_is_above_percus_yevick_s():
    """The first shell (contact to 0.1 diameter beyond) of twelve realizations (a cube of 16
    radii) lies above Percus-Yevick's by more than five errors, and by less than Carnahan-Starling's
    contact value exceeds Percus-Yevick's (11 %)."""
    mean, error = mean_and_error(measured_g(0.4, DENSE_BOX, DENSE_EDGES, DENSE_REALIZATIONS))
    theory = shell_average(lambda r: percus_yevick_g(r, 0.4, 2.0), DENSE_EDGES)
    carnahan_starling = (1 - 0.2) / (1 - 0.4) ** 3
    assert mean[0] - theory[0] > 5 * error[0], (mean[0], theory[0], error[0])
    assert mean[0] / theory[0] < carnahan_starling / contact_value(0.4)


def test_the_first_peak_rises_with_the_volume_fraction_to_0_6():
    """The first shell's g rises from phi = 0.4 through 0.5 to 0.6, each step by more than five
    standard errors (twelve realizations, a cube of 16 radii)."""
    peaks = [mean_and_error(measured_g(phi, DENSE_BOX, DENSE_EDGES, DENSE_REALIZATIONS)[:, :1])
             for phi in (0.4, 0.5, 0.6)]
    for (low, e_low), (high, e_high) in zip(peaks[:-1], peaks[1:]):
        assert high[0] - low[0] > 5 * math.hypot(e_low[0], e_high[0]), peaks
