"""Relations of the Boolean (Poisson germ-grain) models that microsim's scenes are built from.

One home for the formulas that a scene generator and the analytic model of the same scene must
share, so that the two can never drift apart (generators, models, benchmarks and tests import
them from here).

Boolean spheres (CONVENTIONS 5.2), radius r = 1, centres a Poisson process of n per unit
volume: a point is in the void when no centre lies within r of it, with probability
exp(-n 4/3 pi) = 1 - phi, so n = -ln(1 - phi) / (4/3 pi); a ray in the void travels an
exponential distance with mean l = 1 / (n pi r^2) = 4 / (-3 ln(1 - phi)) before it meets a
sphere, and r / l = n pi r^2 = -3/4 ln(1 - phi) measures the finite size of the spheres.
"""

from __future__ import annotations

import math


def number_density(phi: float) -> float:
    """Sphere centres per unit volume (radius 1): n = -ln(1 - phi) / (4/3 pi)."""
    return -math.log1p(-phi) / (4.0 / 3.0 * math.pi)


def radius_over_free_path(phi: float) -> float:
    """r / l = n pi r^2 = -3/4 ln(1 - phi): the sphere radius in mean void free paths."""
    return -0.75 * math.log1p(-phi)


def free_path(phi: float) -> float:
    """Mean void free path l = 4 / (-3 ln(1 - phi)) in radii (CONVENTIONS 5.2)."""
    return 1.0 / radius_over_free_path(phi)
