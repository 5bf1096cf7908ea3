"""The cells the sphere-grid intersector walks (microsim.tracer.integrators.sphere_grid), built
from a scene of exact spheres, or of exact ellipsoids traced as the native spheres of a scaled
frame (micrograins).

The slab [0, L_x) x [0, L_y) x [z_bottom, z_top], in the frame of the scene's native spheres
(x scaled by ``sphere_scale[0]``, y by ``sphere_scale[1]``), is cut into cubes of a given side
(stretched to fit a whole number along each axis), and every sphere of the scene that reaches
into the slab, the periodic images Embree would trace included, is listed in every cell it
reaches into, with the float64 centre and radius of its shape (the ellipsoid's centre mapped into
the frame, where its radius is its vertical semi-axis). A cell's side trades the spheres tested
in it (each listed in about (s + 2 r)^3 / s^3 cells) against the cells a segment crosses (its
length, about the void's mean free path l, over s): for a suspension or packing of spheres the
side that traced fastest was about 4 r at phi 0.1 (l = 12.6 r), 3 r at phi 0.3 (l = 3.7 r) and
2 r at phi 0.6 (l = 1.5 r), so :func:`void_side` is l, clipped to [2 r, 4 r] (r the largest
radius); for a layer of grains, one cell deep, GRAIN_SIDE (measurements:
docs/developer/performance.md, "Sphere scenes: a grid walk against Embree").
"""

from __future__ import annotations

import math

import numpy as np

from microsim.geometry import void_chords
from microsim.tracer.integrators.sphere_grid import SphereCells
from microsim.tracer.scene import Scene
from microsim.tracer.shapes import ELLIPSOID

#: the cells' side, in radii of the largest sphere, lies in [LEAST_SIDE, MOST_SIDE] (module doc)
LEAST_SIDE, MOST_SIDE = 2.0, 4.0
#: the cells' side over a layer of grains, in their frame (unit spheres centred on the base):
#: a grain's diameter (module doc)
GRAIN_SIDE = 2.0


def cell_side(free_path: float, radius: float) -> float:
    """The cells' side for a void of mean free path ``free_path`` among spheres of largest radius
    ``radius``: the free path, within [LEAST_SIDE, MOST_SIDE] radii (module doc)."""
    return min(max(free_path, LEAST_SIDE * radius), MOST_SIDE * radius)


def native_spheres(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """(centres (K, 3), radii (K,)) in float64 of the scene's native spheres, in their frame: a
    sphere's own, an ellipsoid's (semi-axes 1/params[3:6]) mapped by ``sphere_scale``."""
    params = scene.shapes.params[scene.sphere_shape]
    if not np.any(scene.shapes.code[scene.sphere_shape] == ELLIPSOID):
        return params[:, :3], params[:, 3]
    scale = np.array([*scene.sphere_scale, 1.0])
    return params[:, :3] * scale, 1.0 / params[:, 5]


def void_side(scene: Scene, free_path: float) -> float:
    """:func:`cell_side` for the scene's spheres in a void of mean free path ``free_path``."""
    return cell_side(free_path, float(native_spheres(scene)[1].max(initial=1.0)))


def build(scene: Scene, side: float) -> SphereCells:
    """The sphere cells of ``scene`` (exact spheres or scaled ellipsoids; its base plane, if any,
    the first two faces), cubes of ``side`` in the spheres' frame (module doc)."""
    centres, radii = native_spheres(scene)
    scale = np.array(scene.sphere_scale, np.float64)
    lo = np.array([0.0, 0.0, scene.z_bottom])
    sides = np.array([scene.tile * scale[0], scene.tile_y * scale[1], scene.z_top - scene.z_bottom])
    reach = np.all((centres + radii[:, None] >= lo) & (centres - radii[:, None] <= lo + sides), axis=1)
    kept = np.flatnonzero(reach)  # images beyond the slab are never met: rays start and end in it
    grid = void_chords.build(centres[kept], radii[kept], lo, sides, (False, False, False), side)
    has_base = scene.base_material >= 0
    if scene.n_triangles != (2 if has_base else 0):
        raise ValueError("the sphere grid traces exact spheres and a base plane only")
    # the base's triangles hold its height in float32, as Embree meets it
    base_z = float(scene.vertices[scene.faces[0, 0], 2]) if has_base else -math.inf
    return SphereCells(grid.entries, kept[grid.owners] + scene.n_triangles, grid.starts, grid.counts,
                       grid.sides / grid.counts, float(lo[2]), base_z, 0 if has_base else -1, scale)
