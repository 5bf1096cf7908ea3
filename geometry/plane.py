"""The flat plane z = 0 made of ``[material]``: the exactness reference (docs/conventions.md §5.1)."""

from typing import Literal

import numpy as np
from pydantic import Field

from microsim.core.schema import Section
from microsim.tracer.scene import Scene, SceneBuilder

KIND = "plane"
INTEGRATOR = "surface"
#: a small whole run config of this kind, fixed seed (the generator protocol, geometry/__init__.py): what
#: the conformance test of every kind (tests/test_scene_kinds.py) and the CLI fuzzer start from
EXAMPLE = {"scene": {"kind": "plane"}, "material": {"kind": "lambert", "albedo": 0.5},
           "illumination": {"theta_i_deg": [0.0, 60.0]}, "sensor": {"cells": 24},
           "run": {"paths": 4000, "realizations": 4, "seed": 1}}
#: paths start and leave this fraction of the tile above the plane
TOP_HEIGHT = 1e-2


class Config(Section):
    kind: Literal["plane"]
    tile: float = Field(1.0, gt=0.0, le=1e4, description="period of the tile (any length: the plane is flat)")


def check(config) -> None:
    if config.base is not None:
        raise ValueError("base: not used by scene kind 'plane' (the plane is made of [material]); remove [base]")


def for_backend(config, backend: str):
    """(config, note): the plane's two triangles are traced by every backend as they are."""
    return config, ""


def resolve(config) -> dict:
    tile = config.scene.tile
    return {"kind": KIND, "tile": tile, "z_top": TOP_HEIGHT * tile, "z_bottom": -tile, "max_mesh_error": 0.0}


def scene_bytes(resolved: dict) -> int:
    """Two triangles: nothing to speak of."""
    return 4096


def generate(resolved: dict, config, rng: np.random.Generator) -> Scene:
    """The base plane alone, facing +z."""
    builder = SceneBuilder(resolved["tile"])
    builder.add_base_plane(0.0, config.material)
    return builder.build(resolved["z_top"], resolved["z_bottom"], resolved)
