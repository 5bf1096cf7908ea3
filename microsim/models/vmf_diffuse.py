"""The vMF diffuse BRDF (d'Eon and Weidlich 2024), ``vmf_diffuse``.

Paper: d'Eon and Weidlich 2024 (VMF Diffuse; docs/reference/papers.md), whose equation, section
and appendix numbers are cited below.

One-sided Lambertian flakes of albedo c (``albedo``) with the von Mises-Fisher NDF (Eq. 1) of
shape alpha = -log(1 - sqrt(r)) (Eq. 2), r = ``roughness`` in [0, 1]; r = 1 is alpha = inf
(uniformly oriented flakes: the Lambert-sphere medium). The fitted form is (Eq. 7)

    f = c f1 + c^2 f2 + c^3 f3 + f_m,   f_k = f_k^(0) + 2 f_k^(1) cos(phi) + 2 f_k^(2) cos(2 phi)

with phi the relative azimuth (phi = 0 backscatter, docs/conventions.md §1: the fitted
cos(phi) coefficients of f1 are positive, the retro-reflection that a Monte-Carlo simulation of
the flake medium shows), f1 from Section 3.3 with the cross section sigma of Eq. 4-6, f2 and f3
from Appendix A, f_m from Eq. 9. ``kd`` replaces ``albedo`` by the remap of Section 5 (meant
to make the albedo at normal incidence kd; it misses by up to 29 %, see :func:`albedo_from_kd`).
:meth:`VMFDiffuse.orders` returns the four terms separately (the scattering orders 1, 2, 3, 4+
of a table).

Corrections to the printed text (tests/test_models_vmf.py checks each):

- Fourier convention. The text writes f_k^(0) + f_k^(1) cos(phi) + f_k^(2) cos(2 phi), but the
  fitted modes follow Horak-Chandrasekhar's f^(0) + 2 sum f^(m) cos(m phi) (the convention of
  d'Eon 2021, Eq. 28, which is half the cos(phi) coefficient of its single scattering): the
  exact single scattering of the flake medium, integral D(m) <i.m><o.m> dm
  / (pi (mu_o sigma(mu_i) + mu_i sigma(-mu_o))), has cos(phi) coefficients 1.72-2.16 times
  (median 1.96) the printed f1^(1) and cos(2 phi) coefficients a median 2.04 times f1^(2)
  (16 cosine pairs at each of r = 0.2, 0.5, 1); with the factor 2 the
  fitted orders 1, 2, 3 match a Monte-Carlo simulation of the flake medium cell by cell
  (median deviation 1-3 %, against 11-19 % for order 1 without it).
- Eq. 4 prints exp(+u^2 / (alpha^2 (1 - u^2))); the Beckmann projected area it modifies has
  exp(-a^2), a = u / (alpha sqrt(1 - u^2)); only that sign meets sigma(u, 0) = u Theta(u) and
  the exact integral Eq. 3.
- Eq. 9 (f_m) is used with its bracket clamped, max(0, tanh(r) - 0.09 - 0.0579 /
  (mu_i mu_o + 0.288)), in place of |tanh(r) - 0.09| - 0.0579 / (mu_i mu_o + 0.288), and the
  whole term clamped at 0. As printed, f_m at r = 0 spans -0.03 to +0.01 1/sr for c = 1 (no
  Lambert limit, which the paper states, and a white albedo of 1.02) and it is negative for
  c < 0.34 or r < 0.3 (down to -0.06 in albedo at r = 0.1, c = 0.95), while f_m sums path
  contributions. Both forms agree wherever the printed one is positive (r >= 0.3, c > 0.34).
  Below, a Monte-Carlo simulation of the flake medium gives a 4+ albedo under 0.009; the
  clamped form stays within 0.012 of it, the printed one is off by up to 0.06.

Accuracy and energy of the published fit (measured against that simulation, not corrected):
the albedos of orders 1, 2, 3 agree within 0.017, 0.007, 0.004 (order 1 within 2.3 %); the
4+ albedo is off by up to a factor 2.5 for 0.2 <= r <= 0.35 and by +0.04 at r = 1, c = 0.95,
and rises as sqrt(1 - c) towards c = 1. So the directional albedo exceeds c near r = 0.25
(by <= 0.022) and exceeds 1 for c >= 0.97 (up to 1.14 at c = 1, r = 0.95, theta_i = 89.9 deg);
the BRDF turns negative in forward-grazing pairs (none with both angles <= 80 deg, -0.017 1/sr
with both <= 85 deg, -2.1 1/sr at 89.9 deg), where the exact single scattering vanishes
while the fitted f1^(0) falls 10-20 % below the exact one (its cos(phi) mode matches).
Reciprocal: all terms are symmetric in (mu_i, mu_o) except the f1 denominator
mu_i sigma(-mu_o) + mu_o sigma(mu_i), which is symmetric because the odd part of sigma is
linear in u in every branch (exactly u L(2/alpha^2) / 2 in Eq. 4 and 6).
"""

import math

import numpy as np
from scipy.special import erf

from microsim.models.base import BRDFModel, Param, register

ALPHA_LOW = 0.25
ALPHA_HIGH = 0.9


def alpha_from_roughness(r: float) -> float:
    """Eq. 2: alpha = -log(1 - sqrt(r)); inf at r = 1."""
    return math.inf if r >= 1.0 else -math.log1p(-math.sqrt(r))


def _langevin_terms(x: float) -> tuple[float, float]:
    """L(x) = coth x - 1/x and Q(x) = 4 - 12 L(x) / x, by series below x = 0.01 (both -> 0)."""
    if x < 0.01:
        x2 = x * x
        return x * (1.0 / 3.0 - x2 / 45.0 + 2.0 * x2 * x2 / 945.0), x2 * (4.0 / 15.0 - 8.0 * x2 / 315.0)
    lang = 1.0 / math.tanh(x) - 1.0 / x
    return lang, 4.0 - 12.0 * lang / x


def cross_section(u, alpha: float) -> np.ndarray:
    """sigma^vMF(u, alpha) = integral D^vMF(m) <u.m> dm for cosines u in [-1, 1] (Eq. 4-6).

    alpha = 0 gives u Theta(u) exactly; alpha = inf gives 1/4. Eq. 6 is evaluated as
    (5/128)(3u^2 - 1) Q(x) + (u/2) L(x) + 1/4 with x = 2/alpha^2, the same expression without
    the cancellation of 3 alpha^4 - 6 alpha^2 coth(2/alpha^2) + 4 at large alpha.
    """
    u = np.asarray(u, dtype=np.float64)
    if alpha == 0.0:
        return np.maximum(u, 0.0)
    if alpha < ALPHA_LOW:
        a2 = alpha * alpha
        t = 1.0 / a2
        s = np.sqrt(np.maximum(1.0 - u * u, 0.0))
        with np.errstate(divide="ignore"):
            a = u / (alpha * s)
        # Eq. 4 as printed has exp(+a^2); exp(-a^2) is the Beckmann form it builds on.
        beckmann = 0.5 * (u * (erf(a) + 1.0) + alpha * s * np.exp(-a * a) / math.sqrt(math.pi))
        correction = 0.25 * (math.tanh(t) * (u - a2 * np.abs(u)) + (-a2 - 2.0) * u + u / math.tanh(t))
        return correction + beckmann
    if alpha < ALPHA_HIGH:
        u2 = u * u
        one_minus4 = (1.0 - alpha) ** 4
        return (
            0.25
            + (0.4975 - 0.273731 * (alpha - 0.1) ** 1.7) * u
            + (0.153918 - 0.139522 * (alpha - 0.1) ** 1.2) * (3.0 * u2 - 1.0)
            - (0.013762 + (0.013922 * alpha - 0.027553) * alpha) * (3.0 - 30.0 * u2 + 35.0 * u2 * u2)
            + 0.048357 * np.abs(one_minus4 * u2**4)
            - 0.033493 * one_minus4 * np.cos(7.7 * u)
        )
    lang, q = _langevin_terms(0.0 if math.isinf(alpha) else 2.0 / (alpha * alpha))
    return 5.0 / 128.0 * (3.0 * u * u - 1.0) * q + 0.5 * u * lang + 0.25


def _coefficients(r: float) -> dict:
    """The fitted constants C_kjl(r) of Section 3.3 and Appendix A."""
    r2, r3, r4, r5 = r**2, r**3, r**4, r**5
    r25, r45 = r**2.5, r**4.5
    return {
        "C100": 1.0 + (0.84 * r4 - 0.1 * r) / (9.0 * r3 + 1.0),
        "C101": (-9.47 * r3 + 20.4 * r2 + 0.0173 * r) / (7.46 * r + 1.0),
        "C102": (2.37 * r2 - 0.927 * r) / (r2 + 1.24),
        "C103": (-1.54 * r2 - 0.11 * r) / (7.1 * r2 - 1.05 * r + 1.0),
        "C110": (0.54 * r - 0.182 * r3) / (1.32 * r2 + 1.0),
        "C111": (-0.375 * r3 + 0.62 * r2 - 0.097 * r) / (0.4 * r3 + 1.0),
        "C112": -0.681 * r2 + 0.862 * r + 0.283,
        "C120": (5.1 * r2 + 2.25 * r) / (32.4 * r2 + 9.8 * r + 1.0),
        "C121": (6.0 * r3 - 4.32 * r) / (287.0 * r3 + 9.7 * r + 1.0),
        "C200": (0.226 * r2 + 0.00056 * r) / (7.07 * r2 + 1.0),
        "C201": (-12.04 * r3 + 4.57 * r2 - 0.268 * r) / (36.7 * r3 + 1.0),
        "C202": (-0.97 * r3 + 2.52 * r2 + 0.418 * r) / (10.0 * r2 + 1.0),
        "C203": (2.65 * r3 - 2.25 * r2 + 0.068 * r) / (21.4 * r3 + 1.0),
        "C204": (0.05 * r - 4.22 * r3) / (43.1 * r3 + 17.6 * r2 + 1.0),
        "C210": (-0.027 * r3 - 0.049 * r) / (3.36 * r2 + 1.0),
        "C211": (-8.332 * r25 + 6.073 * r3 + 2.77 * r2) / (50.0 * r4 + 1.0),
        "C212": (-0.295 * r3 - 0.431 * r2) / (23.9 * r3 + 1.0),
        "C300": (0.262 * r4 - 0.083 * r3) / (38.6 * r4 - 1.9 * r2 + 1.0),
        "C301": (4.95 * r25 - 2.44 * r3 - 0.627 * r2) / (31.5 * r4 + 1.0),
        "C302": (0.31 * r25 + 1.4 * r3 + 0.33 * r2) / (20.0 * r3 + 1.0),
        "C303": (1.77 * r25 - 4.06 * r3 - 0.74 * r2) / (215.0 * r5 + 1.0),
        "C304": -1.026 * r3 / (13.2 * r3 + 5.81 * r2 + 1.0),
        "C310": (0.028 * r2 - 0.0132 * r3) / (-3.315 * r4 + 7.46 * r2 + 1.0),
        "C311": (0.162 * r25 + 0.302 * r3 - 0.134 * r2) / (57.5 * r45 + 1.0),
        "C312": (0.5 * r25 - 0.207 * r3 - 0.119 * r2) / (18.7 * r3 + 1.0),
    }


def albedo_from_kd(kd: float, r: float) -> float:
    """Section 5: flake albedo c from kd, the paper's remap meant to give the albedo kd at normal
    incidence (with this model that albedo is within -29 % to +4 % of kd, measured).

    c = ((-1 + kd + sqrt((1 - kd)^2 + 4 s^2 kd^2)) / (2 s kd)) sqrt(r) + (1 - sqrt(r)) kd,
    s = 0.64985 + 0.631112 r + 1.38922 r^2; the first fraction is evaluated in the
    rationalised form 2 s kd / ((1 - kd) + sqrt((1 - kd)^2 + 4 s^2 kd^2)) (finite at kd = 0).
    """
    s = 0.64985 + 0.631112 * r + 1.38922 * r * r
    root = math.sqrt((1.0 - kd) ** 2 + 4.0 * s * s * kd * kd)
    frac = 2.0 * s * kd / ((1.0 - kd) + root) if kd > 0.0 else 0.0
    return frac * math.sqrt(r) + (1.0 - math.sqrt(r)) * kd


def higher_orders(c: float, r: float, ui, uo) -> np.ndarray:
    """f_m, fourth and higher orders (Eq. 9), with the reconstruction of the module docstring.

    C_k = (-0.453 (1-c) - 0.544 sqrt(1-c) + 1) / (1.429 sqrt(1-c) + 1) (the Lambert-sphere
    albedo of c, d'Eon 2021, Eq. 40) and
    C_a = c (1.169 sqrt(1-c) + 1)^(-atan((r - 0.265) r + 0.0225) erf(sqrt(1-c))).
    """
    s = math.sqrt(1.0 - c)
    c_k = (-0.453 * (1.0 - c) - 0.544 * s + 1.0) / (1.429 * s + 1.0)
    c_a = c * (1.169 * s + 1.0) ** (-math.atan((r - 0.265) * r + 0.0225) * math.erf(s))
    bracket = np.maximum(math.tanh(r) - 0.09 - 0.0579 / (ui * uo + 0.288), 0.0)
    return np.maximum(0.384 * c_k * (c_a - 0.342) * c_a, 0.0) * bracket


@register
class VMFDiffuse(BRDFModel):
    name = "vmf_diffuse"
    params = (
        Param("albedo", "Lambertian albedo c of the microsurface (give albedo or kd)", None, 0.0, 1.0),
        Param("kd", "albedo of the BRDF at normal incidence (Sec. 5 remap; give albedo or kd)", None, 0.0, 1.0),
        Param("roughness", "r of Eq. 2: 0 = Lambert, 1 = Lambert sphere", None, 0.0, 1.0),
    )
    reference = "d'Eon and Weidlich 2024 (VMF Diffuse), Eq. 1-9, Sec. 3.3, Sec. 5, Appendix A"

    def resolve(self, values):
        given = [k for k in ("albedo", "kd") if k in values]
        if len(given) != 1:
            got = ", ".join(given) or "neither"
            raise ValueError(f"model 'vmf_diffuse' needs exactly one of albedo, kd in [0, 1] (got {got})")
        if "roughness" not in values:
            raise ValueError("model 'vmf_diffuse' needs parameter roughness in [0, 1]")
        if "kd" in values:
            return {**values, "albedo": albedo_from_kd(values["kd"], values["roughness"])}
        return {"kd": None, **values}

    def setup(self):
        r = self.roughness
        self.alpha = alpha_from_roughness(r)
        self.coef = _coefficients(r)

    def orders(self, wi, wo) -> np.ndarray:
        """The terms c f1, c^2 f2, c^3 f3 and f_m of Eq. 7, shape (4, ...): the scattering
        orders 1, 2, 3 and 4+ of a table's ``brdf_order`` (0 below the horizon)."""
        wi, wo = np.broadcast_arrays(np.asarray(wi, dtype=np.float64), np.asarray(wo, dtype=np.float64))
        shape = wi.shape[:-1]
        wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
        out = np.zeros((4, wi.shape[0]))
        above = (wi[:, 2] > 0.0) & (wo[:, 2] > 0.0)
        if above.any():
            out[:, above] = self._orders(wi[above], wo[above])
        return out.reshape((4, *shape))

    def _orders(self, wi, wo):
        c, r, k = self.albedo, self.roughness, self.coef
        ui, uo = wi[:, 2], wo[:, 2]
        cos_phi_term = 2.0 * (wi[:, 0] * wo[:, 0] + wi[:, 1] * wo[:, 1])
        sin2 = (1.0 - ui * ui) * (1.0 - uo * uo)
        cos_2phi_term = cos_phi_term**2 - 2.0 * sin2
        pi, uiuo, usum = math.pi, ui * uo, ui + uo

        s_i = cross_section(ui, self.alpha)
        s_o = cross_section(uo, self.alpha)
        s_mo = cross_section(-uo, self.alpha)
        denom = ui * s_mo + uo * s_i
        f1 = (
            s_i * s_o / denom * (k["C100"] + k["C101"] * uiuo + k["C102"] * uiuo**2 + k["C103"] * (ui**2 + uo**2))
            + (s_i * s_o) ** k["C112"] / denom * cos_phi_term * (k["C110"] + k["C111"] * uiuo)
            + (k["C120"] + k["C121"] * ui) * (k["C120"] + k["C121"] * uo) * cos_2phi_term / usum
        ) / pi
        f2 = (
            k["C200"] + k["C201"] * uiuo + k["C202"] * usum + k["C203"] * uiuo**2 + k["C204"] * (ui**2 + uo**2)
            + cos_phi_term * (k["C210"] + k["C211"] * uiuo + k["C212"] * usum)
        ) / (pi * usum)
        f3 = (
            k["C300"] + k["C301"] * uiuo + k["C302"] * usum + k["C303"] * uiuo**2 + k["C304"] * (ui**2 + uo**2)
            + cos_phi_term * (k["C310"] + k["C311"] * uiuo + k["C312"] * usum)
        ) / (pi * usum)
        return np.stack([c * f1, c * c * f2, c**3 * f3, higher_orders(c, r, ui, uo)])

    def _eval(self, wi, wo):
        return np.sum(self._orders(wi, wo), axis=0)
