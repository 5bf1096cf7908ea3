"""The flat plane z = 0 made of ``[material]``: the exactness reference (CONVENTIONS 5.1)."""

from typing import Literal

import numpy as np
from pydantic import Field

from microsim.scene import MaterialTable, Scene
from microsim.schema import Section
from microsim.shapes import Shapes

KIND = "plane"


class Config(Section):
    kind: Literal["plane"]
    tile: float = Field(1.0, gt=0.0, le=1e4, description="period of the tile (any length: the plane is flat)")


def check(config) -> None:
    if config.base is not None:
        raise ValueError("base: not used by scene kind 'plane' (the plane is made of [material]); remove [base]")


def resolve(config) -> dict:
    tile = config.scene.tile
    return {"kind": KIND, "tile": tile, "z_top": 1e-2 * tile, "z_bottom": -tile}


def generate(resolved: dict, config, rng: np.random.Generator) -> Scene:
    """Two triangles covering the tile (with a margin), facing +z."""
    vertices, faces = base_quad(resolved["tile"], 0.0)
    shapes = Shapes.planes(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), material=0, size=resolved["tile"])
    materials = MaterialTable.from_specs([config.material.model_dump()])
    info = dict(resolved, triangles=2, max_mesh_error=0.0)
    return Scene(vertices, faces, np.zeros(2, np.int32), shapes, materials,
                 resolved["tile"], resolved["z_top"], resolved["z_bottom"], info)


def base_quad(tile: float, z: float):
    """Vertices and two counter-clockwise faces (normal +z) covering [0, tile]^2 with a 1% margin."""
    lo, hi = -0.01 * tile, 1.01 * tile
    vertices = np.array([[lo, lo, z], [hi, lo, z], [hi, hi, z], [lo, hi, z]], dtype=np.float32)
    faces = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)
    return vertices, faces
