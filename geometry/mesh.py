"""A user's periodic tile: a triangle mesh repeated in x and y (docs/conventions.md §5.6).

The mesh (OBJ, PLY, STL, GLB or OFF, read by trimesh) is one period of a surface: its x and y
bounds are the tile, ``period`` on each side (square tiles; ``period_x`` and ``period_y`` are
planned), lengths in the mesh's own units times ``scale``. Paths start above its highest point
and leave when they rise above it again; rays wrap at the tile's sides, as in every surface
scene, and the triangles within ``BASE_MARGIN`` of a side are also laid, shifted by a period,
beyond it, so that a ray meeting a seam in float32 meets a triangle on one side or the other.
Every triangle is a flat facet: hits are projected onto its plane and shaded by its normal
(``shading = "flat"``; interpolated normals are planned).

A mesh is refused, in one line naming ``scene.path`` and what is wrong, where a ray could leak
or the tile is not a surface: vertices not finite, faces of zero area, normals pointing down on
average (inverted orientation), vertices outside one period, open edges on the tile's sides that
have no counterpart a period away (seams that do not match), and a surface that does not cover
the tile (its faces' signed projected area is not the tile's: a hole reaching the bottom) unless
a ``[base]`` closes it, a plane just under the mesh's lowest point.

The table's ``scene/`` attributes record the period, the file's SHA-256, the mesh's area and its
facets' summary: the mean cosine of the normals (area-weighted: the tile's area over the mesh's
for a surface over the tile) and the RMS slope (projected-area-weighted over the facets that
face up, as microfacet slope distributions are).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field

from microsim.scene import BASE_MARGIN, Scene, SceneBuilder
from microsim.schema import Section
from microsim.shapes import Shapes

KIND = "mesh"
INTEGRATOR = "surface"
#: paths start and leave this fraction of the period above the mesh's highest point
TOP_HEIGHT = 1e-2
#: a [base] lies this fraction of the period under the mesh's lowest point
BASE_GAP = 1e-3
#: relative tolerance of the tile's bounds, seams and projected area (of the period, its square)
TOLERANCE = 1e-6
#: bytes a triangle of the built scene takes (Embree's BVH, the vertices and the facet's shape)
TRIANGLE_BYTES = 200


class Config(Section):
    kind: Literal["mesh"]
    path: str = Field(min_length=1, description="the mesh file: OBJ, PLY, STL, GLB or OFF (relative to the "
                                                "directory microsim runs in)")
    period: float | None = Field(None, gt=0.0, le=1e9, description="the tile's side in the mesh's units times "
                                 "scale (default: the mesh's extent in x, which must equal its extent in y)")
    scale: float = Field(1.0, gt=0.0, le=1e9, description="factor applied to the mesh's coordinates")
    shading: Literal["flat"] = Field("flat", description="flat: every triangle shaded by its own normal "
                                     "(interpolated vertex normals are planned)")


@dataclass
class Tile:
    """One period of the mesh, checked: vertices (V, 3) float64 with the tile at [0, period)^2,
    faces (F, 3), and its facets' unit normals and areas."""

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    areas: np.ndarray
    period: float
    sha256: str


def load(path: str, scale: float = 1.0, period: float | None = None, closed_by_base: bool = False) -> Tile:
    """The checked tile of the mesh file ``path`` (module doc); ValueError with one line."""
    key = f"scene.path = {path!r}"
    file = Path(path)
    if not file.is_file():
        raise ValueError(f"{key}: no such file")
    try:
        import trimesh

        mesh = trimesh.load(file, force="mesh", process=False)
        data = file.read_bytes()
    except Exception as err:  # trimesh raises what its loaders raise
        raise ValueError(f"{key}: cannot be read as a mesh ({' '.join(str(err).split())[:200]})") from None
    vertices = np.asarray(mesh.vertices, np.float64) * scale
    faces = np.asarray(mesh.faces, np.int64)
    if len(faces) == 0:
        raise ValueError(f"{key}: holds no triangles")
    if bad := np.count_nonzero(~np.isfinite(vertices).all(axis=1)):
        raise ValueError(f"{key}: {bad} of {len(vertices)} vertices are NaN or infinite")
    low, high = vertices[:, :2].min(axis=0), vertices[:, :2].max(axis=0)
    extent = high - low
    if period is None:
        if abs(extent[0] - extent[1]) > TOLERANCE * extent.max():
            raise ValueError(f"scene.period: the mesh {path!r} spans {extent[0]:.6g} in x and {extent[1]:.6g} in y; "
                             "give period (square tiles; period_x and period_y are planned)")
        period = float(extent[0])
    if np.any(extent > period * (1 + TOLERANCE)):
        raise ValueError(f"{key}: spans {extent[0]:.6g} x {extent[1]:.6g}, more than one period {period:.6g}")
    vertices = vertices - np.array([low[0], low[1], 0.0])
    corners = vertices[faces]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    areas = 0.5 * np.linalg.norm(cross, axis=1)
    if bad := np.count_nonzero(areas <= 1e-12 * period**2):
        raise ValueError(f"{key}: {bad} of {len(faces)} faces are degenerate (zero area)")
    normals = cross / (2.0 * areas[:, None])
    projected = float(np.sum(normals[:, 2] * areas))
    if projected <= 0.0:
        raise ValueError(f"{key}: inverted orientation (the normals point down on average: mean cosine "
                         f"{projected / areas.sum():.3g}); flip the faces' winding")
    _check_seams(key, vertices, faces, period)
    if not closed_by_base and abs(projected - period**2) > TOLERANCE * period**2:
        raise ValueError(f"{key}: the surface covers {projected / period**2:.6g} of the tile (holes reaching the "
                         "bottom, or faces folded over); add a [base] to close it")
    return Tile(vertices, faces.astype(np.int32), normals, areas, period, hashlib.sha256(data).hexdigest())


def _check_seams(key: str, vertices, faces, period: float) -> None:
    """Every open edge (of one face) on a tile side has its twin a period away, on the opposite
    side; open edges elsewhere are holes, which the projected-area check sees."""
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    open_edges = vertices[unique[counts == 1]]  # (E, 2 ends, 3)
    step = TOLERANCE * period
    for axis, name in ((0, "x"), (1, "y")):
        coordinate = open_edges[:, :, axis]
        low = np.all(np.abs(coordinate) <= step, axis=1)
        high = np.all(np.abs(coordinate - period) <= step, axis=1)
        keys = [{_edge_key(edge, axis, step) for edge in open_edges[side]} for side in (low, high)]
        if keys[0] != keys[1]:
            unmatched = len(keys[0] ^ keys[1])
            raise ValueError(f"{key}: the seams do not match across the period: {unmatched} open edges on "
                             f"{name} = 0 or {name} = {period:.6g} have no twin on the other side (a ray could "
                             "leak between tiles)")


def _edge_key(edge, axis: int, step: float) -> tuple:
    """An open edge on a side, without its coordinate along ``axis``, rounded to ``step``."""
    ends = sorted(tuple(np.round(np.delete(end, axis) / step).astype(np.int64)) for end in edge)
    return tuple(ends)


def check(config) -> None:
    scene = config.scene
    load(scene.path, scene.scale, scene.period, closed_by_base=config.base is not None)


def for_backend(config, backend: str):
    """(config, note): triangles, which every backend traces as they are."""
    return config, ""


def resolve(config) -> dict:
    scene = config.scene
    tile = load(scene.path, scene.scale, scene.period, closed_by_base=config.base is not None)
    z = tile.vertices[:, 2]
    up = tile.normals[:, 2] > 0.0
    weight = tile.areas[up] * tile.normals[up, 2]
    slope2 = (1.0 - tile.normals[up, 2] ** 2) / tile.normals[up, 2] ** 2
    return {"kind": KIND, "path": scene.path, "period": tile.period, "tile": tile.period, "scale": scene.scale,
            "shading": scene.shading, "sha256": tile.sha256, "mesh_triangles": len(tile.faces),
            "area": float(tile.areas.sum()), "mean_cosine": float(np.sum(tile.normals[:, 2] * tile.areas) /
                                                                  tile.areas.sum()),
            "rms_slope": float(np.sqrt(np.sum(weight * slope2) / weight.sum())),
            "z_top": float(z.max() + TOP_HEIGHT * tile.period), "z_bottom": float(z.min() - tile.period),
            "base_z": float(z.min() - BASE_GAP * tile.period), "max_mesh_error": 0.0}


def scene_bytes(resolved: dict) -> int:
    """The triangles and their copies beyond the sides (at most all of them, 9 times)."""
    return 9 * resolved["mesh_triangles"] * TRIANGLE_BYTES + 4096


def generate(resolved: dict, config, rng: np.random.Generator) -> Scene:
    """The tile's triangles, each its own flat facet, and their copies within BASE_MARGIN beyond
    the sides (module doc); the [base] under it, if any. Nothing is random."""
    scene = config.scene
    tile = load(scene.path, scene.scale, scene.period, closed_by_base=config.base is not None)
    period = tile.period
    corners = tile.vertices[tile.faces]
    margin = BASE_MARGIN * period
    parts = []
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            shift = np.array([dx * period, dy * period, 0.0])
            moved = corners + shift
            near = (np.all(moved[:, :, :2].max(axis=1) >= -margin, axis=1)
                    & np.all(moved[:, :, :2].min(axis=1) <= period + margin, axis=1))
            parts.append((moved[near], tile.normals[near]))
    triangles = np.concatenate([p[0] for p in parts])
    normals = np.concatenate([p[1] for p in parts])
    n = len(triangles)
    size = float(np.sqrt(np.mean(tile.areas)))
    builder = SceneBuilder(period)
    builder.add(triangles.reshape(-1, 3).astype(np.float32), np.arange(3 * n, dtype=np.int32).reshape(n, 3),
                np.arange(n, dtype=np.int32), Shapes.planes(triangles.mean(axis=1), normals, size), config.material)
    if config.base is not None:
        builder.add_base_plane(resolved["base_z"], config.base)
    return builder.build(resolved["z_top"], resolved["z_bottom"], {"copies": n - len(tile.faces)})
