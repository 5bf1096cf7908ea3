"""What a periodic surface realization is, measured: its NDF and its masking (docs/conventions.md §6).

For a tile of flat facets (a mesh or heightfield scene, :class:`microsim.geometry.periodic_tile.Tile`) and
the sensor's cells (here cells of facet normals m, not of exit directions):

- ``ndf``: the cell average of the microfacet distribution D, the facets' area whose normal lies
  in the cell over the tile's area and the cell's solid angle, so that sum(ndf cos(theta) dOmega)
  = 1 for a surface over the tile (Heitz 2014, Eq. 4). Facets facing down are not counted.
- ``vndf`` at each masking direction wo: the cell average of the distribution of visible normals
  D_wo(m) = G1(wo, m) <wo.m> D(m) / cos(theta_o) (Heitz 2014, Eq. 2): points drawn on the facets
  in proportion to their area projected towards wo, each kept if a shadow ray towards wo leaves
  the surface, binned by their facet's normal. Its ratio to <wo.m> D(m) / cos(theta_o) is the
  masking G1(wo, m) of facets of normal m, which Smith's model says does not depend on m and the
  V-cavity model says does.
- ``g1``: the visible share of the projected area facing wo (for a heightfield, the sum of vndf
  times the cells' solid angle, times cos(theta_o) / facing_area). On any surface over the tile
  every line from wo meets the surface once, so this is exactly cos(theta_o) over the facing
  projected area per tile area: a check of the shadow rays with nothing to fit, which Smith's and
  the V-cavity G1 both satisfy (Heitz 2014, §4); the models differ in vndf.
- ``facing_area``: that projected area, the sum of area <wo.m> over the facets per tile area, the
  integral of <wo.m> D(m) (cos(theta_o) (1 + Lambda(wo)) in Smith's model).
- ``g1_rays``, ``g1_free``: the shadow rays started on facets of normals in each cell, and those
  that left: summed over realizations, their ratio is G1(wo, m) with no model in it.

A shadow ray starts off its facet as the tracer's scattered rays do (the clearance of
microsim.tracer.integrators.surface_transport: OFFSET_SIZE of the facets' size, OFFSET_SPACINGS float32
spacings of the coordinates). Shadow rays cross the periodic tile in segments, each to the nearer
of the top z_top and the tile side, and go on from the opposite side (the tracer's wrapping),
tested with Embree's occlusion query on the scene's triangles (with their copies beyond the
sides).
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from microsim.core.frames import direction
from microsim.tracer.sensor import Sensor

#: shadow rays a masking direction, by default
RAYS = 4096
#: masking directions (theta_o, phi_o) in degrees by default: phi_o 0 (and 90 for an anisotropic surface)
THETAS_DEG = (0.0, 30.0, 60.0, 75.0, 85.0)
#: tile crossings after which a shadow ray that has neither left nor been blocked is an error
MAX_CROSSINGS = 10_000


def default_directions(anisotropic: bool) -> list[list[float]]:
    """[theta_o, phi_o] in degrees: THETAS_DEG at phi_o 0, and at 90 for an anisotropic surface."""
    return [[theta, phi] for phi in ((0.0, 90.0) if anisotropic else (0.0,)) for theta in THETAS_DEG]


def statistics_key():
    """The ``[scene]`` key ``statistics`` of the scenes that take it (pydantic Field)."""
    return Field(False, description="store every realization's measured NDF, visible NDF and G1 "
                                    "(microsim.geometry.surface_statistics)")


def rays_key():
    """The ``[scene]`` key ``statistics_rays`` (pydantic Field)."""
    return Field(None, ge=16, le=10_000_000, description="with statistics: shadow rays a masking direction and "
                                                         f"realization (default {RAYS})")


def check_keys(scene) -> None:
    """ValueError, one line, for ``statistics_rays`` given without ``statistics = true``."""
    if scene.statistics_rays is not None and not scene.statistics:
        raise ValueError(f"scene.statistics_rays = {scene.statistics_rays}: only with statistics = true")


def resolve(config, isotropic: bool) -> dict:
    """The table's record of what a run of ``config`` measures: {"statistics": False}, or the
    masking directions and rays (default_directions: phi_o 90 too unless ``isotropic``)."""
    scene = config.scene
    if not scene.statistics:
        return {"statistics": False}
    return {"statistics": True, "statistics_rays": RAYS if scene.statistics_rays is None else scene.statistics_rays,
            "statistics_directions_deg": default_directions(not isotropic)}


def add(scene, tile, resolved: dict, config, rng: np.random.Generator):
    """``scene`` with, if ``resolved`` asks for statistics, the realization's :func:`measure` in
    its info (stored per realization in the table's scene/ group); shadow rays drawn from ``rng``."""
    if resolved.get("statistics"):
        sensor = Sensor.build(config.sensor.cells)
        scene.info.update(measure(tile, scene, sensor, resolved["statistics_directions_deg"],
                                  resolved["statistics_rays"], rng))
    return scene


def ndf(normals: np.ndarray, areas: np.ndarray, tile_area: float, sensor: Sensor) -> np.ndarray:
    """Cell averages of D (module doc) of facets of unit ``normals`` (F, 3) and ``areas`` (F,)."""
    up = normals[:, 2] > 0.0
    area = np.bincount(sensor.lookup(normals[up]), weights=areas[up], minlength=sensor.n_cells)
    return area / (tile_area * sensor.solid_angle())


def measure(tile, scene, sensor: Sensor, directions_deg, rays: int, rng: np.random.Generator) -> dict:
    """The realization's statistics (module doc): "ndf" (cells,), and at each of the k masking
    directions ``directions_deg`` [theta_o, phi_o]: "g1" (k,), "vndf" (k, cells), "facing_area"
    (k,), and "g1_rays", "g1_free" (k, cells), the shadow rays started on facets of normals in
    each cell and those that left (their ratio, pooled over realizations, is G1(wo, m) with no
    model in it). ``tile``: its facets; ``scene`` (microsim.tracer.scene.Scene): the triangles rays are
    tested against; ``rays`` shadow rays a direction. Facets that do not face up (overhangs,
    vertical walls of a mesh) are in neither ndf nor vndf, but their rays count in g1."""
    # the tracer's kernels, imported where they are used (not when a config is checked)
    from microsim.tracer.integrators.surface_transport import FLOAT32_EPS, OFFSET_SIZE, OFFSET_SPACINGS

    tile_area = tile.sides[0] * tile.sides[1]
    occluded = occlusion_query(scene.vertices, scene.faces)
    offset = max(OFFSET_SIZE * float(np.sqrt(np.mean(tile.areas))),
                 OFFSET_SPACINGS * FLOAT32_EPS * max(*tile.sides, float(np.max(np.abs(tile.vertices)))))
    up = tile.normals[:, 2] > 0.0
    cell = np.where(up, sensor.lookup(tile.normals), -1)
    g1, vndf, facing_area, drawn, left = [], [], [], [], []
    for theta, phi in directions_deg:
        wo = direction(np.radians(theta), np.radians(phi))
        facing = np.maximum(tile.normals @ wo, 0.0) * tile.areas
        total = facing.sum()
        facet = rng.choice(len(facing), size=rays, p=facing / total)
        u, v = rng.random(rays), rng.random(rays)
        flip = u + v > 1.0
        u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
        corners = tile.vertices[tile.faces[facet]]
        points = corners[:, 0] + u[:, None] * (corners[:, 1] - corners[:, 0]) + v[:, None] * (corners[:, 2] - corners[:, 0])
        points += offset * tile.normals[facet]
        free = leaves(occluded, points, wo, tile.sides, scene.z_top)
        binned = up[facet]
        drawn.append(np.bincount(cell[facet[binned]], minlength=sensor.n_cells))
        left.append(np.bincount(cell[facet[binned & free]], minlength=sensor.n_cells))
        vndf.append(left[-1] / rays * total / (wo[2] * tile_area * sensor.solid_angle()))
        g1.append(free.mean())
        facing_area.append(total / tile_area)
    return {"ndf": ndf(tile.normals, tile.areas, tile_area, sensor), "g1": np.array(g1), "vndf": np.array(vndf),
            "facing_area": np.array(facing_area), "g1_rays": np.array(drawn), "g1_free": np.array(left)}


def occlusion_query(vertices, faces):
    """occluded(origins, directions, tfar) -> bool array, on Embree's scene of the triangles:
    the direct binding where it loads, else embreex."""
    from microsim.tracer import embree

    try:
        committed = embree.Scene(vertices, faces)
        return committed.occluded
    except embree.EmbreeUnavailable:
        from microsim.tracer.integrators.embreex import embree_scene

        committed = embree_scene(np.asarray(vertices, np.float32), np.asarray(faces, np.int32))
        return lambda o, d, t: committed.run(np.asarray(o, np.float32), np.asarray(d, np.float32),
                                             dists=np.asarray(t, np.float32), query="OCCLUDED") >= 0


def leaves(occluded, origins: np.ndarray, wo: np.ndarray, sides, z_top: float) -> np.ndarray:
    """Whether the ray from each origin (n, 3) towards ``wo`` (w.z > 0) reaches ``z_top``
    unblocked, crossing the periodic tile [0, L_x) x [0, L_y) (``sides``) side after side
    (module doc)."""
    period = np.array(sides, np.float64)
    p = np.array(origins, np.float64)
    p[:, :2] = np.mod(p[:, :2], period)
    out = np.zeros(len(p), bool)
    active = np.arange(len(p))
    for _ in range(MAX_CROSSINGS):
        if not len(active):
            return out
        q = p[active]
        t_top = (z_top - q[:, 2]) / wo[2]
        t_axis = [(period[k] - q[:, k]) / wo[k] if wo[k] > 0.0 else (-q[:, k] / wo[k] if wo[k] < 0.0
                                                                     else np.full(len(q), np.inf)) for k in (0, 1)]
        t_far = np.minimum(t_top, np.minimum(*t_axis))
        blocked = occluded(q, np.broadcast_to(wo, q.shape), t_far)
        left = t_top <= t_far
        out[active[~blocked & left]] = True
        going = ~blocked & ~left
        q = q[going] + t_far[going, None] * wo
        q[:, :2] = np.mod(q[:, :2], period)
        for k in (0, 1):  # the side it reached: go on from the opposite one
            if wo[k] != 0.0:
                q[t_axis[k][going] <= t_far[going], k] = 0.0 if wo[k] > 0.0 else period[k]
        p[active[going]] = q
        active = active[going]
    raise RuntimeError(f"shadow rays still under the top after {MAX_CROSSINGS} tile crossings")
