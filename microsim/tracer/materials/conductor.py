"""The material ``conductor``: a smooth metal of complex index eta + i k.
"""

from __future__ import annotations

from typing import ClassVar, Literal

import numpy as np
from pydantic import Field

from microsim.physics.fresnel import fresnel_conductor
from microsim.physics.sampling import reflect
from microsim.tracer.materials.base import Material

#: cosines at which a conductor's reflectance is probed for its largest value
_CONDUCTOR_PROBES = 101

class Conductor(Material):
    """Smooth metal with complex index eta + i k: mirror reflection, weight x Fresnel reflectance
    (exact unpolarised form, :mod:`microsim.physics.fresnel`)."""

    kind: Literal["conductor"]
    eta: float = Field(gt=0.0, le=100.0, description="real part of the complex index")
    k: float = Field(ge=0.0, le=100.0, description="imaginary part of the complex index")
    example: ClassVar[dict] = {"eta": 0.2, "k": 3.0}
    delta_lobes: ClassVar[str] = "its mirror reflection (Fresnel-weighted)"
    continuous: ClassVar[bool] = False

    def albedo_bound(self) -> float:
        cosines = np.linspace(0.0, 1.0, _CONDUCTOR_PROBES)
        return float(max(fresnel_conductor(c, self.eta, self.k) for c in cosines))

    @staticmethod
    def sample(prm, states, i, d, n):
        cos_i = -(d[0] * n[0] + d[1] * n[1] + d[2] * n[2])
        return reflect(d, n), fresnel_conductor(cos_i, prm[0], prm[1]), 0.0


CONDUCTOR = Conductor.code
