"""The material ``lambert``: a Lambertian reflector, of one albedo or several traced together.
"""

from __future__ import annotations

import math
from typing import ClassVar, Literal

import pydantic
from pydantic import Field

from microsim.physics.sampling import sample_cosine
from microsim.tracer.materials.base import MAX_ALBEDOS, Material


class Lambert(Material):
    """Lambertian reflector: cosine sampling about the shading normal, weight x albedo.

    ``albedo`` may be a list (conventions §4, every albedo from one run): the material scatters
    with the largest, and a run tallies each exit for every listed albedo
    (:class:`microsim.core.tally.Tally`)."""

    kind: Literal["lambert"]
    albedo: float | list[float] = Field(description="Lambertian albedo in [0, 1], or a list of them: every "
                                                    "albedo from one run")
    example: ClassVar[dict] = {"albedo": 0.7}

    @pydantic.field_validator("albedo", mode="before")
    @classmethod
    def _one_or_several(cls, value):
        """A number in [0, 1], or a list of 1 to MAX_ALBEDOS distinct ones, the largest above 0
        (the message starts with the field's name; the config adds its section)."""
        accepted = (f"accepted: a number in [0, 1], or a list of 1 to {MAX_ALBEDOS} distinct numbers in [0, 1] "
                    "(the largest above 0)")
        numbers = value if isinstance(value, list) else [value]
        if not numbers or len(numbers) > MAX_ALBEDOS or any(
                isinstance(v, bool) or not isinstance(v, (int, float)) for v in numbers):
            raise ValueError(f"albedo = {value!r}: {accepted}")
        if not all(0.0 <= v <= 1.0 for v in numbers):
            raise ValueError(f"albedo = {value!r}: out of range; {accepted}")
        if isinstance(value, list) and (len(set(numbers)) != len(numbers) or max(numbers) <= 0.0):
            raise ValueError(f"albedo = {value!r}: {accepted}")
        return [float(v) for v in value] if isinstance(value, list) else float(value)

    @property
    def albedos(self) -> tuple[float, ...]:
        """Every albedo of the material, in the order given (one unless ``albedo`` is a list)."""
        return tuple(self.albedo) if isinstance(self.albedo, list) else (self.albedo,)

    def row(self) -> tuple[float, ...]:
        return (max(self.albedos),)

    def albedo_bound(self) -> float:
        return max(self.albedos)

    @staticmethod
    def sample(prm, states, i, d, n):
        return sample_cosine(states, i, n), prm[0], 0.0

    @staticmethod
    def lobes(prm, white, wi, wo, n):
        return (1.0 if white else prm[0]) * (wo[0] * n[0] + wo[1] * n[1] + wo[2] * n[2]) / math.pi


LAMBERT = Lambert.code
