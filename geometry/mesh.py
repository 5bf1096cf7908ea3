"""A user's periodic tile: a triangle mesh repeated in x and y (docs/conventions.md §5.6).

The mesh (OBJ, PLY, STL, GLB or OFF, read by trimesh) is one period of a surface: its x and y
bounds are the tile, ``period`` on each side (square tiles; ``period_x`` and ``period_y`` are
planned), lengths in the mesh's own units times ``scale``. It is checked, laid and summarized as
every periodic tile is (:mod:`geometry.periodic_tile`: refusals of meshes through which a ray
could leak, flat facets, copies beyond the sides, an optional ``[base]`` under it); every
triangle is shaded by its own normal (``shading = "flat"``; interpolated normals are planned).
The table also records the file's SHA-256.
"""

from __future__ import annotations

import hashlib
from typing import Literal

import numpy as np
from pydantic import Field

from microsim.scene import Scene
from microsim.schema import Section

from . import periodic_tile
from .periodic_tile import Tile

KIND = "mesh"
INTEGRATOR = "surface"
#: the generator protocol's, as every periodic tile has them
for_backend, scene_bytes = periodic_tile.for_backend, periodic_tile.scene_bytes


class Config(Section):
    kind: Literal["mesh"]
    path: str = Field(min_length=1, description="the mesh file: OBJ, PLY, STL, GLB or OFF (relative to the "
                                                "directory microsim runs in)")
    period: float | None = Field(None, gt=0.0, le=1e9, description="the tile's side in the mesh's units times "
                                 "scale (default: the mesh's extent in x, which must equal its extent in y)")
    scale: float = Field(1.0, gt=0.0, le=1e9, description="factor applied to the mesh's coordinates")
    shading: Literal["flat"] = Field("flat", description="flat: every triangle shaded by its own normal "
                                     "(interpolated vertex normals are planned)")


def load(config) -> tuple[Tile, str]:
    """The checked tile of the config's mesh file and the file's SHA-256, read once
    (:func:`geometry.periodic_tile.remembered`); ValueError, one line naming scene.path."""
    return periodic_tile.remembered(config, _read)


def _read(config) -> tuple[Tile, str]:
    scene = config.scene
    key, file = periodic_tile.source(config)
    try:
        import trimesh

        mesh = trimesh.load(file, force="mesh", process=False)
        data = file.read_bytes()
    except Exception as err:  # trimesh raises what its loaders raise
        raise ValueError(f"{key}: cannot be read as a mesh ({' '.join(str(err).split())[:200]})") from None
    tile = periodic_tile.checked(key, np.asarray(mesh.vertices, np.float64) * scene.scale, mesh.faces, scene.period,
                                 closed_by_base=config.base is not None)
    return tile, hashlib.sha256(data).hexdigest()


def check(config) -> None:
    load(config)


def resolve(config) -> dict:
    scene = config.scene
    tile, digest = load(config)
    return {"kind": KIND, "path": scene.path, "scale": scene.scale, "shading": scene.shading, "sha256": digest,
            **periodic_tile.summary(tile)}


def generate(resolved: dict, config, rng: np.random.Generator) -> Scene:
    """The tile (:func:`geometry.periodic_tile.build`); nothing is random."""
    return periodic_tile.build(load(config)[0], resolved, config.material, config.base)
