"""Single scattering of a Boolean suspension of Lambertian spheres, with its finite-size terms.

The radiative-transfer limit is the Lambert-sphere half space, f1 = c p(-wi.wo) / (mu_i + mu_o)
(d'Eon 2021, Eqs. 1 and 10): point scatterers, independent of the density. Real spheres of
radius r in a Boolean model (docs/conventions.md §5.2, free path l) differ from it at first order
in r / l in two ways, and this model keeps both:

    f = c p(-wi.wo) / (mu_i + mu_o) * (I + k (r / l) M),    k = 1/mu_i + 1/mu_o.

Derivation (r = 1, n = 1 / (pi l) centres per volume). A hit point x on a sphere with normal m
lies at depth h_x = h_c - m_z below the top z = 0, where h_c is its centre's depth. By Slivnyak's
theorem the other centres stay Poisson, so the light reaches x and leaves it along wo unblocked
with probability exp(-n V), V the volume (within z < 0) of centres closer than r to either ray
from x. Deep in the medium V = pi r^2 k h_x - O(h_x): two half-infinite cylinders and the ball
of x, less their common part O (the centres that would block both rays at once).

* ``I = (k / l) int_0^inf exp(-n V(h)) dh`` is shadow hiding, the opposition effect of finite
  particles: O(h) is the volume common to the two cylinders outside the ball of x, below the
  top, and V is kept exactly as cut by the top plane (which matters at grazing angles). I tends
  to 2 at retro as r / l -> 0 (the classical doubling; 2 exp(-2 r / 3 l) at normal retro, the
  half ball of x), and its 1 / tan(g / 2) tail in the phase angle g is still +1 to +2 % at
  g = 30 deg for phi = 0.02.
* ``M`` = mean m_z over the lit and visible surface, weight (m.wi)(m.wo): the hit point's height
  above its centre lowers the attenuation by exp(k m_z / l). Integrating the weight over the
  lune of directions lit and seen gives, with alpha half the angle between wi and wo and u the
  bisector, ``M = u_z (3 pi / 8) cos^3 alpha / ((pi/2 - alpha) cos 2 alpha + sin alpha cos alpha)``
  (M = 3/4 at normal retro).

Dropped: the attenuation of hit points above the top (h < 0) inside the M term, O(k (r / l)^2).
Against order-1 tables of the tracer (16 realizations, so 1.15 is expected) chi^2 per cell is
1.01-1.41 for phi = 0.005 and 0.02 at theta_i = 0-85 deg (tests/test_single_scattering.py and
benchmarks/dilute_limit.py, which also covers phi = 0.01-0.08). The expansion needs k r / l
small: at grazing retro with k r / l > 1 the neglected attenuation of hit points above the
top matters. r / l = -3/4 ln(1 - phi) comes from :mod:`microsim.physics.boolean_model`, the relations the
scene generator uses too.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from microsim.models.base import BRDFModel, Param, register
from microsim.models.radiative_transfer import single_scattering
from microsim.physics.boolean_model import radius_over_free_path

#: Midpoint nodes across the common part of the two cylinders (t) and along it inside the ball (s),
#: and the depth grid of O(h).
_NODES_T, _NODES_S, _NODES_H = 16, 24, 64


@numba.njit(cache=True)
def _frame(a, b):
    """Bisector u, in-plane unit e1 (towards a), normal e2, and the half angle of (a, b)."""
    u = a + b
    e1 = a - b
    norm_u = math.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
    norm = math.sqrt(e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2])
    alpha = math.atan2(norm, norm_u)  # accurate near retro and near opposite directions
    u = u / norm_u
    if norm < 1e-12:  # retro: any direction normal to u
        e1 = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        e1 = e1 - (e1[0] * u[0] + e1[1] * u[1] + e1[2] * u[2]) * u
        norm = math.sqrt(e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2])
    e1 = e1 / norm
    e2 = np.array([u[1] * e1[2] - u[2] * e1[1], u[2] * e1[0] - u[0] * e1[2], u[0] * e1[1] - u[1] * e1[0]])
    return u, e1, e2, alpha


@numba.njit(cache=True)
def _clip(xs, ys, count, a, b, c):
    """Clip the convex polygon (xs, ys)[:count] to a x + b y <= c, in place; new count."""
    out_x, out_y = np.empty(count + 1), np.empty(count + 1)
    kept = 0
    for i in range(count):
        j = (i + 1) % count
        di, dj = a * xs[i] + b * ys[i] - c, a * xs[j] + b * ys[j] - c
        if di <= 0.0:
            out_x[kept], out_y[kept] = xs[i], ys[i]
            kept += 1
        if (di < 0.0 < dj) or (dj < 0.0 < di):
            f = di / (di - dj)
            out_x[kept], out_y[kept] = xs[i] + f * (xs[j] - xs[i]), ys[i] + f * (ys[j] - ys[i])
            kept += 1
    xs[:kept], ys[:kept] = out_x[:kept], out_y[:kept]
    return kept


@numba.njit(cache=True)
def _area(xs, ys, count):
    total = 0.0
    for i in range(count):
        j = (i + 1) % count
        total += xs[i] * ys[j] - xs[j] * ys[i]
    return 0.5 * abs(total)


@numba.njit(cache=True)
def common_volume(a, b, heights, nodes_t, nodes_s):
    """O(h) for every h of ``heights``: volume of the points q within 1 of both rays {t a} and
    {t b}, t >= 0, outside the unit ball, with q_z < h (x at the origin, r = 1).

    In the frame (u, e1, e2) a point is s u + p e1 + t e2, and q_z is linear in (s, p). Across,
    t = -cos(theta) with the midpoint rule in theta. At each t the section outside the ball,
    s >= sqrt(1 - t^2), is a convex polygon of the (s, p) plane (both cylinders, both half-spaces
    q.a, q.b >= 0), clipped exactly below h; inside, |p| runs from the ball's edge to the
    cylinders' reach: exact in p, midpoint rule in s.
    """
    out = np.zeros(heights.shape[0])
    u, e1, e2, alpha = _frame(a, b)
    sa, ca = math.sin(alpha), math.cos(alpha)
    if ca < 1e-9:
        return out
    reach_max = 1.0 / ca
    s_cap = (heights[-1] + 1.0 + reach_max * abs(e1[2])) / u[2]  # beyond it every point is higher
    xs, ys = np.empty(12), np.empty(12)
    for it in range(nodes_t):  # t = -cos(theta), midpoint in theta: smooth across the cylinder's edge
        theta = (it + 0.5) * math.pi / nodes_t
        t, w = -math.cos(theta), math.sin(theta)
        dt = w * math.pi / nodes_t
        lift = t * e2[2]
        # the ball zone 0 <= s < w
        ds = w / nodes_s
        for i_s in range(nodes_s):
            s = (i_s + 0.5) * ds
            reach = (w - s * sa) / ca
            if sa > 0.0:
                reach = min(reach, s * ca / sa)
            inner = math.sqrt(max(0.0, 1.0 - s * s - t * t))
            if inner >= reach:
                continue
            base, slope = s * u[2] + lift, e1[2]
            for j in range(heights.shape[0]):
                h = heights[j]
                length = 0.0
                for lo, hi in ((-reach, -inner), (inner, reach)):
                    if abs(slope) < 1e-15:
                        length += (hi - lo) if base < h else 0.0
                    elif slope > 0.0:
                        length += max(0.0, min(hi, (h - base) / slope) - lo)
                    else:
                        length += max(0.0, hi - max(lo, (h - base) / slope))
                out[j] += length * dt * ds
        # beyond the ball: the polygon, clipped at each height
        if w >= s_cap:
            continue
        for j in range(heights.shape[0]):
            xs[:4] = np.array([w, s_cap, s_cap, w])
            ys[:4] = np.array([-reach_max - 1.0, -reach_max - 1.0, reach_max + 1.0, reach_max + 1.0])
            count = _clip(xs, ys, 4, sa, ca, w)
            count = _clip(xs, ys, count, sa, -ca, w) if count else 0
            count = _clip(xs, ys, count, -ca, sa, 0.0) if count else 0
            count = _clip(xs, ys, count, -ca, -sa, 0.0) if count else 0
            count = _clip(xs, ys, count, u[2], e1[2], heights[j] - lift) if count else 0
            if count >= 3:
                out[j] += _area(xs, ys, count) * dt
    return out


@numba.njit(cache=True)
def lit_visible_height(a, b):
    """M: mean m_z over the sphere, weight (m.a)+ (m.b)+ (closed form in the module docstring)."""
    u, _, _, alpha = _frame(a, b)
    eps = 0.5 * math.pi - alpha
    if eps < 1e-4:  # a = -b: both limits are eps^3, the ratio tends to 9 pi / 32
        return u[2] * 9.0 * math.pi / 32.0
    denominator = eps * math.cos(2.0 * alpha) + math.sin(alpha) * math.cos(alpha)
    return u[2] * 0.375 * math.pi * math.cos(alpha) ** 3 / denominator


@numba.njit(cache=True)
def _ball_below(h):
    """Volume of the unit ball about the hit point below the top, the hit point at depth h >= 0."""
    if h >= 1.0:
        return 4.0 * math.pi / 3.0
    return 2.0 * math.pi / 3.0 + math.pi * (h - h**3 / 3.0)


@numba.njit(cache=True)
def shadow_hiding(a, b, r_over_l, nodes_t=_NODES_T, nodes_s=_NODES_S, nodes_h=_NODES_H):
    """I = (k / l) int_0^inf exp(-n V(h)) dh, V = ball + C_a + C_b - O below the top, each cut
    exactly by the top plane (C_a: the half-cylinder of a outside the ball, common_volume(a, a));
    deep down -n V = -k h / l + n O(h). Exponential-linear between depth nodes, spaced as the
    square of a uniform grid: fine near the top, where the volumes bend."""
    kl = (1.0 / a[2] + 1.0 / b[2]) * r_over_l
    n = r_over_l / math.pi
    alpha = _frame(a, b)[3]
    top = 40.0 / kl  # exp(-40): nothing deeper matters
    if math.sin(alpha) > 1e-12:
        top = min(top, 1.0 / math.sin(alpha) + 2.0)  # below, O is constant and C_a, C_b linear
    heights = top * np.linspace(0.0, 1.0, nodes_h) ** 2
    volume = (common_volume(a, a, heights, nodes_t, nodes_s) + common_volume(b, b, heights, nodes_t, nodes_s)
              - common_volume(a, b, heights, nodes_t, nodes_s))
    exponent = np.empty(nodes_h)
    for j in range(nodes_h):
        exponent[j] = -n * (volume[j] + _ball_below(heights[j]))
    total = 0.0
    for j in range(nodes_h - 1):
        width = heights[j + 1] - heights[j]
        rate = (exponent[j + 1] - exponent[j]) / width
        start = math.exp(exponent[j])
        if abs(rate * width) < 1e-8:
            total += start * width
        else:
            total += start * math.expm1(rate * width) / rate
    # below the last node the exponent decays at kl
    total += math.exp(exponent[-1]) / kl
    return kl * total


@numba.njit(cache=True)
def finite_size_ratio(wi, wo, r_over_l):
    """f / f_RT = I + k (r / l) M for each pair of rows."""
    out = np.empty(wi.shape[0])
    for i in range(wi.shape[0]):
        a, b = wi[i].copy(), wo[i].copy()
        k = 1.0 / a[2] + 1.0 / b[2]
        out[i] = shadow_hiding(a, b, r_over_l) + k * r_over_l * lit_visible_height(a, b)
    return out


@register
class BooleanSpheresSingle(BRDFModel):
    name = "boolean_spheres_single"
    params = (
        Param("albedo", "albedo c of the Lambertian spheres", None, 0.0, 1.0),
        Param("volume_fraction", "phi of the Boolean model (first order in r / l = -3/4 ln(1 - phi))",
              None, 0.0, 0.1, lo_open=True),
    )
    reference = ("single scattering only (compare with --order 1): d'Eon 2021 (Lambert-sphere BRDF), "
                 "Eqs. 1, 10 times the shadow-hiding and finite-size terms derived in "
                 "microsim/models/boolean_spheres.py")

    def setup(self) -> None:
        self.r_over_l = radius_over_free_path(self.volume_fraction)

    def _eval(self, wi, wo):
        return single_scattering(wi, wo, self.albedo) * finite_size_ratio(wi, wo, self.r_over_l)
