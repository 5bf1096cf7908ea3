"""What a sphere-scene realization is, measured: its pair correlation and its void's chords.

For the spheres of a realization of ``poisson_spheres`` or ``packed_spheres`` (exact spheres,
whatever the traced model), with ``statistics = true``, stored per realization in the table's
``scene/`` (docs/conventions.md §6):

- ``pair_correlation``: g(r) of the centres in the box of the tile and the slab's depth, periodic
  in x, y and z (:func:`microsim.geometry.packing_statistics.pair_correlation`; a Boolean scene's
  Poisson centres are a Poisson process on that torus too), over the bins ``pair_edges`` (attrs):
  ``PAIR_BIN`` radii wide out to ``PAIR_RANGE`` radii or half the box's shortest edge.
- ``chords``: the void's chord lengths in the bulk. From points drawn uniformly on the spheres'
  exposed surface (a sphere drawn in proportion to its area, a point uniform on it, kept if no
  other sphere covers it) a ray leaves in a cosine-weighted direction about the outward normal,
  as a Lambertian grain scatters, to the next sphere it enters, in the same box periodic in x, y
  and z: by Cauchy's and Santalo's formulas these are the chords of isotropic uniform random
  lines through the void, of mean 4 (1 - phi) / S_v (S_v the exposed area per volume) in any
  medium; for Boolean spheres exactly exponential, P(L > l) = exp(-n pi r^2 l) (the centres
  other than the start's are Poisson outside the start point's ball: Slivnyak's theorem).
  Counts in the bins ``chord_edges`` (attrs), the last bin every chord beyond the last edge;
  ``mean_chord`` is their mean, none cut.
- ``free_path_top``: at each incidence of the run, the path from the plane z = the largest
  radius (above every sphere) along wi to the first sphere, for rays at points uniform over the
  tile: the first flight of the incident light, in the slab as traced (periodic in x and y, not
  in z). Counts in the bins ``chord_edges``, the last bin every path beyond the last edge or
  through the slab. For Boolean spheres at normal incidence, exactly P(T > t) = exp(-n V(t)),
  V(t) = pi t^2 (3 - t) / 3 for t <= 1, 2 pi / 3 + pi (t - 1) beyond (the centres below z = 0
  within a radius of the path).

The bins: ``CHORD_BINS`` of equal width out to ``CHORD_RANGE`` times the scene's free path
(``scene/free_path``); ``statistics_rays`` (default ``RAYS``) chords a realization, and as many
top rays at each incidence.
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import Field

from microsim.core.frames import direction
from microsim.geometry.packing_statistics import pair_correlation

#: chords (and top rays at each incidence) a realization, by default
RAYS = 16384
#: g(r): bins of this width, in radii, out to PAIR_RANGE radii (or half the box's shortest edge)
PAIR_BIN = 0.1
PAIR_RANGE = 10.0
#: chord histograms: this many bins out to CHORD_RANGE free paths, and one more beyond
CHORD_BINS = 48
CHORD_RANGE = 6.0
#: candidate start points drawn a round, per chord still wanted (some are covered)
OVERDRAW = 1.25


def statistics_key():
    """The ``[scene]`` key ``statistics`` of the sphere scenes (pydantic Field)."""
    return Field(False, description="store every realization's measured pair correlation g(r) and void chord "
                                    "distributions, in the bulk and from the top (microsim.geometry.sphere_statistics)")


def rays_key():
    """The ``[scene]`` key ``statistics_rays`` (pydantic Field)."""
    return Field(None, ge=16, le=10_000_000, description="with statistics: chords a realization, and top rays "
                                                         f"an incidence (default {RAYS})")


def resolve(config, box, free_path: float) -> dict:
    """The table's record of what a run measures: {"statistics": False}, or the rays and the bins
    of g(r) (``box``: the spheres' periodic box) and of the chords (``free_path``: the void's)."""
    scene = config.scene
    if not scene.statistics:
        return {"statistics": False}
    reach = min(PAIR_RANGE, math.floor(0.5 * min(box) / PAIR_BIN) * PAIR_BIN)
    return {"statistics": True, "statistics_rays": RAYS if scene.statistics_rays is None else scene.statistics_rays,
            "pair_edges": np.linspace(0.0, reach, round(reach / PAIR_BIN) + 1).tolist(),
            "chord_edges": np.linspace(0.0, CHORD_RANGE * free_path, CHORD_BINS + 1).tolist()}


def add(scene, centres: np.ndarray, radii: np.ndarray, resolved: dict, config, rng: np.random.Generator):
    """``scene`` with, if ``resolved`` asks for statistics, :func:`measure` of the spheres
    (``centres`` in the tile and -depth <= z < 0, ``radii``) in its info; rays drawn from ``rng``."""
    if resolved.get("statistics"):
        incidences = direction(np.radians(config.illumination.theta_i_deg), np.radians(config.illumination.azimuths_deg()))
        scene.info.update(measure(centres, radii, resolved["tile"], resolved["depth"], incidences, resolved, rng))
    return scene


def measure(centres, radii, tile: float, depth: float, incidences: np.ndarray, resolved: dict,
            rng: np.random.Generator) -> dict:
    """The realization's statistics (module doc): "pair_correlation" (pair bins,), "chords"
    (chord bins + 1,), "mean_chord", and "free_path_top" (incidences, chord bins + 1) at the unit
    ``incidences`` (n_i, 3) (wi, pointing away from the surface)."""
    # the kernels, imported where they are used (not when a config is checked)
    from microsim.geometry import void_chords

    radii = np.broadcast_to(np.asarray(radii, np.float64), (len(centres),))
    rays, edges = resolved["statistics_rays"], np.asarray(resolved["chord_edges"])
    box = np.array([tile, tile, depth])
    g = pair_correlation(centres, box, np.asarray(resolved["pair_edges"]))
    wrapped = np.mod(centres - [0.0, 0.0, -depth], box)
    chords = bulk_chords(void_chords.build(wrapped, radii, (0.0, 0.0, 0.0), box, (True,) * 3), wrapped, radii, rays,
                         edges[-1], rng)
    highest = float(radii.max(initial=0.0))
    slab = void_chords.build(centres, radii, (0.0, 0.0, -depth - highest), (tile, tile, depth + 2.0 * highest),
                             (True, True, False))
    top = []
    for wi in incidences:
        origins = np.column_stack([rng.uniform(0.0, tile, (rays, 2)), np.full(rays, highest)])
        top.append(histogram(void_chords.first_hits(slab, origins, np.broadcast_to(-wi, (rays, 3)), edges[-1]), edges))
    return {"pair_correlation": g, "chords": histogram(chords, edges),
            "mean_chord": float(np.mean(chords)) if np.all(np.isfinite(chords)) else math.inf,
            "free_path_top": np.array(top)}


def histogram(lengths: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Counts of ``lengths`` in the bins ``edges``, and one more: those beyond the last (inf too)."""
    inside = np.histogram(lengths[np.isfinite(lengths)], edges)[0]
    return np.append(inside, len(lengths) - inside.sum()).astype(np.int64)


def bulk_chords(grid, centres: np.ndarray, radii: np.ndarray, rays: int, t_max: float,
                rng: np.random.Generator) -> np.ndarray:
    """``rays`` chords of the void (module doc) of the spheres of ``grid`` (``centres``, ``radii``):
    each the distance to the next sphere, or inf beyond ``t_max``. The chords themselves, long
    ones walked to the end, are what ``mean_chord`` averages: ``t_max`` here is only a guard."""
    from microsim.geometry import void_chords

    area = radii * radii
    chosen, normals = [], []
    wanted = rays
    while wanted > 0:
        drawn = max(16, int(OVERDRAW * wanted))
        own = rng.choice(len(radii), size=drawn, p=area / area.sum())
        normal = rng.standard_normal((drawn, 3))
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        kept = ~void_chords.covered(grid, centres[own] + radii[own, None] * normal, own)
        chosen.append(own[kept][:wanted])
        normals.append(normal[kept][:wanted])
        wanted -= len(chosen[-1])
    own, normal = np.concatenate(chosen), np.concatenate(normals)
    origins = centres[own] + radii[own, None] * normal
    return void_chords.first_hits(grid, origins, cosine_about(normal, rng), 1e3 * t_max)


def cosine_about(normals: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Directions drawn with density cos(theta) / pi about each unit row of ``normals``."""
    u1, u2 = rng.random(len(normals)), rng.random(len(normals))
    r, phi = np.sqrt(u1), 2.0 * math.pi * u2
    local = np.column_stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(0.0, 1.0 - u1))])
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    tangent = np.cross(helper, normals)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    bitangent = np.cross(normals, tangent)
    return local[:, :1] * tangent + local[:, 1:2] * bitangent + local[:, 2:] * normals
