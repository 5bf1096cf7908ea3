"""The material ``mirror``: the perfect conductor, mirror reflection with F = 1 at every angle.
"""

from __future__ import annotations

from typing import ClassVar, Literal

from microsim.physics.sampling import reflect
from microsim.tracer.materials.base import Material


class Mirror(Material):
    """The perfect conductor (conventions §4): mirror reflection with F = 1 at every angle."""

    kind: Literal["mirror"]
    example: ClassVar[dict] = {}
    delta_lobes: ClassVar[str] = "its mirror reflection"
    continuous: ClassVar[bool] = False

    @staticmethod
    def sample(prm, states, i, d, n):
        return reflect(d, n), 1.0, 0.0


MIRROR = Mirror.code
