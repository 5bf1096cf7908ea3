"""The material ``absorber``: absorbs everything.
"""

from __future__ import annotations

from typing import ClassVar, Literal

from microsim.tracer.materials.base import Material


class Absorber(Material):
    """Absorbs everything."""

    kind: Literal["absorber"]
    example: ClassVar[dict] = {}
    continuous: ClassVar[bool] = False

    def albedo_bound(self) -> float:
        return 0.0

    @staticmethod
    def sample(prm, states, i, d, n):
        return d, 0.0, 0.0


ABSORBER = Absorber.code
