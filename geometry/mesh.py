"""A user's periodic tile: a triangle mesh repeated in x and y (docs/conventions.md §5.6).

The mesh (OBJ, PLY, STL, GLB or OFF, read by trimesh) is one period of a surface, lengths in the
mesh's own units times ``scale``. Without a period its x and y bounds are the tile (their extents
are the periods L_x and L_y). With ``period`` (a square tile), or ``period_x`` and ``period_y``,
the tile is [0, L_x) x [0, L_y) in the mesh's coordinates (times ``scale``) and the mesh is laid
where it lies: parts beyond a side, at most one period beyond, are wrapped
in by the period, so closed bodies may cross the sides (a Boolean-sphere realization written by
:func:`microsim.geometry.poisson_spheres.export_tile`); seams are matched a period apart wherever the
mesh's bounds put them. It is checked, laid and summarized as
every periodic tile is (:mod:`microsim.geometry.periodic_tile`: refusals of meshes through which a ray
could leak, facets, copies beyond the sides, an optional ``[base]`` under it); every
triangle is shaded by its own normal (``shading = "flat"``) or by its vertex normals
interpolated (``"smooth"``: :func:`microsim.geometry.periodic_tile.corner_normals`; the file's own normals
are not read).
The table also records the file's SHA-256; with ``statistics = true``, every realization's
measured NDF, visible NDF and G1 (:mod:`microsim.geometry.surface_statistics`).
"""

from __future__ import annotations

import hashlib
from typing import Literal

import numpy as np
import pydantic
from pydantic import Field

from microsim.core.schema import Section
from microsim.geometry import periodic_tile, surface_statistics
from microsim.geometry.periodic_tile import Tile
from microsim.tracer.scene import Scene

KIND = "mesh"
INTEGRATOR = "surface"
#: a small whole run config of this kind, fixed seed (the generator protocol, geometry/__init__.py): what
#: the conformance test of every kind (tests/test_scene_kinds.py) and the CLI fuzzer start from
#: (its file: relative to the repository's root, a config of runs/; microsim.testing.scenes.example resolves it)
EXAMPLE = {"scene": {"kind": "mesh", "path": "runs/meshes/weave.ply"},
           "material": {"kind": "lambert", "albedo": 0.7},
           "illumination": {"theta_i_deg": [0.0, 60.0]}, "sensor": {"cells": 24},
           "run": {"paths": 4000, "realizations": 4, "seed": 1}}
#: what sets the scene's size, for the memory refusal (microsim.run.memory.check_memory)
SIZE = "take fewer triangles in scene.path"
#: the generator protocol's, as every periodic tile has them
for_backend, scene_bytes = periodic_tile.for_backend, periodic_tile.scene_bytes


class Config(Section):
    kind: Literal["mesh"]
    path: str = Field(min_length=1, description="the mesh file: OBJ, PLY, STL, GLB or OFF (relative to the "
                                                "directory microsim runs in)")
    period: float | None = Field(None, gt=0.0, le=1e9, description="the square tile's side in the mesh's units "
                                 "times scale; given, the tile is [0, period)^2 where the mesh lies, parts beyond a "
                                 "side wrapped in (default: the mesh's bounds)")
    period_x: float | None = Field(None, gt=0.0, le=1e9, description="a rectangular tile's side along x (with "
                                   "period_y; instead of period)")
    period_y: float | None = Field(None, gt=0.0, le=1e9, description="a rectangular tile's side along y (with "
                                   "period_x)")
    scale: float = Field(1.0, gt=0.0, le=1e9, description="factor applied to the mesh's coordinates")
    shading: Literal["flat", "smooth"] = Field("flat", description=periodic_tile.SHADING_DESCRIPTION)
    statistics: bool = surface_statistics.statistics_key()
    statistics_rays: int | None = surface_statistics.rays_key()

    @pydantic.model_validator(mode="after")
    def _one_period(self):
        surface_statistics.check_keys(self)
        sides = [key for key in ("period_x", "period_y") if getattr(self, key) is not None]
        if self.period is not None and sides:
            raise ValueError(f"scene.period: give either period (a square tile) or period_x and period_y, not both "
                             f"(got period and {sides[0]})")
        if len(sides) == 1:
            partner = "period_y" if sides[0] == "period_x" else "period_x"
            raise ValueError(f"scene.{partner}: missing; {sides[0]} needs it (each in (0, 1e9]), or give period")
        return self

    @property
    def tile_sides(self):
        """The period as periodic_tile.checked takes it: None, a side, or (L_x, L_y)."""
        return (self.period_x, self.period_y) if self.period_x is not None else self.period


def load(config) -> tuple[Tile, str]:
    """The checked tile of the config's mesh file and the file's SHA-256, read once
    (:func:`microsim.geometry.periodic_tile.remembered`); ValueError, one line naming scene.path."""
    return periodic_tile.remembered(config, _read)


def _read(config) -> tuple[Tile, str]:
    scene = config.scene
    key, file = periodic_tile.source(config)
    try:
        import trimesh

        mesh = trimesh.load(file, force="mesh", process=False)
        data = file.read_bytes()
    except Exception as err:  # trimesh raises what its loaders raise
        raise ValueError(f"{key}: trimesh cannot read it as a {file.suffix.lstrip('.').upper() or 'mesh'} file "
                         f"(damaged, or not of that format: its reader raised {_reader_error(err)})") from None
    vertices, faces = shared_vertices(np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64))
    tile = periodic_tile.checked(key, vertices * scene.scale, faces, scene.tile_sides,
                                 closed_by_base=config.base is not None)
    return tile, hashlib.sha256(data).hexdigest()


def _reader_error(err: Exception) -> str:
    """A reader's exception in a few words: its type and message (a KeyError's message is only the
    missing key, as 'y' for a PLY vertex without a y property)."""
    message = " ".join(str(err).split())[:200]
    if isinstance(err, KeyError):
        return f"KeyError: no {message} in the file's declarations"
    return f"{type(err).__name__}: {message}" if message else type(err).__name__


def shared_vertices(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mesh with each position held once: vertices at exactly the same coordinates made one
    (the first of them, in their order), the faces re-indexed. Formats that store each triangle's
    corners apart (STL) then give the connectivity the checks of open edges need; a mesh whose
    vertices are already distinct is returned as it is."""
    unique, first, inverse = np.unique(vertices, axis=0, return_index=True, return_inverse=True)
    if len(unique) == len(vertices):
        return vertices, faces
    order = np.argsort(first)  # the kept vertices in the order of their first appearance
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return vertices[np.sort(first)], rank[inverse.reshape(-1)][faces]


def check(config) -> None:
    load(config)


def resolve(config) -> dict:
    scene = config.scene
    tile, digest = load(config)
    return {"kind": KIND, "path": scene.path, "scale": scene.scale, "shading": scene.shading, "sha256": digest,
            **periodic_tile.summary(tile), **surface_statistics.resolve(config, isotropic=False)}


def generate(resolved: dict, config, rng: np.random.Generator) -> Scene:
    """The tile (:func:`microsim.geometry.periodic_tile.build`); nothing is random but, with
    ``statistics``, the points the masking's shadow rays start from."""
    tile = load(config)[0]
    return surface_statistics.add(periodic_tile.build(tile, resolved, config.material, config.base), tile, resolved,
                                  config, rng)
