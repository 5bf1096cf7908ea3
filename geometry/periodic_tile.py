"""One period of a triangulated surface, repeated in x and y: its checks, its summary, its scene.

What the ``mesh`` and ``heightfield`` scenes share (docs/conventions.md §5.6-7). A :class:`Tile`
is the triangles of one period with the tile at [0, period)^2. :func:`checked` refuses, in one
line naming the scene's key, a tile through which a ray could leak or that is not a surface:
vertices not finite, faces of zero area, normals pointing down on average (inverted
orientation), vertices outside one period, open edges on the tile's sides that have no twin a
period away (seams that do not match), and a surface that does not cover the tile (its faces'
signed projected area is not the tile's: a hole reaching the bottom) unless a base closes it.

:func:`build` lays the triangles, each its own flat facet (hits projected onto its plane,
shaded by its normal), and the triangles within ``BASE_MARGIN`` of a side again a period beyond
it, so that a ray meeting a seam in float32 meets a triangle on one side or the other; paths
start ``TOP_HEIGHT`` of the period above the highest point and leave when they rise above it
again; a base lies ``BASE_GAP`` of the period under the lowest point. :func:`summary` gives the
facets' mean cosine (area-weighted: the tile's area over the surface's, for a surface over the
tile) and RMS slope (projected-area-weighted over the facets that face up, as microfacet slope
distributions are).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from microsim.scene import BASE_MARGIN, Scene, SceneBuilder
from microsim.shapes import Shapes

#: paths start and leave this fraction of the period above the highest point
TOP_HEIGHT = 1e-2
#: a base lies this fraction of the period under the lowest point
BASE_GAP = 1e-3
#: relative tolerance of the tile's bounds, seams and projected area (of the period, its square)
TOLERANCE = 1e-6
#: bytes a triangle of the built scene takes (Embree's BVH, the vertices and the facet's shape)
TRIANGLE_BYTES = 200


@dataclass
class Tile:
    """One period of a surface, checked: vertices (V, 3) float64 with the tile at [0, period)^2,
    faces (F, 3), and its facets' unit normals and areas."""

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    areas: np.ndarray
    period: float


def source(config) -> tuple[str, Path]:
    """The key that names the config's ``scene.path`` in messages, and the file; ValueError
    where there is no such file."""
    key = f"scene.path = {config.scene.path!r}"
    file = Path(config.scene.path)
    if not file.is_file():
        raise ValueError(f"{key}: no such file")
    return key, file


#: the last tile read (:func:`remembered`): its key and (tile, file digest)
_LAST: dict = {}


def remembered(config, read):
    """``read(config)``, a scene's (tile, file digest), once for a file's state and the scene's
    parameters: the config's check, its resolution and every realization of a run (in each
    process) take the same tile without reading and checking the file again. One tile is kept."""
    file = Path(config.scene.path)
    state = (file.stat().st_mtime_ns, file.stat().st_size) if file.is_file() else None
    key = (config.scene.model_dump_json(), config.base is not None, state)
    if key not in _LAST:
        value = read(config)
        _LAST.clear()
        _LAST[key] = value
    return _LAST[key]


def checked(key: str, vertices, faces, period: float | None, closed_by_base: bool) -> Tile:
    """The tile of triangles ``vertices`` (V, 3) and ``faces`` (F, 3) after the checks of the
    module doc; ``period`` None: the extent in x, which must equal the extent in y. ValueError,
    one line starting with ``key``."""
    vertices = np.asarray(vertices, np.float64)
    faces = np.asarray(faces, np.int64)
    if len(faces) == 0:
        raise ValueError(f"{key}: holds no triangles")
    if bad := np.count_nonzero(~np.isfinite(vertices).all(axis=1)):
        raise ValueError(f"{key}: {bad} of {len(vertices)} vertices are NaN or infinite")
    low, high = vertices[:, :2].min(axis=0), vertices[:, :2].max(axis=0)
    extent = high - low
    if period is None:
        if abs(extent[0] - extent[1]) > TOLERANCE * extent.max():
            raise ValueError(f"{key}: spans {extent[0]:.6g} in x and {extent[1]:.6g} in y; give the period "
                             "(square tiles; rectangular ones are planned)")
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
    return Tile(vertices, faces.astype(np.int32), normals, areas, period)


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



def summary(tile: Tile) -> dict:
    """The tile's scene parameters for the table (module doc): period, area, mean cosine, RMS
    slope, the heights paths start at and a base lies at."""
    z = tile.vertices[:, 2]
    up = tile.normals[:, 2] > 0.0
    weight = tile.areas[up] * tile.normals[up, 2]
    slope2 = (1.0 - tile.normals[up, 2] ** 2) / tile.normals[up, 2] ** 2
    return {"period": tile.period, "tile": tile.period, "surface_triangles": len(tile.faces),
            "area": float(tile.areas.sum()),
            "mean_cosine": float(np.sum(tile.normals[:, 2] * tile.areas) / tile.areas.sum()),
            "rms_slope": float(np.sqrt(np.sum(weight * slope2) / weight.sum())),
            "z_top": float(z.max() + TOP_HEIGHT * tile.period), "z_bottom": float(z.min() - tile.period),
            "base_z": float(z.min() - BASE_GAP * tile.period), "max_mesh_error": 0.0}


def for_backend(config, backend: str):
    """(config, note): triangles, which every backend traces as they are."""
    return config, ""


def scene_bytes(resolved: dict) -> int:
    """The triangles and their copies beyond the sides (at most all of them, 9 times)."""
    return 9 * resolved["surface_triangles"] * TRIANGLE_BYTES + 4096


def build(tile: Tile, resolved: dict, material, base) -> Scene:
    """The tile's triangles, each its own flat facet, and their copies within BASE_MARGIN beyond
    the sides (module doc); ``base`` (a material, or None) under it."""
    period = tile.period
    corners = tile.vertices[tile.faces]
    margin = BASE_MARGIN * period
    parts = []
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            moved = corners + np.array([dx * period, dy * period, 0.0])
            near = (np.all(moved[:, :, :2].max(axis=1) >= -margin, axis=1)
                    & np.all(moved[:, :, :2].min(axis=1) <= period + margin, axis=1))
            parts.append((moved[near], tile.normals[near]))
    triangles = np.concatenate([p[0] for p in parts])
    normals = np.concatenate([p[1] for p in parts])
    n = len(triangles)
    builder = SceneBuilder(period)
    builder.add(triangles.reshape(-1, 3).astype(np.float32), np.arange(3 * n, dtype=np.int32).reshape(n, 3),
                np.arange(n, dtype=np.int32), Shapes.planes(triangles.mean(axis=1), normals,
                                                            float(np.sqrt(np.mean(tile.areas)))), material)
    if base is not None:
        builder.add_base_plane(resolved["base_z"], base)
    return builder.build(resolved["z_top"], resolved["z_bottom"], {"copies": n - len(tile.faces)})
