"""The packings' structure against the theory of hard spheres: the pair correlation g(r) of the
equilibrium fluid, Percus-Yevick's at phi 0.1-0.3 and Verlet and Weis's correction of it at 0.3
within the errors (Hotelling's test on the realizations), the correction within 2.5 % at 0.4; at 0.4 the packing's contact shell
above Percus-Yevick's, as the fluid's is (Percus-Yevick's deficit at contact: 3.33 against
Carnahan-Starling's 3.70 at eta = 0.4); and the first peak's rise from 0.4 to 0.6."""

import functools
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
from microsim.testing.bounds import hotelling_f, hotelling_interval

PACKED = geometry.SCENES["packed_spheres"]
#: the fluid's tests: realizations and the cubic box's edge (radii); g(r) measured in bins of 0.1
#: radii from contact to 10 radii, merged into the bins each test takes (by their shells' volume)
FLUID_REALIZATIONS, FLUID_BOX, FINE_EDGES = 24, 24.0, np.linspace(2.0, 10.0, 81)
#: Hotelling's bins (indices into FINE_EDGES): finest at contact, out to 6 radii, ten in all
#: (fewer than the realizations, so that their covariance can be estimated)
HOTELLING_BINS = (0, 1, 2, 4, 7, 10, 15, 20, 25, 30, 40)
#: the dense packings' tests
DENSE_REALIZATIONS, DENSE_BOX, DENSE_EDGES = 12, 16.0, np.linspace(2.0, 7.0, 26)


@functools.lru_cache(maxsize=None)
def measured_g(phi: float, box: float, edges: tuple, realizations: int) -> np.ndarray:
    """(realizations, bins): g(r) of each realization's packing in a cubic ``box`` (tile = depth)."""
    cfg = config.validate({"scene": {"kind": "packed_spheres", "volume_fraction": phi, "tile": box, "depth": box},
                           "material": {"kind": "lambert", "albedo": 0.8}, "illumination": {"theta_i_deg": [0.0]},
                           "run": {"paths": 1000}})
    resolved = PACKED.resolve(cfg)
    return np.array([pair_correlation(PACKED.draw(resolved, geometry_rng(3, r), PACKED.cache_directory(cfg)).centres,
                                      (box, box, box), np.array(edges)) for r in range(realizations)])


def fluid_g(phi: float, bins) -> tuple[np.ndarray, np.ndarray]:
    """(g (realizations, bins), edges): the fluid test's g(r), merged into the FINE_EDGES indices ``bins``."""
    fine = measured_g(phi, FLUID_BOX, tuple(FINE_EDGES), FLUID_REALIZATIONS)
    shells = np.diff(FINE_EDGES**3)
    merged = [(fine[:, a:b] * shells[a:b]).sum(axis=1) / shells[a:b].sum() for a, b in zip(bins[:-1], bins[1:])]
    return np.stack(merged, axis=1), FINE_EDGES[list(bins)]


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


@pytest.mark.parametrize("phi, theory, accepted", [
    (0.1, percus_yevick_g, True), (0.2, percus_yevick_g, True), (0.3, percus_yevick_g, True),
    (0.3, verlet_weis_g, True), (0.4, percus_yevick_g, False)],
    ids=["0.1 Percus-Yevick", "0.2 Percus-Yevick", "0.3 Percus-Yevick", "0.3 Verlet-Weis", "0.4 Percus-Yevick fails"])
def test_the_fluid_packings_follow_the_fluid_s_g_within_their_errors(phi, theory, accepted):
    """Twenty-four realizations (a cube of 24 radii), g(r) in ten shells from contact to 6 radii
    (0.1 radius wide at contact, 1 radius at the last): Hotelling's F of the realizations against
    the theory's shell averages, with the realizations' covariance (neighbouring shells of one
    realization are anticorrelated, -0.2 to -0.4), within its two-sided 99 % interval F(10, 14),
    0.18-4.60. Measured: Percus-Yevick 0.34, 2.43, 3.60 at 0.1, 0.2, 0.3 and Verlet-Weis 1.62 at
    0.3; at 0.4 Percus-Yevick's contact deficit is rejected (F = 43.6)."""
    g, edges = fluid_g(phi, HOTELLING_BINS)
    f = hotelling_f(g, shell_average(lambda r: theory(r, phi, 2.0), edges))
    lo, hi = hotelling_interval(len(edges) - 1, FLUID_REALIZATIONS)
    assert (lo <= f <= hi) == accepted, (f, lo, hi)


def test_at_phi_0_4_verlet_weis_is_within_2_5_percent_of_every_shell():
    """At 0.4 every shell of 0.2 radii from contact to 10 radii is within 2.5 % of the correction,
    where Percus-Yevick's first shells are 4 % off or more (the contact shell 4.2 % high, the third
    4.9 % low). A bound on the model, not a statistical one: measured, the largest gap is 2.0 %
    (the first minimum), and Hotelling's F against the correction in the ten shells of the fluid
    test is 4.98, just beyond its interval's 4.60: the packings resolve the correction's own error."""
    mean = fluid_g(0.4, tuple(range(0, 81, 2)))[0].mean(axis=0)
    edges = FINE_EDGES[::2]
    corrected, plain = (shell_average(lambda r, g=g: g(r, 0.4, 2.0), edges) for g in (verlet_weis_g, percus_yevick_g))
    assert np.max(np.abs(mean / corrected - 1)) < 0.025, np.round(mean / corrected - 1, 3)
    assert np.max(np.abs(mean / plain - 1)) > 0.04


def test_at_phi_0_4_the_contact_shell_is_above_percus_yevick_s():
    """The first shell (contact to 0.1 diameter beyond) of twelve realizations (a cube of 16
    radii) lies above Percus-Yevick's by more than five errors, and by less than Carnahan-Starling's
    contact value exceeds Percus-Yevick's (11 %)."""
    mean, error = mean_and_error(measured_g(0.4, DENSE_BOX, tuple(DENSE_EDGES), DENSE_REALIZATIONS))
    theory = shell_average(lambda r: percus_yevick_g(r, 0.4, 2.0), DENSE_EDGES)
    carnahan_starling = (1 - 0.2) / (1 - 0.4) ** 3
    assert mean[0] - theory[0] > 5 * error[0], (mean[0], theory[0], error[0])
    assert mean[0] / theory[0] < carnahan_starling / contact_value(0.4)


def test_the_first_peak_rises_with_the_volume_fraction_to_0_6():
    """The first shell's g rises from phi = 0.4 through 0.5 to 0.6, each step by more than five
    standard errors (twelve realizations, a cube of 16 radii)."""
    peaks = [mean_and_error(measured_g(phi, DENSE_BOX, tuple(DENSE_EDGES), DENSE_REALIZATIONS)[:, :1])
             for phi in (0.4, 0.5, 0.6)]
    for (low, e_low), (high, e_high) in zip(peaks[:-1], peaks[1:]):
        assert high[0] - low[0] > 5 * math.hypot(e_low[0], e_high[0]), peaks
