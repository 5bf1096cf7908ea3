"""Write ``runs/meshes/weave.ply``: one period of a plain weave, the tile of ``runs/mesh_weave.toml``.

Two families of threads, warp along x and weft along y, ``SPACING`` apart, each passing over one
thread of the other family and under the next. A thread is a tube of elliptical cross-section,
``WIDTH`` wide and ``THICKNESS`` thick, whose centre line undulates as
``z = +-AMPLITUDE sin(pi t / SPACING)`` along it (``t`` the coordinate along the thread), up where
it passes over a crossing thread and down where it passes under it. The surface is what is seen
from above: the height of the highest thread top over each point, and, in the gaps between the
threads, a floor at ``-(AMPLITUDE + THICKNESS / 2)`` (the level of the lowest thread's underside;
it closes the tile, so the run needs no [base]). The tube's sides are steep facets between the
edge of its top (at the centre line's height) and the floor or the thread below.

One period is 2 x 2 threads (the plain weave's repeat): ``PERIOD = 2 SPACING`` on each side,
x and y in [0, PERIOD], a gap at each corner of the tile. Lengths are in units of ``SPACING``
(= 1): period 2, thread width 0.8 (gaps 0.2 wide), thickness 0.3, undulation amplitude 0.15 (a
thread over a crossing rests on the one under it: 2 AMPLITUDE = THICKNESS).

The mesh is a grid of heights, regular in the index but not in space: in x (and alike in y)
grid lines fall on every thread's edges, ``THREAD_STEPS`` intervals across a thread (closer near
its edges, where the ellipse is steep) and ``GAP_STEPS`` across a gap. Each grid cell is two
triangles, split along the diagonal whose mid-point lies nearer the surface at the cell's centre
(the crease where a warp and a weft thread meet runs across cells). The vertices of the x = PERIOD
and y = PERIOD sides are those of x = 0 and y = 0 (the seams match exactly), every face has
area, and every face's normal points up (z > 0): the tile passes geometry/periodic_tile.checked.
2 (2 THREAD_STEPS + 2 GAP_STEPS)^2 = 2592 triangles, 1369 vertices; binary PLY (float32
coordinates, as trimesh writes them), 50 341 bytes.

Regenerate (deterministic, numpy and trimesh only; prints the triangle count and the file's size
and SHA-256), from anywhere::

    python runs/meshes/make_weave.py
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import trimesh

SPACING = 1.0  # between neighbouring threads of one family (the unit of length)
PERIOD = 2.0 * SPACING  # the plain weave's repeat: two threads of each family
WIDTH = 0.8  # of a thread (the gaps between threads are SPACING - WIDTH wide)
THICKNESS = 0.3  # of a thread (its elliptical cross-section's vertical axis)
AMPLITUDE = 0.15  # of a thread's undulation (up over a crossing thread, down under it)
THREAD_STEPS = 14  # grid intervals across a thread
GAP_STEPS = 4  # grid intervals across a gap
OUT = Path(__file__).resolve().parent / "weave.ply"


def grid_lines() -> np.ndarray:
    """The grid's coordinates along x (and y) over one period, 0 to PERIOD inclusive: thread i
    (centre (i + 1/2) SPACING) from its centre - WIDTH / 2 to its centre + WIDTH / 2, at
    half-width sin(s) for s uniform in [-pi/2, pi/2] (closer near the edges), and gaps between."""
    half, gap = WIDTH / 2, SPACING - WIDTH
    across = half * np.sin(np.linspace(-np.pi / 2, np.pi / 2, THREAD_STEPS + 1))
    lines = [np.linspace(0.0, gap / 2, GAP_STEPS // 2 + 1)]
    for i in range(2):
        centre = (i + 0.5) * SPACING
        lines.append(centre + across[1:])
        if i == 0:
            lines.append(np.linspace(centre + half, centre + half + gap, GAP_STEPS + 1)[1:])
    lines.append(np.linspace(PERIOD - gap / 2, PERIOD, GAP_STEPS // 2 + 1)[1:])
    u = np.concatenate(lines)
    assert np.all(np.diff(u) > 0) and u[0] == 0.0 and abs(u[-1] - PERIOD) < 1e-12
    u[-1] = PERIOD
    return u


def height(x, y) -> np.ndarray:
    """The surface over (x, y): the highest thread top there, or the floor."""
    half, b = WIDTH / 2, THICKNESS / 2
    z = np.full(np.broadcast(x, y).shape, -(AMPLITUDE + b))
    for j in range(2):  # warp threads along x, centred on y = (j + 1/2) SPACING
        d = (np.asarray(y) - (j + 0.5) * SPACING) / half
        top = (-1) ** j * AMPLITUDE * np.sin(np.pi * np.asarray(x) / SPACING) + b * np.sqrt(np.clip(1 - d**2, 0, 1))
        z = np.where(np.abs(d) <= 1 + 1e-12, np.maximum(z, top), z)
    for i in range(2):  # weft threads along y, centred on x = (i + 1/2) SPACING, over where warp is under
        d = (np.asarray(x) - (i + 0.5) * SPACING) / half
        top = -(-1) ** i * AMPLITUDE * np.sin(np.pi * np.asarray(y) / SPACING) + b * np.sqrt(np.clip(1 - d**2, 0, 1))
        z = np.where(np.abs(d) <= 1 + 1e-12, np.maximum(z, top), z)
    return z


def weave() -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) and faces (F, 3), counter-clockwise seen from above."""
    u = grid_lines()
    n = len(u) - 1
    gx, gy = np.meshgrid(u, u, indexing="ij")
    gz = height(gx, gy)
    gz[n, :], gz[:, n] = gz[0, :], gz[:, 0]  # the seams: the last row and column are the first
    vertices = np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()])
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a = (i * (n + 1) + j).ravel()
    b, c, d = a + n + 1, a + n + 2, a + 1  # (i + 1, j), (i + 1, j + 1), (i, j + 1)
    z = vertices[:, 2]
    xm = 0.5 * (vertices[a, 0] + vertices[c, 0])
    ym = 0.5 * (vertices[a, 1] + vertices[c, 1])
    centre = height(xm, ym)
    along_ac = np.abs(0.5 * (z[a] + z[c]) - centre) <= np.abs(0.5 * (z[b] + z[d]) - centre)
    faces = np.concatenate([np.where(along_ac[:, None], np.column_stack([a, b, c]), np.column_stack([a, b, d])),
                            np.where(along_ac[:, None], np.column_stack([a, c, d]), np.column_stack([b, c, d]))])
    return vertices, faces


def main() -> None:
    vertices, faces = weave()
    corners = vertices[faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    assert np.all(normals[:, 2] > 0.0), "a face does not face up"
    trimesh.Trimesh(vertices, faces, process=False).export(OUT, encoding="binary")
    data = OUT.read_bytes()
    print(f"{OUT}: {len(faces)} triangles, {len(vertices)} vertices, {len(data)} bytes, "
          f"sha256 {hashlib.sha256(data).hexdigest()}")


if __name__ == "__main__":
    main()
