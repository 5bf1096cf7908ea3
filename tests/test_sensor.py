"""The sensor of docs/conventions.md §3: equal solid angles, exact cover, near-square cells, O(1) lookup."""

import numpy as np
import pytest

from microsim.tracer.sensor import Sensor


@pytest.mark.parametrize("cells", [1, 10, 100, 500, 3240, 10000])
def test_cells_cover_the_hemisphere_exactly_with_equal_solid_angle(cells):
    s = Sensor.build(cells)
    t_lo, t_hi, p_lo, p_hi = s.cell_bounds()
    omega = (p_hi - p_lo) * (np.cos(t_lo) - np.cos(t_hi))
    assert np.allclose(omega, 2 * np.pi / s.n_cells, rtol=1e-12, atol=0)
    assert np.allclose(s.solid_angle(), omega, rtol=1e-12)
    assert s.solid_angle().sum() == pytest.approx(2 * np.pi, rel=1e-14)
    assert s.projected_solid_angle().sum() == pytest.approx(np.pi, rel=1e-14)
    assert t_lo[0] == 0.0 and t_hi[-1] == pytest.approx(np.pi / 2, abs=1e-15)
    ring = s.ring_of_cell()
    assert np.all(t_hi[:-1][np.diff(ring) > 0] == t_lo[1:][np.diff(ring) > 0])  # rings abut
    for k in range(s.n_rings):  # each ring is cut evenly over the full circle
        widths = (p_hi - p_lo)[ring == k]
        assert widths.sum() == pytest.approx(2 * np.pi, rel=1e-13)
    assert abs(s.n_cells - cells) <= max(2, 0.01 * cells)


def test_projected_solid_angle_is_exact():
    s = Sensor.build(500)
    t_lo, t_hi, p_lo, p_hi = s.cell_bounds()
    x, w = np.polynomial.legendre.leggauss(20)
    for c in range(0, s.n_cells, 37):  # integral of cos(theta) sin(theta) by Gauss-Legendre
        t = t_lo[c] + (t_hi[c] - t_lo[c]) * 0.5 * (x + 1)
        integral = (p_hi[c] - p_lo[c]) * 0.5 * (t_hi[c] - t_lo[c]) * np.sum(w * np.cos(t) * np.sin(t))
        assert s.projected_solid_angle()[c] == pytest.approx(integral, rel=1e-12)


def test_cells_are_close_to_square():
    s = Sensor.build(3240)
    t_lo, t_hi, p_lo, p_hi = s.cell_bounds()
    ring = s.ring_of_cell()
    aspect = (t_hi - t_lo) / ((p_hi - p_lo) * np.sin(0.5 * (t_lo + t_hi)))
    assert np.all((aspect[ring > 0] > 0.8) & (aspect[ring > 0] < 1.25))


def test_lookup_returns_the_cell_whose_bounds_contain_the_direction():
    s = Sensor.build(3240)
    rng = np.random.default_rng(3)
    w = rng.normal(size=(100_000, 3))
    w[:, 2] = np.abs(w[:, 2])
    w /= np.linalg.norm(w, axis=1)[:, None]
    c = s.lookup(w)
    t_lo, t_hi, p_lo, p_hi = s.cell_bounds()
    theta = np.arccos(w[:, 2])
    phi = np.arctan2(w[:, 1], w[:, 0])
    assert np.all((theta >= t_lo[c] - 1e-12) & (theta <= t_hi[c] + 1e-12))
    assert np.all(np.mod(phi - p_lo[c], 2 * np.pi) <= (p_hi - p_lo)[c] + 1e-12)
    # uniform directions fill equal-solid-angle cells equally: chi-square over cells
    counts = np.bincount(c, minlength=s.n_cells)
    expected = len(w) / s.n_cells
    chi2 = np.sum((counts - expected) ** 2 / expected)
    dof = s.n_cells - 1
    assert abs(chi2 - dof) < 5 * np.sqrt(2 * dof)


def test_lookup_at_the_pole_the_horizon_and_the_seam():
    s = Sensor.build(3240)
    edge = np.array([[0, 0, 1.0], [1.0, 0, 1e-300], [np.cos(np.pi), np.sin(np.pi), 0.0], [-1.0, -1e-17, 1e-3]])
    c = s.lookup(edge / np.linalg.norm(edge, axis=1)[:, None])
    assert c[0] == 0
    assert np.all(s.ring_of_cell()[c[1:]] == s.n_rings - 1)
    assert c[2] == c[3]  # phi = +pi and phi -> -pi land in the same cell


@pytest.mark.parametrize("cells", [2, 20, 3240, 200_000])
def test_lookup_bins_as_atan2_does_even_next_to_every_phi_edge(cells):
    """The lookup guesses with a polynomial azimuth and settles by the edges' cross products: it
    must bin as floor(atan2(y, x) n_k / 2 pi + 1/2) did, 1e-9 and 1e-12 rad either side of every
    cell's phi edge, and on random directions."""
    s = Sensor.build(cells)
    ring = s.ring_of_cell()
    j = np.arange(s.n_cells) - s.ring_start[ring]
    edge = np.concatenate([(j - 0.5) * 2 * np.pi / s.ring_counts[ring] + e for e in (1e-9, -1e-9, 1e-12, -1e-12)])
    mu = np.tile(1 - (s.ring_start[ring] + 0.5 * s.ring_counts[ring]) / s.n_cells, 4)  # mid-ring heights
    sin_theta = np.sqrt(1 - mu**2)
    rng = np.random.default_rng(8)
    w = rng.normal(size=(200_000, 3))
    w[:, 2] = np.abs(w[:, 2])
    w /= np.linalg.norm(w, axis=1)[:, None]
    w = np.concatenate([np.stack([sin_theta * np.cos(edge), sin_theta * np.sin(edge), mu], axis=1), w])
    ring_of_w = s.ring_of[np.clip(((1 - w[:, 2]) * s.n_cells).astype(int), 0, s.n_cells - 1)]
    count = s.ring_counts[ring_of_w]
    by_atan2 = np.floor(np.arctan2(w[:, 1], w[:, 0]) * count / (2 * np.pi) + 0.5).astype(int) % count
    assert np.array_equal(s.lookup(w), s.ring_start[ring_of_w] + by_atan2)


def test_cell_average_integrates_polynomials_in_mu_exactly():
    s = Sensor.build(500)
    c = s.cos_edges
    ring = s.ring_of_cell()
    hi, lo = c[ring], c[ring + 1]
    exact = (2.0 / 3.0) * (hi**3 - lo**3) / (hi**2 - lo**2)  # cos-weighted mean of mu
    assert np.allclose(s.cell_average(lambda w: w[:, 2]), exact, rtol=1e-12)
    assert np.allclose(s.cell_average(lambda w: np.ones(len(w))), 1.0, rtol=1e-13)
