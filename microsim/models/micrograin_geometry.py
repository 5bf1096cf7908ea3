"""Geometry of a Boolean layer of half-ellipsoidal micrograins (Lucas et al. 2024, Sec. 4).

Paper: Lucas et al. 2024 (fully-correlated anisotropic micrograin BSDF; docs/reference/papers.md),
whose equation, section and appendix numbers are cited below. Grains are half-ellipsoids of vertical
semi-axis 1 and lateral semi-axes 1/beta_x, 1/beta_y whose centres are a Poisson process of
density rho on the base plane z = 0 (docs/conventions.md §5.3), so that the covered fraction is
``tau0 = 1 - exp(-rho pi / (beta_x beta_y))``. That density, lambda and the unit-space maps
below are the relations of the Boolean model in :mod:`microsim.physics.boolean_model`, which the
micrograin scene generator (:mod:`microsim.geometry.micrograins`) shares.

Parametrisation. The paper takes spheres of radius r_s stretched laterally by 1/beta_x, 1/beta_y
(Eq. 8) and then sets r_s = 1 (after Eq. 9): r_s is our vertical semi-axis, and beta is the
height-to-lateral-radius ratio of a grain, as in Lucas et al. 2023, whose grains of radius r_s
compressed vertically to height beta r_s are the same shape at another scale. Every quantity
below depends on tau0, beta_x, beta_y only.

Everything is computed in the "unit space" of the paper's affine map E = diag(beta_x, beta_y, 1)
(Sec. 4.2, Eq. 19), in which grains are unit half-spheres, centres have density
``lambda / pi`` with ``lambda = -ln(1 - tau0)``, directions map to ``w' = E w / |E w|``, normals
to ``m' = E^-1 m / |E^-1 m|`` and heights are unchanged. A point of a grain with unit-space normal
m' lies at height h' = m'.z (the height-normal bijection of the paper).

Shadow areas (Appendix A-C): for a unit sphere at the origin, the points of the plane at height
h whose ray towards w meets the sphere form a convex set (a section of the sphere swept along
-w), bounded by the circle C_h of radius sqrt(1 - h^2) on the lit side and by the ellipse
E_h(w) (the section of the cylinder tangent to the sphere along w) on the shadow side. The
shadow sigma_s is that set minus the disc. The overlap of two shadows is computed here from
the polar description of both sets about the disc centre (fans of ellipse arcs), which covers
the three cases of Appendix B with one formula; the tests check it against hit tests of the
sphere and against ray casting among explicit Poisson grains. (App. B prints the ellipse
E_n(i, o) as 1 = p_h^2 + [1 - (h.o)^2] p_b^2; for p = p_h h + p_b b the distance to the axis i
gives [1 - (h.i)^2] p_h^2 + p_b^2 = 1. It is not needed here.)
"""

from __future__ import annotations

import math

import numba
import numpy as np

from microsim.physics.boolean_model import grain_extinction, unit_space_direction_array

#: Gauss-Legendre order of the height integral of the Smith Lambda (micrograin_smith).
LAMBDA_NODES = 32
_TINY_COS = 1e-300


def end_graded_gauss_rule(n: int):
    """Gauss-Legendre nodes on [-1, 1] pushed to both ends by x -> (3x - x^3) / 2.

    Height integrals here end where a shadow or the masking of a direction starts, h = sin(theta'),
    where the integrand behaves like (s - h)^(3/2), with a boundary layer of width ~ cos(theta')
    at grazing angles: the map turns (s - h)^(3/2) into a smooth (1 - x)^3 and clusters the
    nodes in the layer.
    """
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (3.0 * x - x**3), 1.5 * (1.0 - x * x) * w


@numba.njit(cache=True)
def ndf_value(mx, my, mz, tau0, beta_x, beta_y):
    """Micrograin NDF D(m) (Eq. 10-12) of a unit normal m, normalised: integral D (m.n) dm = 1.

    D = lambda exp(-lambda t^2 / (1 + t^2)) / tau0 * D_GGX(m; beta_x, beta_y), with
    t^2 = tan^2(theta_m) (cos^2 phi_m / beta_x^2 + sin^2 phi_m / beta_y^2) (Eq. 12) and the
    anisotropic GGX prefactor 1 / (pi beta_x beta_y cos^4 (1 + t^2)^2).
    """
    if mz <= 0.0:
        return 0.0
    lam = grain_extinction(tau0)
    cos2 = mz * mz
    slope2 = (mx / beta_x) ** 2 + (my / beta_y) ** 2
    denom = cos2 + slope2
    return lam * math.exp(-lam * slope2 / denom) / (tau0 * math.pi * beta_x * beta_y * denom * denom)


@numba.njit(cache=True)
def _ndf_values(m, tau0, beta_x, beta_y):
    out = np.empty(m.shape[0])
    for n in range(m.shape[0]):
        out[n] = ndf_value(m[n, 0], m[n, 1], m[n, 2], tau0, beta_x, beta_y)
    return out


def ndf(m: np.ndarray, tau0: float, beta_x: float, beta_y: float) -> np.ndarray:
    """D(m) of ``ndf_value`` for unit normals m (..., 3); 0 below the horizon."""
    m = np.asarray(m, dtype=np.float64)
    flat = np.ascontiguousarray(m.reshape(-1, 3))
    return _ndf_values(flat, tau0, beta_x, beta_y).reshape(m.shape[:-1])


@numba.njit(cache=True)
def _disc_area_left_of(a):
    """Area of the unit disc on the side x <= a of the line x = a."""
    a = min(max(a, -1.0), 1.0)
    return math.pi - math.acos(a) + a * math.sqrt(1.0 - a * a)


@numba.njit(cache=True)
def shadow_area(sin_t, cos_t, h):
    """sigma_s(w, h): shadow of a unit sphere from a direction of polar angle theta (App. A).

    In the frame where w = (sin t, 0, cos t) the shadow lies on x <= x_q = -h cot t, between the
    ellipse E_h (centre h tan t, semi-axes 1/cos t and 1) and the circle C_h (radius
    sqrt(1 - h^2)); it exists iff h < sin t. sigma_s = |E_h, x <= x_q| - |C_h, x <= x_q|, the same
    as the printed sigma_e - sigma_c - sigma_t (identical after expanding the segments).
    """
    r2 = 1.0 - h * h
    if r2 <= 0.0 or h >= sin_t:
        return 0.0
    cos_t = max(cos_t, _TINY_COS)
    kappa = h * cos_t / (sin_t * math.sqrt(r2))
    area = _disc_area_left_of(-h / sin_t) / cos_t - r2 * _disc_area_left_of(-kappa)
    return max(area, 0.0)


@numba.njit(cache=True)
def _ellipse_radius(qx, qy, dx, dy, dz, h):
    """Distance from the disc centre, along the unit in-plane vector q, to the ellipse E_h(d).

    Points p = (r q, h) at distance 1 from the axis of d: r^2 (1 - w^2) - 2 r w h dz = 1 - h^2 s^2
    with w = q . d_xy; the positive root (the disc centre is inside the ellipse). 1 - w^2 is
    formed as dz^2 + (q x d_xy)^2 and 1 - h^2 s^2 as 1 - h^2 + h^2 dz^2, exact at grazing d.
    """
    w = qx * dx + qy * dy
    cross = qx * dy - qy * dx
    b = w * h * dz
    a = dz * dz + cross * cross
    c = 1.0 - h * h + h * h * dz * dz
    root = math.sqrt(b * b + a * c)
    if b >= 0.0:
        return (b + root) / a
    return c / (root - b)


@numba.njit(cache=True)
def _ellipse_fan_area(alpha1, alpha2, dx, dy, dz, h):
    """Area swept from the disc centre by the arc of E_h(d) between polar angles alpha1 < alpha2.

    Half the integral of p x dp along the arc: (alpha_t2 - alpha_t1) / (2 cos t), the sector about
    the ellipse centre e in the ellipse's own angle, plus e x (P2 - P1) / 2.
    """
    s = math.sqrt(dx * dx + dy * dy)
    ux = dx / s
    uy = dy / s
    cz = max(dz, _TINY_COS)
    ex = h * dx / cz
    ey = h * dy / cz
    r1 = _ellipse_radius(math.cos(alpha1), math.sin(alpha1), dx, dy, dz, h)
    r2 = _ellipse_radius(math.cos(alpha2), math.sin(alpha2), dx, dy, dz, h)
    p1x = r1 * math.cos(alpha1)
    p1y = r1 * math.sin(alpha1)
    p2x = r2 * math.cos(alpha2)
    p2y = r2 * math.sin(alpha2)
    a1 = ((p1x - ex) * ux + (p1y - ey) * uy) * cz
    b1 = -(p1x - ex) * uy + (p1y - ey) * ux
    a2 = ((p2x - ex) * ux + (p2y - ey) * uy) * cz
    b2 = -(p2x - ex) * uy + (p2y - ey) * ux
    dt = math.atan2(a1 * b2 - b1 * a2, a1 * a2 + b1 * b2)
    return 0.5 * dt / cz + 0.5 * (ex * (p2y - p1y) - ey * (p2x - p1x))


@numba.njit(cache=True)
def _wrap(angle):
    """Angle wrapped into (-pi, pi]."""
    return angle - 2.0 * math.pi * math.ceil((angle - math.pi) / (2.0 * math.pi))


@numba.njit(cache=True)
def _nearer_fan_area(alpha1, alpha2, a, b, h):
    """Fan of the nearer of E_h(a), E_h(b) (a, b: unit directions as 3-tuples) between polar angles
    alpha1 <= alpha2, minus the disc sector."""
    (ax, ay, az), (bx, by, bz) = a, b
    if alpha2 <= alpha1:
        return 0.0
    mid = 0.5 * (alpha1 + alpha2)
    qx = math.cos(mid)
    qy = math.sin(mid)
    if _ellipse_radius(qx, qy, ax, ay, az, h) <= _ellipse_radius(qx, qy, bx, by, bz, h):
        fan = _ellipse_fan_area(alpha1, alpha2, ax, ay, az, h)
    else:
        fan = _ellipse_fan_area(alpha1, alpha2, bx, by, bz, h)
    return fan - 0.5 * (1.0 - h * h) * (alpha2 - alpha1)


@numba.njit(cache=True)
def overlap_area(ax, ay, az, bx, by, bz, h):
    """sigma_cap(a, b, h): area common to the unit-sphere shadows from unit directions a and b.

    Both shadow sets plus the disc C_h are star-shaped about the disc centre; on the polar
    interval J where both shadow arcs exist the common part is bounded by the nearer ellipse.
    The two ellipses cross there only on the plane p.(a - b) = 0 (their points on the other
    bisector plane have p.a = -p.b and lie outside the shadows), so J is cut at those crossings
    and each piece adds an ellipse fan minus the disc sector. Equivalent to the three cases of
    App. B (disjoint shadows: J empty; nested: no crossing in J; partial: one crossing p_+).
    """
    sa = math.sqrt(ax * ax + ay * ay)
    sb = math.sqrt(bx * bx + by * by)
    r2 = 1.0 - h * h
    if r2 <= 0.0 or h >= sa or h >= sb:
        return 0.0
    r = math.sqrt(r2)
    half_a = math.acos(min(h * az / (sa * r), 1.0))
    half_b = math.acos(min(h * bz / (sb * r), 1.0))
    centre = math.atan2(ay, ax) + math.pi
    delta = _wrap(math.atan2(by, bx) + math.pi - centre)
    lo = max(-half_a, delta - half_b)
    hi = min(half_a, delta + half_b)
    if hi <= lo:
        return 0.0
    first = hi
    second = hi
    gx = ax - bx
    gy = ay - by
    g2 = gx * gx + gy * gy
    if g2 > 1e-24:
        k = -h * (az - bz) / g2
        p0x = k * gx
        p0y = k * gy
        g = math.sqrt(g2)
        tx = -gy / g
        ty = gx / g
        u0 = p0x * ax + p0y * ay + h * az
        u1 = tx * ax + ty * ay
        along = (gx * ax + gy * ay) / g
        qa = az * az + along * along
        qb = u0 * u1
        qc = p0x * p0x + p0y * p0y + h * h - u0 * u0 - 1.0
        disc = qb * qb - qa * qc
        if disc >= 0.0:
            for sign in (-1.0, 1.0):
                tau = (qb + sign * math.sqrt(disc)) / qa
                if u0 + tau * u1 < 0.0:
                    psi = _wrap(math.atan2(p0y + tau * ty, p0x + tau * tx) - centre)
                    if lo < psi < first:
                        first, second = psi, first
                    elif lo < psi < second:
                        second = psi
    a, b = (ax, ay, az), (bx, by, bz)
    area = _nearer_fan_area(centre + lo, centre + first, a, b, h)
    area += _nearer_fan_area(centre + first, centre + second, a, b, h)
    area += _nearer_fan_area(centre + second, centre + hi, a, b, h)
    return max(area, 0.0)


@numba.njit(cache=True)
def shadowed_area(ax, ay, az, bx, by, bz, h, correlated):
    """Area of centres (unit space) whose grain blocks a or b from a void point at height h.

    Correlated: sigma_s(a) + sigma_s(b) - sigma_cap (Eq. 18); uncorrelated: no overlap (Eq. 17).
    """
    sa = shadow_area(math.sqrt(ax * ax + ay * ay), az, h)
    sb = shadow_area(math.sqrt(bx * bx + by * by), bz, h)
    if not correlated:
        return sa + sb
    return max(sa + sb - overlap_area(ax, ay, az, bx, by, bz, h), max(sa, sb))


@numba.njit(cache=True)
def _shadowed_areas(a, b, h, correlated):
    out = np.empty(a.shape[0])
    for n in range(a.shape[0]):
        out[n] = shadowed_area(a[n, 0], a[n, 1], a[n, 2], b[n, 0], b[n, 1], b[n, 2], h[n], correlated)
    return out


def g_distant(wi, wo, h, tau0, beta_x, beta_y, correlated=True) -> np.ndarray:
    """G^dist(i, o, h'): neither i nor o blocked from a void point at height h' (Eq. 17-19).

    exp(ln(1 - tau0) / pi * area), the area of ``shadowed_area`` in unit space. The unnumbered
    line before Eq. 19 prints det E^-1 after the exponential; it scales the area inside it, as
    Eq. 19 itself has it (check: test_g1_distant_matches_ray_casting, anisotropic cases).
    ``wi``, ``wo`` (..., 3) true-space directions with z > 0; ``h`` broadcasts with them.
    """
    a = unit_space_direction_array(wi, beta_x, beta_y)
    b = unit_space_direction_array(wo, beta_x, beta_y)
    h = np.asarray(h, dtype=np.float64)
    shape = np.broadcast_shapes(a.shape[:-1], b.shape[:-1], h.shape)
    a = np.ascontiguousarray(np.broadcast_to(a, shape + (3,)).reshape(-1, 3))
    b = np.ascontiguousarray(np.broadcast_to(b, shape + (3,)).reshape(-1, 3))
    h = np.ascontiguousarray(np.broadcast_to(h, shape).reshape(-1))
    area = _shadowed_areas(a, b, h, correlated)
    return np.exp(-grain_extinction(tau0) / math.pi * area).reshape(shape)


def g1_distant(w, h, tau0, beta_x, beta_y) -> np.ndarray:
    """G1^dist(w, h') = exp(ln(1 - tau0) / pi * sigma_s(w', h')) (Eq. 16, anisotropic via Eq. 19)."""
    return g_distant(w, w, h, tau0, beta_x, beta_y, correlated=True)


def pore_visibility(wi, wo, tau0, beta_x, beta_y, correlated=True) -> np.ndarray:
    """V_p(i, o) = (1 - tau0) G^dist(i, o, 0) (Eq. 23): base-plane points lit and seen."""
    return (1.0 - tau0) * g_distant(wi, wo, 0.0, tau0, beta_x, beta_y, correlated)


def smith_lambda(w, tau0, beta_x, beta_y, nodes: int = LAMBDA_NODES) -> np.ndarray:
    """Smith Lambda of the micrograin NDF, Lambda(w) = integral D(m) (w.m)+ dm / (w.n) - 1.

    We know no closed form (public implementations sum a series in lambda cut after 7 terms:
    equal to this to 1e-13 at tau0 = 0.1, but half of it at tau0 = 0.9999, theta = 80 deg), so it
    is computed by quadrature. The NDF is shape-invariant (Eq. 10), so Lambda(w) = Lambda_1(w')
    in unit space, where the normals are those of a unit sphere at height h = m'.z with the
    covered-area density p(h) = 2 lambda h exp(-lambda (1 - h^2)) / tau0 (the CDF of Eq. 13 in
    h) and a uniform azimuth. The azimuthal integral of (w.m)+ is closed-form; h >= sin(theta')
    is fully lit (closed form), h < sin(theta') uses ``end_graded_gauss_rule`` (32 nodes: 1e-10).
    """
    wp = unit_space_direction_array(w, beta_x, beta_y)
    c = np.maximum(wp[..., 2], _TINY_COS)
    s = np.hypot(wp[..., 0], wp[..., 1])
    lam = grain_extinction(tau0)
    lit = c * -np.expm1(-lam * c * c) / tau0
    x, wx = end_graded_gauss_rule(nodes)
    h = 0.5 * s[..., None] * (x + 1.0)
    wh = 0.5 * s[..., None] * wx
    a = s[..., None] * np.sqrt(1.0 - h * h)
    b = c[..., None] * h
    with np.errstate(divide="ignore", invalid="ignore"):
        phi0 = np.arccos(np.clip(-b / a, -1.0, 1.0))
    lune = np.where(a > 0.0, (a * np.sin(phi0) + b * phi0) / np.pi, b)
    weight = 2.0 * lam * np.exp(-lam * (1.0 - h * h)) / tau0
    partial = np.sum(wh * weight * lune, axis=-1)
    return (lit + partial) / c - 1.0
