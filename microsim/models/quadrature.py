"""Deterministic hemispherical quadrature shared by the models and their checks."""

import numpy as np


def hemisphere_rule(n_mu: int = 64, n_phi: int = 128):
    """Directions and weights integrating g(w) d(omega) over the upper hemisphere.

    Gauss-Legendre in mu = cos(theta) on (0, 1), midpoint rule in phi (exact for
    trigonometric polynomials of degree < n_phi). Returns ``(w (M, 3), weight (M,))``.
    """
    x, wx = np.polynomial.legendre.leggauss(n_mu)
    mu = 0.5 * (x + 1.0)
    wmu = 0.5 * wx
    phi = (np.arange(n_phi) + 0.5) * (2.0 * np.pi / n_phi)
    mu_g, phi_g = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1.0 - mu_g**2)
    w = np.stack([s * np.cos(phi_g), s * np.sin(phi_g), mu_g], axis=-1).reshape(-1, 3)
    weight = (wmu[:, None] * np.full(n_phi, 2.0 * np.pi / n_phi)[None, :]).reshape(-1)
    return w, weight


def directional_albedo(model, wi, n_mu: int = 64, n_phi: int = 128) -> np.ndarray:
    """a(wi) = integral of f(wi, wo) cos(theta_o) d(omega_o), for each direction in ``wi`` (..., 3)."""
    wi = np.asarray(wi, dtype=np.float64)
    flat = wi.reshape(-1, 3)
    wo, weight = hemisphere_rule(n_mu, n_phi)
    out = np.empty(flat.shape[0])
    for j, d in enumerate(flat):
        f = model(np.broadcast_to(d, wo.shape), wo)
        out[j] = np.sum(f * wo[:, 2] * weight)
    return out.reshape(wi.shape[:-1])

