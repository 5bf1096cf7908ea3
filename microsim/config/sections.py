"""The sections of a run's config (docs/conventions.md §4), each a strict pydantic model.

Unknown keys, wrong types and out-of-range values are rejected. Scene kinds come from the
generator registry (``geometry.SCENES``) and material kinds from the material registry
(``microsim.tracer.materials.MATERIALS``), each with its own model, selected by ``kind``.
"""

from __future__ import annotations

from typing import Annotated, Literal, Union

import pydantic
from pydantic import Field

from microsim import geometry
from microsim.config import full_brdf
from microsim.config.full_brdf import MAX_INCIDENCES
from microsim.core.choices import BACKEND_CHOICES
from microsim.core.schema import Section
from microsim.tracer import estimators
from microsim.tracer.materials import MATERIALS

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


class SensorKeys(Section):
    """The sensor's own key of ``[sensor]``: its cells."""

    cells: int = Field(3240, ge=1, le=1_000_000, description="cells of the equal-solid-angle sensor, approximately "
                       "(the table stores the actual cells)")


#: ``[sensor]``: the sensor's cells, then the keys each estimator declares (``Estimator.KEYS``), in
#: the estimators' order (pydantic lays out the fields of the last base first)
SensorSection = pydantic.create_model("SensorSection", __base__=tuple(reversed((SensorKeys, *estimators.keys()))),
                                      __module__=__name__)


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
    def _estimators_agree(self):
        """What each estimator checks of the whole config (``Estimator.check``)."""
        for cls in estimators.classes():
            cls.check(self)
        return self
