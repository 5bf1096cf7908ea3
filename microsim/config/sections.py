"""The sections of a run's config (docs/conventions.md §4), each a strict pydantic model.

Unknown keys, wrong types and out-of-range values are rejected. Scene kinds come from the
generator registry (``geometry.SCENES``) and material kinds from the material registry
(``microsim.tracer.materials.MATERIALS``), each with its own model, selected by ``kind``.
"""

from __future__ import annotations

import numbers
from typing import Annotated, Literal, Union

import pydantic
from pydantic import Field

from microsim import geometry
from microsim.config import full_brdf
from microsim.config.full_brdf import MAX_INCIDENCES
from microsim.config.messages import excerpt
from microsim.core.choices import BACKEND_CHOICES
from microsim.core.schema import Section
from microsim.tracer.materials import MATERIALS
from microsim.tracer.sensor import MAX_POINTS


def _is_number(value) -> bool:
    """A real number, of Python or numpy, not a bool."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


AnyMaterial = Annotated[Union[tuple(MATERIALS.values())], Field(discriminator="kind")]
Scene = Annotated[Union[tuple(g.Config for g in geometry.SCENES.values())], Field(discriminator="kind")]


class Illumination(Section):
    """Incidences: ``theta_i_deg`` a list; ``phi_i_deg`` one azimuth for all, or a list as long as
    ``theta_i_deg`` (one incidence per pair)."""

    theta_i_deg: list[Annotated[float, Field(ge=0.0, le=89.9)]] = Field(
        min_length=1, max_length=MAX_INCIDENCES, description="polar angle of each incidence, deg (one table row each); "
        "made by incidences where it is given")
    phi_i_deg: list[Annotated[float, Field(ge=-360.0, le=360.0)]] = Field(
        [0.0], min_length=1, max_length=MAX_INCIDENCES,
        description="one azimuth for all incidences, or one per theta_i_deg")
    incidences: int | None = Field(
        None, ge=2, le=MAX_INCIDENCES, description="a full BRDF: this many polar angles at the centres of the "
        "sensor's rings, from normal incidence to the last ring, those between keeping the widest gap in "
        "cos theta_i least, instead of theta_i_deg (microsim.config.full_brdf; what `--model table` and `microsim export` "
        "need: cos theta_i gaps of 0.25 at most, 6 incidences or more; fewer are refused before tracing)")
    azimuths: int | None = Field(None, ge=1, le=64, description="with incidences: each polar angle but 0 at this "
                                 "many azimuths 360 j / azimuths (an anisotropic scene's full BRDF; 1 if left out)")

    @pydantic.field_validator("theta_i_deg", mode="before")
    @classmethod
    def _scalar_to_list(cls, v):
        return [v] if isinstance(v, (int, float)) and not isinstance(v, bool) else v

    @pydantic.field_validator("phi_i_deg", mode="before")
    @classmethod
    def _one_azimuth(cls, v):
        """One number is kept as a list of one: the azimuth of every incidence."""
        return [v] if isinstance(v, (int, float)) and not isinstance(v, bool) else v

    @pydantic.model_validator(mode="after")
    def _paired(self):
        if len(self.phi_i_deg) not in (1, len(self.theta_i_deg)):
            raise ValueError(f"illumination.phi_i_deg: a list of {len(self.phi_i_deg)} azimuths for "
                             f"{len(self.theta_i_deg)} theta_i_deg; accepted: one number, or a list as long as "
                             "theta_i_deg")
        return self

    def azimuths_deg(self) -> list[float]:
        """phi_i of every incidence, paired with ``theta_i_deg``."""
        if len(self.phi_i_deg) == 1:
            return self.phi_i_deg * len(self.theta_i_deg)
        return list(self.phi_i_deg)


class SensorSection(Section):
    cells: int = Field(3240, ge=1, le=1_000_000, description="cells of the equal-solid-angle sensor, approximately "
                       "(the table stores the actual cells)")
    retro_rings: int = Field(0, ge=0, le=100_000, description="rings about the retro direction, tallied "
                             "apart from the cells (0: none); see microsim.tracer.sensor")
    retro_max_deg: float = Field(10.0, gt=0.0, le=90.0, description="phase angle the retro rings reach, deg")
    directions_deg: list[list[float]] = Field(
        [], description="exact directions [theta_o, phi_o] (phi_o the relative azimuth phi_o - phi_i; the "
                        "cells' azimuths are the scene's), deg, theta_o in [0, 90), "
                        f"phi_o in [-360, 360]: f there by next-event estimation (at most {MAX_POINTS} points "
                        "with retro_points_deg)")
    retro_points_deg: list[float] = Field(
        [], description="phase angles gamma in [0, 90) deg from the retro direction, towards the normal in the "
                        "plane of incidence: f there by next-event estimation")

    @pydantic.field_validator("directions_deg", mode="before")
    @classmethod
    def _directions(cls, value):
        """A list of [theta_o, phi_o] pairs of numbers, theta_o in [0, 90), phi_o in [-360, 360]."""
        accepted = "accepted: a list of [theta_o, phi_o] pairs, theta_o in [0, 90) and phi_o in [-360, 360] deg"
        value = value.tolist() if hasattr(value, "tolist") else value  # a numpy array from Python
        if not isinstance(value, (list, tuple)):
            raise ValueError(f"directions_deg = {excerpt(value)}: not a list; {accepted}")
        for k, pair in enumerate(value):
            if not isinstance(pair, (list, tuple)) or len(pair) != 2 or not all(map(_is_number, pair)):
                raise ValueError(f"directions_deg[{k}] = {excerpt(pair)}: not a pair of numbers; {accepted}")
            theta, phi = pair
            if not 0.0 <= theta < 90.0:
                where = "below the horizon" if theta >= 90.0 else "out of range"
                raise ValueError(f"directions_deg[{k}] = {excerpt(pair)}: theta_o {where}; {accepted}")
            if not -360.0 <= phi <= 360.0:
                raise ValueError(f"directions_deg[{k}] = {excerpt(pair)}: phi_o out of range; {accepted}")
        return [[float(theta), float(phi)] for theta, phi in value]

    @pydantic.field_validator("retro_points_deg", mode="before")
    @classmethod
    def _retro_points(cls, value):
        """A list of numbers in [0, 90)."""
        accepted = "accepted: a list of phase angles in [0, 90) deg"
        value = value.tolist() if hasattr(value, "tolist") else value  # a numpy array from Python
        if not isinstance(value, (list, tuple)) or not all(map(_is_number, value)):
            raise ValueError(f"retro_points_deg = {excerpt(value)}: not a list of numbers; {accepted}")
        for k, gamma in enumerate(value):
            if not 0.0 <= gamma < 90.0:
                raise ValueError(f"retro_points_deg[{k}] = {excerpt(gamma)}: out of range; {accepted}")
        return [float(gamma) for gamma in value]

    @pydantic.model_validator(mode="after")
    def _at_most_max_points(self):
        count = len(self.directions_deg) + len(self.retro_points_deg)
        if count > MAX_POINTS:
            # the key of the longer list: the one to shorten
            key = "directions_deg" if len(self.directions_deg) >= len(self.retro_points_deg) else "retro_points_deg"
            raise ValueError(f"sensor.{key}: {len(self.directions_deg):,} directions_deg and "
                             f"{len(self.retro_points_deg):,} retro_points_deg, {count:,} points; accepted: at "
                             f"most {MAX_POINTS} points together (each costs a shadow ray per scattering event)")
        return self

    @property
    def n_points(self) -> int:
        """Points of next-event estimation asked for (directions and retro points)."""
        return len(self.directions_deg) + len(self.retro_points_deg)


class Run(Section):
    paths: int = Field(ge=1, le=10**12, description="paths per incidence, over all realizations")
    realizations: int = Field(32, ge=2, le=100_000, description="independent geometry samples = batches of the standard errors")
    seed: int = Field(1, ge=0, le=2**63 - 1, description="random seed: of the geometry of each realization and of "
                      "the paths of each unit")
    max_order: int = Field(0, ge=0, le=1_000_000, description="the last scattering order traced (0: unlimited, "
                           "Russian roulette; 1: single scattering)")
    backend: Literal[BACKEND_CHOICES] = Field(
        "auto", description="how Embree is called: direct (numba, native spheres, threads) or embreex; "
                            "auto = direct where its binding loads")

    @pydantic.model_validator(mode="after")
    def _a_path_for_every_realization(self):
        """Every realization traces paths / realizations of them, rounded up: with fewer paths
        than realizations, the run would trace more paths than asked, one scene for each."""
        if self.paths < self.realizations:
            raise ValueError(f"run.paths = {self.paths:,}: fewer than run.realizations = {self.realizations:,}; "
                             "accepted: at least one path a realization (run.paths >= run.realizations)")
        return self


class Config(Section):
    name: str | None = Field(None, max_length=200, pattern=r"^[^\x00-\x1f\x7f]*$",
                             description="a label stored in the table (printable characters); not a file name")
    scene: Scene
    material: AnyMaterial
    base: AnyMaterial | None = None
    illumination: Illumination
    sensor: SensorSection = SensorSection()
    run: Run

    @pydantic.model_validator(mode="before")
    @classmethod
    def _full_brdf_incidences(cls, data):
        """illumination.incidences made into theta_i_deg and phi_i_deg (microsim.config.full_brdf)."""
        return full_brdf.expand(data, SensorSection.model_fields["cells"].default)

    @pydantic.model_validator(mode="after")
    def _points_see_light(self):
        """Next-event estimation sees the lobes that are not a Dirac delta: a scene whose every
        material reflects by delta lobes or absorbs has nothing to show it."""
        materials = [self.material] + ([self.base] if self.base is not None else [])
        if self.sensor.n_points and not any(m.continuous for m in materials):
            kinds = ", ".join(f"{name}.kind = {m.kind!r}" for name, m in zip(("material", "base"), materials))
            key = "sensor.directions_deg" if self.sensor.directions_deg else "sensor.retro_points_deg"
            raise ValueError(f"{key}: next-event estimation sees no light in this scene ({kinds}: delta lobes "
                             "or absorption only); accepted: a scene with a lambert or interfaced_lambert "
                             "material, or no points (the cells see delta lobes)")
        return self
