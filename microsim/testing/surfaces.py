"""Inputs of the mesh and heightfield tests: small periodic tiles, made on the spot.

Contract: :func:`ridges` is an anisotropic periodic height array of one period 1 (pixel
1 / n) with no mirror symmetry; :func:`bumpy` a periodic sinusoidal mesh tile of ``N`` x ``N``
cells (and, on request, the defects a mesh check must refuse: seams that do not match, reversed
winding, a hole); :func:`write_mesh` writes vertices and faces as a mesh file trimesh reads
(by the suffix of its name) and returns its path.
"""

from __future__ import annotations

import math

import numpy as np
import trimesh

#: samples a period of the ridges
RIDGE_SAMPLES = 32
N = 16  # cells a side of the bumpy tile


def ridges(n: int = RIDGE_SAMPLES) -> np.ndarray:
    """An anisotropic periodic height array of one period 1 (pixel 1 / n): steep asymmetric ridges
    along y (RMS slope about 1.9), gentle waves along x, an oblique term that breaks the mirror
    symmetries."""
    x = np.arange(n) / n
    gx, gy = np.meshgrid(x, x, indexing="ij")
    return (0.3 * (np.sin(2 * math.pi * gx) + 0.5 * np.sin(4 * math.pi * gx)) + 0.04 * np.cos(4 * math.pi * gy)
            + 0.05 * np.sin(2 * math.pi * (gx + gy)))


def bumpy(period: float = 2.0, lift_edge: float = 0.0, flip: bool = False, drop: int = 0):
    """A periodic sinusoidal tile (vertices, faces): z = 0.3 sin(pi x) cos(pi y) on [0, period]^2;
    ``lift_edge`` raises the x = 0 side (seams that no longer match), ``flip`` reverses the
    winding, ``drop`` removes that many faces in the middle (a hole)."""
    x = np.linspace(0.0, period, N + 1)
    gx, gy = np.meshgrid(x, x, indexing="ij")
    gz = 0.3 * np.sin(math.pi * gx) * np.cos(math.pi * gy)
    gz[0, :] += lift_edge
    vertices = np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()])
    faces = []
    for i in range(N):
        for j in range(N):
            a, b = i * (N + 1) + j, (i + 1) * (N + 1) + j
            faces += [[a, b, b + 1], [a, b + 1, a + 1]]
    faces = np.array(faces)
    if drop:  # the faces of cells in the middle of the tile, away from its sides
        middle = 2 * ((N // 2) * N + N // 2)
        faces = np.delete(faces, range(middle, middle + drop), axis=0)
    return vertices, faces[:, ::-1] if flip else faces


def write_mesh(path, vertices, faces) -> str:
    trimesh.Trimesh(vertices, faces, process=False).export(path)
    return str(path)
