"""H-functions of the Lambert-sphere half space and the exact Horak-Chandrasekhar constants.

Paper: d'Eon 2021 (Lambert-sphere BRDF; docs/reference/papers.md), Eqs. 13-20 and 22, 30, 32-33;
the exact solution of Horak & Chandrasekhar 1961 (ApJ 134, 45) for the three-term phase function
of Eq. 8, ``c p = w0 + w1 P1 + w2 P2`` with ``w0 = c, w1 = -4c/3, w2 = 5c/16``.

Numerics
--------
* ``dispersion`` is K^(i)(t) of Eq. 17. It is evaluated as ``K(0) + 2 t^2 sum_k p_k J_{k+1}(t)``
  with ``J_k(t) = int_0^1 x^2k / (1 + t^2 x^2) dx`` (a power series for t < 1/2, the upward
  recurrence from ``atan(t)/t`` above). The closed forms Eqs. 18-20 are the same function
  (checked to 1e-12 for t >= 0.5 in the tests) but cancel catastrophically for small t, and the
  subtracted form keeps K relatively accurate even where K(0) = 0 (mode 0 at c = 1, the
  conservative case).
* ``h_function`` is the Fock formula Eq. 16, rewritten with t = e^s as
  ``ln H(mu) = -(1/pi) int ln K(e^s) / (2 cosh(s + ln mu)) ds`` and integrated by the
  trapezoidal rule (step 1/4, window +-40 around s = -ln mu). The integrand is analytic in the
  strip |Im s| < pi/2, so the rule converges geometrically (error ~ exp(-pi^2 / h) ~ 1e-17;
  measured: docs/developer/performance.md, section 'H-functions: step of the Fock quadrature').
* ``h_function_iterated`` solves Chandrasekhar's nonlinear integral equation
  ``H(mu) = 1 + mu H(mu) int_0^1 Psi(mu') H(mu') / (mu + mu') dmu'`` by fixed-point iteration on a
  graded Gauss rule: an independent method used to check ``h_function``.

Exact constants (derivation)
----------------------------
For Fourier mode m of the half space, Ambartsumian's invariance principle factorises as
``(1/mu + 1/mu0) S^m(mu, mu0) = sum_l s_l psi_l(mu) psi_l(mu0)`` with
``s_l = (-1)^(l+m) w_l (l-m)!/(l+m)!`` and
``psi_l(mu) = P_l^m(mu) + (-1)^(l+m) (1/2) int_0^1 S^m(mu, mu') P_l^m(mu') dmu'/mu'``.
Writing ``P_l^m = (1-mu^2)^(m/2) Pt_l``, ``w = (1-mu^2)^m`` and ``psi_l = (1-mu^2)^(m/2) H q_l``,

    S^m = mu mu0 / (mu + mu0) (w w0)^(1/2) H(mu) H(mu0) Pi(mu, mu0),  Pi = sum_l s_l q_l q_l^T,

and the H equation turns the definition of psi_l into the polynomial identity

    q_l(mu) = Pt_l(mu) [1 - mu N(mu)] + (-1)^(l+m) (mu/2) int_0^1 H(mu') R_l(mu, mu') dmu',

with ``N(mu) = int H(mu') (Psi(mu') - Psi(mu)) / (mu' + mu) dmu'`` and
``R_l = (G_l(mu, mu') - G_l(mu, -mu)) / (mu + mu')``, ``G_l = Pi(mu, mu') Pt_l(mu') w(mu')``,
provided ``w(mu) Pi(mu, -mu) = 2 Psi(mu)``: this last identity reproduces Eqs. 13-15 and gives
A and E of Eq. 33 and ``2F - C = c (20c^2 + 281c - 346) / 384`` exactly. Every coefficient on the
right is a moment ``alpha_n = int_0^1 H mu^n dmu``; ``Pi = sum_l s_l q_l q_l^T`` closes the system.

* m = 2: q = 3 (no constant): f^(2) = 15 c (1-mu_i^2)(1-mu_o^2) H2 H2 / (256 pi (mu_i + mu_o)).
* m = 1: q_1 = 1 + l mu, q_2 = 3 sqrt(m) mu (Eq. 22); the identity gives
  ``l^2 + 45 m / 64 = 5 (4c + 9) / 64`` and the mu^1 coefficient of the l = 1 identity gives
  ``l = -(c k / 3) (alpha_1 - alpha_3) / (1 + (c / 3)(alpha_0 - alpha_2))``, k = 5 (4c + 9) / 64.
* m = 0: q_l = Pt_l(0) + u_l mu + v_l mu^2; the closed system (quadratic in the six u_l, v_l) is
  solved by Gauss-Newton from the single-scattering solution q_l = Pt_l (exact as c -> 0).
  Since psi_1(mu) = mu (1 - a(mu)), ``1 - a(mu) = H0(mu) (u1 + v1 mu)`` is the plane-albedo
  deficit. Two roots of the system merge at c = 1 (u1 ~ 0.815 sqrt(1 - c) on the physical
  branch, which has u1 = 1 - a(0) >= 0). At c = 1 itself the merged root q_1 = 0 is taken and
  the rest solved for; energy conservation of f^(0) at c = 1 is then a check, not an input.

The solution was checked against an independent discrete-ordinate solution of the transfer
equation (tests) and against energy conservation at c = 1.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numba
import numpy as np
from numpy.polynomial import polynomial as npoly

#: Trapezoidal step and half window (in s = ln t) of the Fock integral.
_STEP = 0.25
_WINDOW = 40.0
#: Largest mu accepted by ``h_function`` (larger values are clipped; H(mu) is within 1e-16 of
#: H(infinity) there, except in the conservative mode-0 case where H grows without bound).
MU_MAX = 1e16


def phase_coefficients(c: float) -> tuple[float, float, float]:
    """(w0, w1, w2) of the three-term phase function, Eq. 8."""
    return c, -4.0 * c / 3.0, 5.0 * c / 16.0


#: the "mode" of isotropic scattering (physics.phase's "isotropic"), Psi = c / 2 (Chandrasekhar 1960,
#: Radiative Transfer, Ch. V): its H-function is computed by the same Fock formula, with K(0) = 1 - c;
#: modes 0, 1, 2 are those of the three-term phase function
ISOTROPIC_MODE = "isotropic"


def psi_coefficients(mode: int | str, c: float) -> np.ndarray:
    """(p0, p2, p4) with Psi^(mode)(mu) = p0 + p2 mu^2 + p4 mu^4, Eqs. 13-15 (ISOTROPIC_MODE: c / 2)."""
    if mode == ISOTROPIC_MODE:
        return np.array([0.5 * c, 0.0, 0.0])
    if mode == 0:
        return np.array([207.0 * c, c * (20.0 * c * c + 281.0 * c - 346.0), -15.0 * c * (c - 1.0) * (4.0 * c + 9.0)]) / 384.0
    if mode == 1:
        return np.array([-64.0 * c, c * (20.0 * c + 109.0), -5.0 * c * (4.0 * c + 9.0)]) / 192.0
    if mode == 2:
        return np.array([1.0, -2.0, 1.0]) * (15.0 * c / 256.0)
    raise ValueError(f"mode = {mode!r} is outside {{0, 1, 2, {ISOTROPIC_MODE!r}}}")


def _check_c(c: float) -> float:
    c = float(c)
    if not 0.0 <= c <= 1.0:
        raise ValueError(f"c = {c!r} is outside [0, 1]")
    return c


def k_at_zero(mode: int, c: float) -> float:
    """K^(mode)(0) = 1 - 2 int_0^1 Psi; mode 0 in the factored form of Eq. 32 (exactly 0 at c = 1)."""
    c = _check_c(c)
    if mode == ISOTROPIC_MODE:
        return 1.0 - c
    if mode == 0:
        return (16.0 - c) * (1.0 - c) * (4.0 * c + 9.0) / 144.0
    p = psi_coefficients(mode, c)
    return 1.0 - 2.0 * (p[0] + p[1] / 3.0 + p[2] / 5.0)


def h_infinity(mode: int, c: float) -> float:
    """H^(mode)(infinity) = K(0)^(-1/2), Eq. 32 (inf for mode 0 at c = 1)."""
    k0 = k_at_zero(mode, c)
    return math.inf if k0 == 0.0 else 1.0 / math.sqrt(k0)


def _j_integrals(t: np.ndarray, k_max: int) -> np.ndarray:
    """J_k(t) = int_0^1 x^2k / (1 + t^2 x^2) dx for k = 0..k_max (rows)."""
    t = np.asarray(t, dtype=np.float64)
    out = np.empty((k_max + 1,) + t.shape)
    small = t < 0.5
    x = -(t[small] ** 2)
    n = np.arange(48)
    powers = x[None, :] ** n[:, None]
    for k in range(k_max + 1):
        out[k][small] = np.sum(powers / (2 * k + 2 * n[:, None] + 1), axis=0)
    tl = t[~small]
    j = np.arctan(tl) / tl
    out[0][~small] = j
    for k in range(1, k_max + 1):
        j = (1.0 / (2 * k - 1) - j) / tl**2
        out[k][~small] = j
    return out


def _log_dispersion(mode: int, c: float, s: np.ndarray) -> np.ndarray:
    """ln K^(mode)(e^s), relatively accurate also where K(0) = 0.

    Beyond t = e^200 the leading term ln K = -pi Psi(0) / t is used (next term O(t^-2)).
    """
    p = psi_coefficients(mode, c)
    out = np.empty_like(s)
    far = s > 200.0
    out[far] = -math.pi * p[0] * np.exp(-s[far])
    s = s[~far]
    t = np.exp(s)
    j = _j_integrals(t, 3)
    tail = 2.0 * (p[0] * j[1] + p[1] * j[2] + p[2] * j[3])
    k0 = k_at_zero(mode, c)
    out[~far] = np.log(tail) + 2.0 * s if k0 == 0.0 else np.log(k0 + tail * t * t)
    return out


def dispersion(mode: int, c: float, t) -> np.ndarray:
    """K^(mode)(t) of Eq. 17 = 1 - 2 int_0^1 Psi(x) / (1 + t^2 x^2) dx (closed forms: Eqs. 18-20)."""
    c = _check_c(c)
    t = np.asarray(t, dtype=np.float64)
    p = psi_coefficients(mode, c)
    j = _j_integrals(t, 3)
    return k_at_zero(mode, c) + 2.0 * t * t * (p[0] * j[1] + p[1] * j[2] + p[2] * j[3])


@numba.njit(cache=True)
def _fock_sum(log_k, s_first, step, window, mu, out):
    n = log_k.size
    for i in range(mu.size):
        m = mu[i]
        if m <= 0.0:
            out[i] = 0.0
            continue
        lm = math.log(m)
        centre = (-lm - s_first) / step
        j_lo = max(0, int(math.floor(centre - window / step)))
        j_hi = min(n - 1, int(math.ceil(centre + window / step)))
        acc = 0.0
        for j in range(j_lo, j_hi + 1):
            x = s_first + j * step + lm
            e = math.exp(-abs(x))
            acc += log_k[j] * e / (1.0 + e * e)
        out[i] = -(step / math.pi) * acc


class HFunction:
    """H^(mode)(mu) for particle albedo c by the Fock formula, Eq. 16 (see module notes).

    ``h = HFunction(0, 0.8); h(mu)`` for any array of mu >= 0; ``h.moments(n)`` gives
    ``int_0^1 H(mu) mu^k dmu`` for k = 0..n.
    """

    def __init__(self, mode: int, c: float):
        self.mode = mode
        self.c = _check_c(c)
        psi_coefficients(mode, self.c)
        j_first = math.floor((-math.log(MU_MAX) - _WINDOW) / _STEP) - 1
        j_last = math.ceil((-math.log(np.finfo(float).smallest_subnormal) + _WINDOW) / _STEP) + 1
        self._s_first = j_first * _STEP
        s = self._s_first + _STEP * np.arange(j_last - j_first + 1)
        self._log_k = np.ascontiguousarray(_log_dispersion(mode, self.c, s))

    def __call__(self, mu) -> np.ndarray:
        return np.exp(self.log(mu))

    def log(self, mu) -> np.ndarray:
        """ln H(mu), accurate also where H - 1 is tiny (use ``np.expm1`` for H - 1)."""
        mu = np.asarray(mu, dtype=np.float64)
        flat = np.minimum(mu, MU_MAX).reshape(-1)
        if np.any(~(flat >= 0.0)):
            raise ValueError("mu must be >= 0")
        # each distinct mu once: a model's quadrature repeats the cosines of a ring (and mu_i)
        distinct, where = np.unique(flat, return_inverse=True)
        out = np.empty_like(distinct)
        _fock_sum(self._log_k, self._s_first, _STEP, _WINDOW, distinct, out)
        return out[where].reshape(mu.shape)

    def moments(self, n: int) -> np.ndarray:
        """alpha_k = int_0^1 H(mu) mu^k dmu, k = 0..n (Gauss rule graded as mu = u^3 for the mu ln mu at 0)."""
        mu, w = zero_graded_gauss_rule(64)
        h = self(mu)
        return np.array([np.sum(w * h * mu**k) for k in range(n + 1)])


def zero_graded_gauss_rule(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights on (0, 1) of Gauss-Legendre in u with mu = u^3 (clusters at 0 where H ~ mu ln mu)."""
    x, w = np.polynomial.legendre.leggauss(n)
    u = 0.5 * (x + 1.0)
    return u**3, 1.5 * w * u**2


def h_function(mode: int, c: float, mu) -> np.ndarray:
    """H^(mode)(mu) for particle albedo c, Eq. 16 (mode 0, 1, 2; c in [0, 1]; mu >= 0)."""
    return HFunction(mode, c)(mu)


def h_function_iterated(mode: int, c: float, mu, n: int = 200, tol: float = 1e-15, max_iter: int = 100000) -> np.ndarray:
    """H^(mode)(mu) from Chandrasekhar's nonlinear integral equation, by fixed-point iteration.

    ``H(mu) = 1 / (1 - mu int_0^1 Psi(mu') H(mu') / (mu + mu') dmu')`` on the graded Gauss rule of
    ``n`` nodes, then the same equation as a Nystrom interpolant at ``mu``. Independent of the
    Fock formula; converges slowly in the conservative case (mode 0, c -> 1).
    """
    c = _check_c(c)
    x, w = zero_graded_gauss_rule(n)
    p = psi_coefficients(mode, c)
    weight = w * (p[0] + p[1] * x**2 + p[2] * x**4)
    h = np.ones(n)
    kernel = x[:, None] / (x[:, None] + x[None, :])
    for _ in range(max_iter):
        new = 1.0 / (1.0 - kernel @ (weight * h))
        done = np.max(np.abs(new - h)) < tol
        h = new
        if done:
            break
    mu = np.asarray(mu, dtype=np.float64)
    m = mu.reshape(-1, 1)
    return (1.0 / (1.0 - np.sum(m / (m + x[None, :]) * weight * h, axis=1))).reshape(mu.shape)


# --- The Horak-Chandrasekhar solution ------------------------------------------------------


def _moment_operator(g: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """int_0^1 H(mu') (G(mu') - G(-mu)) / (mu' + mu) dmu' as a polynomial in mu (G by coefficients)."""
    out = np.zeros(max(len(g) - 1, 1))
    for n in range(1, len(g)):
        for j in range(n):
            out[n - 1 - j] += g[n] * alpha[j] * (-1.0) ** (n - 1 - j)
    return out


def _mode_data(mode: int, c: float):
    """(s_l, Pt_l, w) of the derivation for Fourier mode ``mode``."""
    w0, w1, w2 = phase_coefficients(c)
    if mode == 0:
        return [w0, -w1, w2], [np.array([1.0]), np.array([0.0, 1.0]), np.array([-0.5, 0.0, 1.5])], np.array([1.0])
    if mode == 1:
        return [w1 / 2.0, -w2 / 6.0], [np.array([1.0]), np.array([0.0, 3.0])], np.array([1.0, 0.0, -1.0])
    return [w2 / 24.0], [np.array([3.0])], np.array([1.0, 0.0, -2.0, 0.0, 1.0])


def q_polynomials(mode: int, c: float, pi: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """The polynomials q_l implied by the bilinear form ``pi`` (coefficient matrix in mu, mu0).

    Right-hand side of the identity in the module notes; rows are q_l (l = mode..2) by ascending
    coefficients, padded to 12. Affine in ``pi``. ``alpha`` are the moments of H^(mode).
    """
    sig, pt, w = _mode_data(mode, c)
    p = psi_coefficients(mode, c)
    n_poly = _moment_operator(np.array([p[0], 0.0, p[1], 0.0, p[2]]), alpha)
    rows = []
    for idx, pt_l in enumerate(pt):
        l = idx + mode
        q = npoly.polymul(pt_l, npoly.polysub([1.0], npoly.polymul([0.0, 1.0], n_poly)))
        moment = np.zeros(pi.shape[0] + pi.shape[1] + len(pt_l) + len(w))
        for i in range(pi.shape[0]):
            g = npoly.polymul(npoly.polymul(pi[i], pt_l), w)
            d = _moment_operator(g, alpha)
            moment[i : i + len(d)] += d
        q = npoly.polyadd(q, (-1.0) ** (l + mode) * 0.5 * npoly.polymul([0.0, 1.0], moment))
        rows.append(np.pad(q, (0, 12 - len(q))))
    return np.array(rows)


def closure_residual(mode: int, c: float, pi: np.ndarray, alpha: np.ndarray) -> float:
    """max |sum_l s_l q_l q_l^T - pi| plus the degree excess of q_l: zero for the exact solution."""
    sig, _, _ = _mode_data(mode, c)
    deg = pi.shape[0] - 1
    q = q_polynomials(mode, c, pi, alpha)
    full = np.einsum("l,li,lj->ij", np.asarray(sig), q[:, : deg + 1], q[:, : deg + 1])
    return float(max(np.max(np.abs(full - pi)), np.max(np.abs(q[:, deg + 1 :]))))


@lru_cache(maxsize=64)
def first_mode_constants(c: float) -> tuple[float, float]:
    """Exact (l, m) of Eq. 22 from the moments of H^(1) (derivation in the module notes)."""
    c = _check_c(c)
    alpha = HFunction(1, c).moments(3)
    k = 5.0 * (4.0 * c + 9.0) / 64.0
    l = -(c * k / 3.0) * (alpha[1] - alpha[3]) / (1.0 + (c / 3.0) * (alpha[0] - alpha[2]))
    return l, (64.0 * k - 64.0 * l * l) / 45.0


def first_mode_form(c: float, l: float, m: float) -> np.ndarray:
    """Pi of mode 1 for constants (l, m): s_1 (1 + l mu)(1 + l mu0) + s_2 9 m mu mu0."""
    s1 = -2.0 * c / 3.0
    return s1 * np.array([[1.0, l], [l, l * l + 45.0 * m / 64.0]])


def zeroth_mode_form(c: float, b: float, cc: float, d: float) -> np.ndarray:
    """Pi of mode 0, i.e. 2 [[A, B, F], [B, C, D], [F, D, E]] with A, E, F from Eq. 33 and the identity."""
    a = 69.0 * c / 128.0
    e = 15.0 / 128.0 * (1.0 - c) * c * (4.0 * c / 3.0 + 3.0)
    f = 0.5 * (cc + c * (20.0 * c * c + 281.0 * c - 346.0) / 384.0)
    return 2.0 * np.array([[a, b, f], [b, cc, d], [f, d, e]])


def _closure_equations(mode: int, c: float, q: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Residuals of the closed system for the polynomials q (rows q_l, ascending coefficients)."""
    sig, pt, w = _mode_data(mode, c)
    sig = np.asarray(sig)
    p = psi_coefficients(mode, c)
    pi = np.einsum("l,li,lj->ij", sig, q, q)
    implied = q_polynomials(mode, c, pi, alpha)
    implied[:, : q.shape[1]] -= q
    identity = np.zeros(12)
    for s_l, q_l in zip(sig, q):
        term = npoly.polymul(npoly.polymul(q_l, q_l * (-1.0) ** np.arange(q.shape[1])), w) * s_l
        identity[: len(term)] += term
    identity[[0, 2, 4]] -= 2.0 * p
    return np.concatenate([implied.ravel(), identity])


def _solve_closure(mode: int, c: float, alpha: np.ndarray, q: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Gauss-Newton for the q coefficients flagged ``free``; the equations are quadratic in q, so
    central differences give the exact Jacobian (up to rounding)."""
    q = q.copy()
    step = 1e-3
    for _ in range(50):
        r = _closure_equations(mode, c, q, alpha)
        jac = np.empty((r.size, int(free.sum())))
        for col, idx in enumerate(zip(*np.nonzero(free))):
            dq = np.zeros_like(q)
            dq[idx] = step
            jac[:, col] = (_closure_equations(mode, c, q + dq, alpha) - _closure_equations(mode, c, q - dq, alpha)) / (2 * step)
        delta = np.linalg.lstsq(jac, -r, rcond=None)[0]
        q[free] += delta
        if np.max(np.abs(delta)) < 1e-15:
            break
    return q


#: Below this distance from c = 1 the two roots of the mode-0 closure nearly merge and the direct
#: solution loses accuracy (~1e-16 / sqrt(1 - c)); there the constants are interpolated linearly
#: in sqrt(1 - c) between c = 1 - _MERGE_GAP and c = 1 (interpolation error ~ _MERGE_GAP / 8).
_MERGE_GAP = 1e-10


@lru_cache(maxsize=64)
def zeroth_mode_constants(c: float) -> dict:
    """Exact A-F of Eq. 30 and the albedo polynomial (u1, v1), from the moments of H^(0).

    Returns a dict with keys A, B, C, D, E, F, u1, v1; ``1 - a(mu) = H0(mu) (u1 + v1 mu)`` is
    the plane albedo deficit of the three-term half space (derivation in the module notes).
    The closed system is solved by Gauss-Newton from the single-scattering polynomials
    (q_l = Pt_l, exact as c -> 0). At c = 1 its two roots merge; there q_1 = 0 (the merged root)
    and the other q_l are solved for: energy conservation is then a check, not an input.
    """
    c = _check_c(c)
    if c == 0.0:
        return _constants_dict(0.0, 0.0, 0.0, 0.0, 1.0, 0.0)
    if 1.0 - _MERGE_GAP < c < 1.0:
        near, one = zeroth_mode_constants(1.0 - _MERGE_GAP), zeroth_mode_constants(1.0)
        x = math.sqrt((1.0 - c) / _MERGE_GAP)
        b, cc, d, u1, v1 = (one[k] + x * (near[k] - one[k]) for k in ("B", "C", "D", "u1", "v1"))
        return _constants_dict(c, b, cc, d, u1, v1)
    alpha = HFunction(0, c).moments(7)
    start = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-0.5, 0.0, 1.5]])
    free = np.ones_like(start, dtype=bool)
    if c == 1.0:
        start[1] = 0.0
        free[1] = False
    q = _solve_closure(0, c, alpha, start, free)
    sig = np.asarray(_mode_data(0, c)[0])
    pi = 0.5 * np.einsum("l,li,lj->ij", sig, q, q)
    return _constants_dict(c, pi[0, 1], pi[1, 1], pi[1, 2], q[1, 1], q[1, 2])


def _constants_dict(c, b, cc, d, u1, v1) -> dict:
    half = zeroth_mode_form(c, b, cc, d) / 2.0
    return dict(A=half[0, 0], B=b, C=cc, D=d, E=half[2, 2], F=half[0, 2], u1=u1, v1=v1)
