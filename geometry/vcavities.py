"""V-cavity surfaces (docs/conventions.md §5.4): symmetric V-grooves whose facet normals follow D(m)(m.n).

The surface is a mosaic of grooves much longer than wide, all rims at z = 0. A groove is a pair of
facets, m and its mirror image m' = (-m_x, -m_y, m_z) through the vertical plane along the
groove (the groove's axis is horizontal and perpendicular to m). ``distribution`` (beckmann |
ggx | gaussian) and ``roughness`` or ``roughness_x`` + ``roughness_y`` mean exactly what they
mean in the ``microfacet`` model (:mod:`microsim.physics.distributions`), so a table and a model
with the same keys describe the same surface.

Layout: one groove per path, drawn afresh. A ray from above crosses the rim plane z = 0 at a
uniform point, so the groove it enters is drawn in proportion to the horizontal area grooves
cover, which is their facets' projected area: the groove's facet m is drawn from D(m)(m.n)
(:func:`microsim.physics.distributions.sample_slope`), and since every D offered is even,
D(m') = D(m), the facets m and m' of all grooves together have projected-area density D(m)(m.n).
The groove is infinitely long and a V is scale-free, so the path is traced in the groove's
cross-section of half-width 1 and depth tan(theta_m) from a uniform point of its aperture; its
motion along the axis changes nothing. It leaves when it rises through the aperture
(:mod:`microsim.tracer.integrators.vcavity`). This is exact (no tile, no end effects, no periodic
images, no finite set of grooves per realization: a realization is an independent batch of
paths), which neither "one groove family per realization" nor "many families side by side"
would be: a finite family is a finite sample of D, and families side by side meet at ends.

Two intersectors give the same surface (``intersector``):

- ``analytic`` (default): the two facet lines of the cross-section, in float64, in numba; the
  hit point is on the facet exactly, so no offset and no self-intersection.
- ``embree``: one canonical groove mesh (4 triangles: half-width 1, depth 1) committed to
  Embree once, which each path sees through its own linear map (rotation to the groove's axis,
  depth scaled by 1/tan(theta_m), the axial motion dropped): the ray parameter t is the same in
  both frames. The general Embree path, and the reference the analytic one is checked against.
  The analytic intersector is the faster (``benchmarks/vcavities_billion.py``).

What the grooves do (tests/test_vcavities.py):

- Single scattering is the microfacet BRDF with the Torrance-Sparrow G, exactly, at every
  azimuth and up to grazing angles: facet m is lit from its rim down to the fraction
  G1(i, m) = min(1, 2 (n.m)(n.i) / (i.m)) of its length and seen from the same rim down to
  G1(o, m) (a direction on the other side of the groove sees it all), so the lit and seen part
  is min(G1(i), G1(o)), Meneveaux et al. 2015, Eq. 14. Its Smith counterpart is not (the tests
  show the bound fails).
- Specular facets have a caustic at the macro-surface's specular direction in order 2. Two mirror
  reflections in a groove rotate the direction about the groove's axis by 4 theta_m, which keeps
  its component along the axis; so for each groove azimuth one tilt, theta_m = half the ray's
  elevation in the cross-section, sends it exactly to the specular direction: a one-parameter
  family of grooves onto one direction. The order-2 density there grows like 1 / (angle from
  specular), integrable, so a cell's average grows as cells shrink (f2 of
  runs/vcavities_conductor.toml at 3240 cells, benchmarks/vcavities_fig7.py). An independent numpy
  brute force of the grooves shows the same, and orders 1 and 2 of the tracer match it cell by
  cell.

Every resolved value is stored in the table's ``scene/`` attrs, with ``layout`` and ``intersector``.

(measurements: docs/developer/performance.md, sections 'V-cavities: the order-2 caustic' and
'One walk, estimators and dispatch' for the intersectors' speeds)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import pydantic
from pydantic import Field

from microsim.core.schema import Section
from microsim.physics import distributions as nd
from microsim.tracer.integrators.vcavity import CANONICAL_FACES, Grooves
from microsim.tracer.materials import row_length

KIND = "vcavities"
INTEGRATOR = "vcavity"
#: a small whole run config of this kind, fixed seed (the generator protocol, geometry/__init__.py): what
#: the conformance test of every kind (tests/test_scene_kinds.py) and the CLI fuzzer start from
EXAMPLE = {"scene": {"kind": "vcavities", "distribution": "beckmann", "roughness": 0.5},
           "material": {"kind": "lambert", "albedo": 0.5},
           "illumination": {"theta_i_deg": [0.0, 60.0]}, "sensor": {"cells": 24},
           "run": {"paths": 4000, "realizations": 4, "seed": 1}}
INTERSECTORS = ("analytic", "embree")
LAYOUT = "one infinitely long groove per path, its facet m drawn from D(m)(m.n)"

class Config(Section):
    kind: Literal["vcavities"]
    distribution: Literal["beckmann", "ggx", "gaussian"] = Field(
        "beckmann", description="facet normal distribution D(m), as in the microfacet model")
    roughness: float | None = Field(None, ge=nd.ROUGHNESS_MIN, le=nd.ROUGHNESS_MAX,
                                    description="alpha (sigma in rad for gaussian), both axes")
    roughness_x: float | None = Field(None, ge=nd.ROUGHNESS_MIN, le=nd.ROUGHNESS_MAX,
                                      description="roughness along the surface x axis")
    roughness_y: float | None = Field(None, ge=nd.ROUGHNESS_MIN, le=nd.ROUGHNESS_MAX,
                                      description="roughness along the surface y axis")
    intersector: Literal["analytic", "embree"] = Field(
        "analytic", description="how a ray meets the groove: exact facet lines, or Embree on a canonical mesh")

    @pydantic.model_validator(mode="after")
    def _one_roughness(self):
        given = [key for key in ("roughness_x", "roughness_y") if getattr(self, key) is not None]
        accepted = f"[{nd.ROUGHNESS_MIN:g}, {nd.ROUGHNESS_MAX:g}]"
        if self.roughness is not None and given:
            raise ValueError(f"scene.roughness: give either roughness or roughness_x + roughness_y, not both "
                             f"(got roughness and {given[0]})")
        if self.roughness is None and len(given) == 1:
            partner = "roughness_y" if given[0] == "roughness_x" else "roughness_x"
            raise ValueError(f"scene.{partner}: missing; {given[0]} needs it (each in {accepted}), or give roughness")
        if self.roughness is None and not given:
            raise ValueError(f"scene.roughness: missing; give roughness, or roughness_x and roughness_y, "
                             f"each in {accepted}")
        if self.distribution == "gaussian" and self.roughness is None and self.roughness_x != self.roughness_y:
            raise ValueError("scene.roughness_x: distribution 'gaussian' is isotropic; give roughness "
                             "(or roughness_x = roughness_y)")
        return self

    @property
    def roughnesses(self) -> tuple[float, float]:
        if self.roughness is not None:
            return self.roughness, self.roughness
        return self.roughness_x, self.roughness_y


@dataclass
class VCavities:
    """One realization: the grooves' law (nothing random is drawn before tracing) and the intersector."""

    grooves: Grooves
    intersector: str
    info: dict = field(default_factory=dict)


def check(config) -> None:
    if config.base is not None:
        raise ValueError("base: not used by scene kind 'vcavities' (light never gets under the facets, "
                         "which are made of [material]); remove [base]")


def for_backend(config, backend: str):
    """(config, note): the Embree intersector needs the direct binding; on embreex the exact
    analytic intersector traces the same grooves."""
    if backend == "embreex" and config.scene.intersector == "embree":
        scene = config.scene.model_copy(update={"intersector": "analytic"})
        return config.model_copy(update={"scene": scene}), "the analytic intersector (the embree intersector needs the direct backend)"
    return config, ""


def resolve(config) -> dict:
    scene = config.scene
    ax, ay = scene.roughnesses
    embree = scene.intersector == "embree"
    return {
        "kind": KIND,
        "distribution": scene.distribution,
        "roughness_x": ax,
        "roughness_y": ay,
        "layout": LAYOUT,
        "intersector": scene.intersector,
        "groove_half_width": 1.0,
        "rim_z": 0.0,
        "triangles": len(CANONICAL_FACES) if embree else 0,
        "max_mesh_error": 0.0,
    }


def scene_bytes(resolved: dict) -> int:
    """A canonical groove at most: nothing to speak of."""
    return 4096


def generate(resolved: dict, config, rng: np.random.Generator) -> VCavities:
    """The grooves of a realization: their law only (each path draws its own groove)."""
    material = config.material
    row = np.zeros(row_length())
    row[: len(material.row())] = material.row()
    grooves = Grooves(nd.DISTRIBUTIONS.index(resolved["distribution"]), resolved["roughness_x"],
                      resolved["roughness_y"], material.code, row)
    return VCavities(grooves, resolved["intersector"], dict(resolved))
