"""The cells the sphere-grid intersector walks (microsim.tracer.integrators.sphere_grid), built
from a scene of exact spheres.

The slab [0, L_x) x [0, L_y) x [z_bottom, z_top] is cut into cubes of side :func:`cell_side`
(stretched to fit a whole number along each axis), and every sphere of the scene, the periodic
images Embree would trace included, is listed in every cell it reaches into, with the float64
centre and radius of its shape. A cell's side trades the spheres tested in it (each listed in
about (s + 2 r)^3 / s^3 cells) against the cells a segment crosses (its length, about the void's
mean free path l, over s): the side that traced fastest was about 4 r at phi 0.1 (l = 12.6 r),
3 r at phi 0.3 (l = 3.7 r) and 2 r at phi 0.6 (l = 1.5 r), so the side is l, clipped to
[2 r, 4 r] (r the largest radius; measurements: docs/developer/performance.md, "Sphere scenes: a
grid walk against Embree").
"""

from __future__ import annotations

import math

import numpy as np

from microsim.geometry import void_chords
from microsim.tracer.integrators.sphere_grid import SphereCells
from microsim.tracer.scene import Scene

#: the cells' side, in radii of the largest sphere, lies in [LEAST_SIDE, MOST_SIDE] (module doc)
LEAST_SIDE, MOST_SIDE = 2.0, 4.0


def cell_side(free_path: float, radius: float) -> float:
    """The cells' side for a void of mean free path ``free_path`` among spheres of largest radius
    ``radius``: the free path, within [LEAST_SIDE, MOST_SIDE] radii (module doc)."""
    return min(max(free_path, LEAST_SIDE * radius), MOST_SIDE * radius)


def build(scene: Scene, free_path: float) -> SphereCells:
    """The sphere cells of ``scene`` (exact spheres; its base plane, if any, the first two faces at
    the height ``scene.info["base_z"]``), for a void of mean free path ``free_path``."""
    params = scene.shapes.params[scene.sphere_shape]
    centres, radii = params[:, :3], params[:, 3]
    radius = float(radii.max(initial=1.0))
    lo = np.array([0.0, 0.0, scene.z_bottom])
    sides = np.array([scene.tile, scene.tile_y, scene.z_top - scene.z_bottom])
    grid = void_chords.build(centres, radii, lo, sides, (False, False, False), cell_side(free_path, radius))
    has_base = scene.base_material >= 0
    if scene.n_triangles != (2 if has_base else 0):
        raise ValueError("the sphere grid traces exact spheres and a base plane only")
    # the base's triangles hold its height in float32, as Embree meets it
    base_z = float(np.float32(scene.info["base_z"])) if has_base else -math.inf
    return SphereCells(grid.entries, grid.owners + scene.n_triangles, grid.starts, grid.counts,
                       grid.sides / grid.counts, float(lo[2]), base_z, 0 if has_base else -1)
