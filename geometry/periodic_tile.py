"""One period of a triangulated surface, repeated in x and y: its checks, its summary, its scene.

What the ``mesh`` and ``heightfield`` scenes share (docs/conventions.md §5.6-7). A :class:`Tile`
is the triangles of one period, the tile at [0, L_x) x [0, L_y) of their coordinates (square
unless the sides differ); parts of it may lie beyond a side (closed bodies that cross it, as a
Boolean-sphere realization's spheres do), at most one period beyond, and are wrapped in by the
period. :func:`checked` takes the tile as the mesh's bounds where no period is given (moved to
start at 0), and as [0, L_x) x [0, L_y) where the mesh lies when one is; it refuses, in one line
naming the scene's key, a tile through which a ray could leak or that is not a surface: vertices
not finite, faces of zero area, inverted orientation (normals pointing down on average; or,
where the faces cover the tile no net area, closed parts enclosing a negative volume), vertices
more than one period beyond the tile (period given), a period below MIN_PERIOD, open edges on a
seam (the mesh's bounding sides, and planes a period apart that both hold open edges) that have
no twin a period away (seams that do not match), and, unless a base closes it, a surface that
does not cover the tile (its faces' signed projected area is not the tile's: a hole reaching the
bottom) or that has open edges on no seam (holes, as a slit in a wall, which have no projected
area).

:func:`build` lays the triangles, each its own flat facet (hits projected onto its plane,
shaded by its normal, or with ``shading = "smooth"`` by its corners' normals interpolated:
:func:`corner_normals`), where they lie and moved by the period either way in x and y, each copy
that reaches within ``BASE_MARGIN`` of the tile: parts beyond a side are so wrapped in, and a ray
meeting a seam in float32 meets a triangle on one side or the other; paths
start ``TOP_HEIGHT`` of the longer side above the highest point and leave when they rise above it
again; a base lies ``BASE_GAP`` of it under the lowest point. :func:`summary` gives the
facets' mean cosine (area-weighted: the tile's area over the surface's, for a surface over the
tile) and RMS slope (projected-area-weighted over the facets that face up, as microfacet slope
distributions are).
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np

from microsim.core import files
from microsim.tracer.scene import BASE_MARGIN, Scene, SceneBuilder
from microsim.tracer.shapes import N_PARAMS, SMOOTH_PARAMS, Shapes, set_plane_row

#: paths start and leave this fraction of the longer side above the highest point
TOP_HEIGHT = 1e-2
#: a base lies this fraction of the longer side under the lowest point
BASE_GAP = 1e-3
#: relative tolerance of the tile's bounds, seams and projected area (of the longer side, the tile's area)
TOLERANCE = 1e-6
#: shortest period traced: the tracer's offsets and Embree's float32 rays lose a tile much
#: shorter (a white heightfield of period 3e-13 returned 8 % of its paths, tests/test_periodic_tile_physics.py)
MIN_PERIOD = 1e-6
#: bytes a triangle of the built scene takes (Embree's BVH, the vertices and the facet's shape),
#: flat; a smooth one's shape row is SMOOTH_PARAMS - N_PARAMS floats wider
TRIANGLE_BYTES = 200
SMOOTH_SHADING = "smooth"
#: the ``shading`` key of every periodic tile's scene
SHADING_DESCRIPTION = ("flat: every triangle shaded by its own normal; smooth: by its vertex normals interpolated "
                       "(vertex normals: the faces' area-weighted normals, averaged across the seams)")


@dataclass
class Tile:
    """One period of a surface, checked: vertices (V, 3) float64 with the tile at
    [0, period) x [0, period_y) (``period_y`` None: square), faces (F, 3), and its facets' unit
    normals and areas."""

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    areas: np.ndarray
    period: float
    period_y: float | None = None
    reaching: np.ndarray | None = None  # which faces each copy of :func:`build` lays, once found

    def __post_init__(self):
        if self.period_y is None:
            self.period_y = self.period

    @property
    def sides(self) -> tuple[float, float]:
        """(L_x, L_y)."""
        return self.period, self.period_y

    @classmethod
    def of(cls, vertices, faces, period: float, period_y: float | None = None) -> "Tile":
        """The tile of triangles known to be one period of a surface (no checks: :func:`checked`)."""
        vertices, faces = np.ascontiguousarray(vertices, np.float64), np.ascontiguousarray(faces, np.int32)
        normals, doubled = _facets(vertices, faces)
        return cls(vertices, faces, normals, 0.5 * doubled, period, period_y)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _facets(vertices, faces):
    """(unit normals (F, 3), doubled areas (F,)) of the faces: the cross product (b - a) x (c - a)
    of each face's corners a, b, c and its length, bit for bit as ``np.cross`` and
    ``np.linalg.norm(axis=1)`` give them (a degenerate face: NaN normal, length 0)."""
    normals = np.empty((len(faces), 3))
    doubled = np.empty(len(faces))
    for f in range(len(faces)):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        ax, ay, az = vertices[a, 0], vertices[a, 1], vertices[a, 2]
        e1x, e1y, e1z = vertices[b, 0] - ax, vertices[b, 1] - ay, vertices[b, 2] - az
        e2x, e2y, e2z = vertices[c, 0] - ax, vertices[c, 1] - ay, vertices[c, 2] - az
        cx, cy, cz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
        length = math.sqrt(cx * cx + cy * cy + cz * cz)
        normals[f, 0], normals[f, 1], normals[f, 2] = cx / length, cy / length, cz / length
        doubled[f] = length
    return normals, doubled


def source(config) -> tuple[str, Path]:
    """The key that names the config's ``scene.path`` in messages, and the file; ValueError
    where there is no such file (or it is a directory)."""
    key = f"scene.path = {config.scene.path!r}"
    file = Path(config.scene.path)
    if why := files.not_a_file(file):
        where = "" if file.is_absolute() else f" (relative to the directory microsim runs in, {Path.cwd()})"
        raise ValueError(f"{key}: {why}{where}")
    return key, file


#: the last tile read (:func:`remembered`): its key and (tile, file digest)
_LAST: dict = {}
_REMEMBERING = threading.RLock()


def remembered(config, read):
    """``read(config)``, a scene's (tile, file digest), once for a file's state and the scene's
    parameters: the config's check, its resolution and every realization of a run (in each
    process) take the same tile without reading and checking the file again. One tile is kept."""
    file = Path(config.scene.path)
    state = (file.stat().st_mtime_ns, file.stat().st_size) if file.is_file() else None
    key = (config.scene.model_dump_json(), config.base is not None, state)
    with _REMEMBERING:  # realizations may be built on two threads at once
        if key not in _LAST:
            value = read(config)
            _LAST.clear()
            _LAST[key] = value
        return _LAST[key]


def require_period(key: str, period: float) -> None:
    """ValueError, one line starting with ``key``, for a period below MIN_PERIOD."""
    if period < MIN_PERIOD:
        raise ValueError(f"{key}: a period of {period:.3g}, below {MIN_PERIOD:g}; scale the surface up (lengths are "
                         "relative)")


def checked(key: str, vertices, faces, period, closed_by_base: bool) -> Tile:
    """The tile of triangles ``vertices`` (V, 3) and ``faces`` (F, 3) after the checks of the
    module doc; ValueError, one line starting with ``key``.

    ``period`` None: the tile is the mesh's bounds in x and y (their extents the periods), and the
    vertices are moved so that it starts at 0. ``period`` given, one side or (L_x, L_y): the tile
    is [0, L_x) x [0, L_y) in the vertices' own coordinates and the mesh is laid where it lies,
    each part beyond a side wrapped in by the period (:func:`build` lays copies a period either
    way), so no vertex may lie more than one period beyond the tile. The facets are
    :meth:`Tile.of`'s (the one computation of every tile's normals and areas)."""
    vertices = np.asarray(vertices, np.float64)
    faces = np.asarray(faces, np.int64)
    if len(faces) == 0:
        raise ValueError(f"{key}: holds no triangles")
    if bad := np.count_nonzero(~np.isfinite(vertices).all(axis=1)):
        raise ValueError(f"{key}: {bad} of {len(vertices)} vertices are NaN or infinite")
    low, high = vertices[:, :2].min(axis=0), vertices[:, :2].max(axis=0)
    if period is None:
        sides = tuple(float(extent) for extent in high - low)
        vertices = vertices - np.array([low[0], low[1], 0.0])
    else:
        sides = (float(period), float(period)) if np.ndim(period) == 0 else tuple(float(side) for side in period)
        for axis, name in ((0, "x"), (1, "y")):
            side = sides[axis]
            if low[axis] < -side * (1 + TOLERANCE) or high[axis] > 2 * side * (1 + TOLERANCE):
                raise ValueError(f"{key}: spans {name} = {low[axis]:.6g} to {high[axis]:.6g}, more than one period "
                                 f"beyond the tile [0, {side:.6g}) (a mesh with a period is laid where it lies; "
                                 "move it, or give no period)")
    for side in sides:
        require_period(key, side)
    area = sides[0] * sides[1]
    with np.errstate(divide="ignore", invalid="ignore"):  # degenerate faces are refused next
        tile = Tile.of(vertices, faces, *sides)
    areas, normals = tile.areas, tile.normals
    if bad := np.count_nonzero(areas <= 1e-12 * area):
        raise ValueError(f"{key}: {bad} of {len(faces)} faces are degenerate (zero area)")
    projected = float(np.sum(normals[:, 2] * areas))
    if projected < -TOLERANCE * area:
        raise ValueError(f"{key}: inverted orientation (the normals point down on average: mean cosine "
                         f"{projected / areas.sum():.3g}); flip the faces' winding")
    if projected <= TOLERANCE * area:  # closed parts only: their volume is their orientation
        volume = float(np.sum(normals[:, 2] * areas * vertices[faces][:, :, 2].mean(axis=1)))
        if volume <= 0.0:
            raise ValueError(f"{key}: inverted orientation (the faces cover no net area of the tile and enclose "
                             f"a volume of {volume:.6g}: their normals point in); flip the faces' winding")
    holes = _check_seams(key, vertices, faces, sides)
    if not closed_by_base and abs(projected - area) > TOLERANCE * area:
        raise ValueError(f"{key}: the surface covers {projected / area:.6g} of the tile (holes reaching the "
                         "bottom, or faces folded over); add a [base] to close it")
    if not closed_by_base and holes:
        raise ValueError(f"{key}: {holes} open edges lie inside the tile, on no seam (holes, as a slit in a wall: "
                         "a ray could leave through them); close them, or add a [base]")
    return tile


def _check_seams(key: str, vertices, faces, sides: tuple[float, float]) -> int:
    """Every open edge (of one face) on a seam has its twin a period away (the same edge, moved
    by the period along that axis). The seams along an axis are the mesh's two bounding sides and
    every pair of planes a period apart that both hold open edges (the sides of a tile that does
    not start at its bounds, as when bodies cross them); open edges elsewhere are holes: their
    number is returned (a hole in a vertical wall has no projected area, so the projected-area
    check does not see it). For a mesh whose bounds span one period the seams are its bounding
    sides, and the open edges on each are those on the other."""
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    open_edges = vertices[unique[counts == 1]]  # (E, 2 ends, 3)
    step = TOLERANCE * max(sides)
    on_seam = np.zeros(len(open_edges), bool)
    for axis, name in ((0, "x"), (1, "y")):
        period = sides[axis]
        coordinate = open_edges[:, :, axis]
        low, high = float(vertices[:, axis].min()), float(vertices[:, axis].max())
        planes = np.unique(np.round(coordinate[np.abs(coordinate[:, 0] - coordinate[:, 1]) <= step, 0] / step))
        shift = round(period / step)
        paired = [k * step for k in planes if np.any(np.abs(planes - (k + shift)) <= 1)]
        seams = []
        for side in [low, high, *paired, *(side + period for side in paired)]:
            if all(abs(side - other) > step for other in seams):
                seams.append(side)

        def keys_on(side: float) -> set:
            on = np.all(np.abs(coordinate - side) <= step, axis=1)
            return {_edge_key(edge, axis, step) for edge in open_edges[on]}

        for side in seams:
            on_seam |= np.all(np.abs(coordinate - side) <= step, axis=1)

        unmatched, named = 0, set()
        for side in seams:
            alone = len(keys_on(side) - keys_on(side - period) - keys_on(side + period))
            if alone:
                unmatched += alone
                named |= {side, side + period if side + period <= high + step else side - period}
        if unmatched:
            where = " or ".join(f"{name} = {side:.6g}" for side in sorted(named))
            raise ValueError(f"{key}: the seams do not match across the period: {unmatched} open edges on {where} "
                             "have no twin on the other side (a ray could leak between tiles)")
    return int(np.count_nonzero(~on_seam))


def _edge_key(edge, axis: int, step: float) -> tuple:
    """An open edge on a side, without its coordinate along ``axis``, rounded to ``step``."""
    ends = sorted(tuple(np.round(np.delete(end, axis) / step).astype(np.int64)) for end in edge)
    return tuple(ends)



def summary(tile: Tile) -> dict:
    """The tile's scene parameters for the table (module doc): periods (``period`` and ``tile``
    the x side, ``period_y``), area, mean cosine, RMS slope, the heights paths start at and a base
    lies at (offsets in units of the longer side)."""
    z = tile.vertices[:, 2]
    normals, areas = _facing_up(tile)
    weight = areas * normals[:, 2]
    slope2 = (1.0 - normals[:, 2] ** 2) / normals[:, 2] ** 2
    longer = max(tile.sides)
    return {"period": tile.period, "period_y": tile.period_y, "tile": tile.period,
            "surface_triangles": len(tile.faces), "area": float(tile.areas.sum()),
            "mean_cosine": float(np.sum(tile.normals[:, 2] * tile.areas) / tile.areas.sum()),
            "rms_slope": float(np.sqrt(np.sum(weight * slope2) / weight.sum())),
            "z_top": float(z.max() + TOP_HEIGHT * longer), "z_bottom": float(z.min() - longer),
            "base_z": float(z.min() - BASE_GAP * longer), "max_mesh_error": 0.0}


#: a surface of more than this many times its tile's area traces slowly, and is said so
STEEP_AREA = 5.0


def steepness_note(resolved: dict) -> str | None:
    """Why a resolved tile (:func:`summary`'s keys) will trace slowly, before it does: a surface of
    more than STEEP_AREA times its tile's area is a maze of steep walls, between which paths
    scatter many times before they leave, each crossing many of the grid's cells (how much
    slower: docs/developer/performance.md, 'Gaussian heightfields: triangles or a grid walk');
    None for a gentler one."""
    mean_cosine = resolved.get("mean_cosine")
    if mean_cosine is None or mean_cosine <= 0.0 or 1.0 / mean_cosine < STEEP_AREA:
        return None
    return (f"scene: a steep surface, {1.0 / mean_cosine:.3g} times the tile's area (mean cosine {mean_cosine:.2g}, "
            f"RMS slope {resolved.get('rms_slope', float('nan')):.3g}): paths scatter many times between its walls, "
            "each ray crossing many cells, so it traces far fewer paths a second than a gentle surface")


def roughness(tile: Tile) -> tuple[float, float]:
    """The facets' Beckmann alpha along x and y: sqrt(2 <slope^2>), the mean over the projected
    area of the facets that face up (as :func:`summary`'s rms_slope)."""
    normals, areas = _facing_up(tile)
    weight = areas * normals[:, 2]
    slopes = -normals[:, :2] / normals[:, 2:3]
    return tuple(float(np.sqrt(2.0 * np.sum(weight * slopes[:, k] ** 2) / weight.sum())) for k in (0, 1))


def _facing_up(tile: Tile) -> tuple[np.ndarray, np.ndarray]:
    """(normals, areas) of the facets that face up: the tile's own arrays where all of them do
    (a heightfield's), not copied."""
    up = tile.normals[:, 2] > 0.0
    return (tile.normals, tile.areas) if up.all() else (tile.normals[up], tile.areas[up])


def for_backend(config, backend: str):
    """(config, note): triangles, which every backend traces as they are."""
    return config, ""


def triangle_bytes(resolved: dict) -> int:
    """Bytes a triangle of the built scene takes, by its shading."""
    wider = SMOOTH_PARAMS - N_PARAMS if resolved.get("shading") == SMOOTH_SHADING else 0
    return TRIANGLE_BYTES + 8 * wider


def scene_bytes(resolved: dict) -> int:
    """The triangles and their copies beyond the sides (at most all of them, 9 times)."""
    return 9 * resolved["surface_triangles"] * triangle_bytes(resolved) + 4096


def corner_normals(tile: Tile) -> np.ndarray:
    """(F, 3, 3): the unit normal at each corner of each face, for smooth shading: the sum of the
    area vectors of every face at the corner's vertex, vertices that coincide (to TOLERANCE of
    the longer side) once folded into the tile counted as one, so that a seam's two sides share
    their normals. A corner whose faces' area vectors cancel (the two sides of a sheet) takes its
    own face's normal."""
    welded = _welded(tile.vertices, np.array(tile.sides), TOLERANCE * max(tile.sides))
    area_vectors = tile.normals * tile.areas[:, None]
    total = np.zeros((welded.max() + 1, 3))
    magnitude = np.zeros(welded.max() + 1)
    for corner in range(3):
        np.add.at(total, welded[tile.faces[:, corner]], area_vectors)
        np.add.at(magnitude, welded[tile.faces[:, corner]], tile.areas)
    norm = np.linalg.norm(total, axis=1)
    summed = total[welded[tile.faces]]  # (F, 3, 3)
    length = norm[welded[tile.faces]][:, :, None]
    cancelled = norm[welded[tile.faces]] <= 1e-9 * magnitude[welded[tile.faces]]
    return np.where(cancelled[:, :, None], tile.normals[:, None, :], summed / np.where(length > 0.0, length, 1.0))


#: the copies :func:`build` lays, in order: shifts by (dx L_x, dy L_y), dx major
SHIFTS = tuple((dx, dy) for dx in (-1, 0, 1) for dy in (-1, 0, 1))
OWN = SHIFTS.index((0, 0))


def _reaching(tile: Tile) -> np.ndarray:
    """(F, 9) bool: which faces, moved by each of SHIFTS, reach within BASE_MARGIN of the tile
    (found once a tile: :func:`build` and :func:`first_own_face` both ask)."""
    if tile.reaching is None:
        sides = np.array(tile.sides)
        tile.reaching = _reach(tile.vertices, tile.faces, sides, BASE_MARGIN * sides)
    return tile.reaching


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _reach(vertices, faces, sides, margins):
    """:func:`_reaching`: a face moved by k periods along an axis reaches the tile where its bounds
    along that axis, moved, overlap [-margin, side + margin]."""
    near = np.empty((len(faces), 9), np.bool_)
    along = np.empty((2, 3), np.bool_)
    for f in range(len(faces)):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        for axis in range(2):
            high = max(max(vertices[a, axis], vertices[b, axis]), vertices[c, axis])
            low = min(min(vertices[a, axis], vertices[b, axis]), vertices[c, axis])
            for k in range(3):
                shift = (k - 1) * sides[axis]
                along[axis, k] = high + shift >= -margins[axis] and low + shift <= sides[axis] + margins[axis]
        for s in range(9):
            near[f, s] = along[0, s // 3] and along[1, s % 3]
    return near


def first_own_face(tile: Tile) -> int:
    """The scene's index of the tile's own face 0 as :func:`build` lays them (after the copies
    shifted by (-1, *) and (0, -1)); every face of the tile itself is laid, in order."""
    near = _reaching(tile)
    if not near[:, OWN].all():
        raise ValueError("faces of the tile lie beyond it: its own faces are not laid in order")
    return int(np.count_nonzero(near[:, :OWN]))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _lay(vertices, faces, normals, near, sides, smooth):
    """The faces of each shift of SHIFTS that reach the tile (``near``), in that order, each moved
    by its shift: (their vertices as float32 (3 n, 3), the face each is a copy of (n,), and either
    their corners in float64 (n, 3, 3) with ``smooth``, or the PLANE shape rows of flat facets
    through their centres facing ``normals``, (n, N_PARAMS))."""
    n = 0
    for f in range(len(faces)):
        for s in range(9):
            n += near[f, s]
    laid = np.empty((3 * n, 3), np.float32)
    source = np.empty(n, np.int32)
    corners = np.empty((n if smooth else 0, 3, 3))
    planes = np.zeros((0 if smooth else n, N_PARAMS))
    corner = np.empty((3, 3))
    j = 0
    for s in range(9):
        shift = ((s // 3 - 1) * sides[0], (s % 3 - 1) * sides[1], 0.0)
        for f in range(len(faces)):
            if not near[f, s]:
                continue
            for k in range(3):
                for axis in range(3):
                    corner[k, axis] = vertices[faces[f, k], axis] + shift[axis]
                    laid[3 * j + k, axis] = corner[k, axis]
            if smooth:
                corners[j] = corner
            else:
                x = (corner[0, 0] + corner[1, 0] + corner[2, 0]) / 3.0
                y = (corner[0, 1] + corner[1, 1] + corner[2, 1]) / 3.0
                z = (corner[0, 2] + corner[1, 2] + corner[2, 2]) / 3.0
                set_plane_row(planes[j], x, y, z, normals[f, 0], normals[f, 1], normals[f, 2])
            source[j] = f
            j += 1
    return laid, source, corners, planes


def _welded(vertices, sides, distance: float) -> np.ndarray:
    """(V,) the index of each vertex's class: vertices within ``distance`` of each other once
    folded into the tile (x and y periodic), chained, are one class. A k-d tree on the periodic
    box finds the pairs (rounding to a grid would split a pair that straddles a cell's edge)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    folded = np.column_stack([np.mod(vertices[:, :2], sides), vertices[:, 2] - vertices[:, 2].min()])
    folded[:, :2] = np.where(folded[:, :2] >= sides, 0.0, folded[:, :2])  # mod may round up to the side
    box = np.array([*sides, 2.0 * folded[:, 2].max() + 1.0])  # z is not periodic: a box twice its height
    pairs = cKDTree(folded, boxsize=box).query_pairs(distance, output_type="ndarray")
    n = len(vertices)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def build(tile: Tile, resolved: dict, material, base) -> Scene:
    """The tile's triangles, each its own facet, and their copies within BASE_MARGIN beyond
    the sides (module doc); flat facets, or smooth ones where ``resolved["shading"]`` says so;
    ``base`` (a material, or None) under it."""
    smooth = resolved.get("shading") == SMOOTH_SHADING
    laid, source, corners, planes = _lay(tile.vertices, tile.faces, tile.normals, _reaching(tile), np.array(tile.sides),
                                         smooth)
    n = len(source)
    size = float(np.sqrt(np.mean(tile.areas)))
    shapes = Shapes.smooth_triangles(corners, corner_normals(tile)[source], size) if smooth else \
        Shapes.planes_of_rows(planes, size)
    builder = SceneBuilder(*tile.sides)
    builder.add(laid, np.arange(3 * n, dtype=np.int32).reshape(n, 3), np.arange(n, dtype=np.int32), shapes, material)
    if base is not None:
        builder.add_base_plane(resolved["base_z"], base)
    return builder.build(resolved["z_top"], resolved["z_bottom"], {"copies": n - len(tile.faces)})
