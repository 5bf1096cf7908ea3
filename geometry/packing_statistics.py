"""The structure of a sphere packing, measured: its pair correlation g(r).

:func:`pair_correlation` is g(r) of the centres in a box periodic in x, y and z, over the bins
``edges`` (in radii): the pairs at distances in each bin, over those an ideal gas of the same
number density would have, N (N - 1) / (2 V) times the shell's volume. Every pair is counted (a
periodic k-d tree), the images included; r up to half the box's shortest edge.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree


def pair_correlation(centres: np.ndarray, box, edges: np.ndarray) -> np.ndarray:
    """g(r) in the bins ``edges`` of the ``centres`` in the periodic ``box`` (module doc)."""
    box = np.asarray(box, np.float64)
    if edges[-1] > 0.5 * box.min():
        raise ValueError(f"pair_correlation: r up to {edges[-1]:g}, beyond half the box's shortest edge {box.min():g}")
    tree = cKDTree(np.mod(centres, box), boxsize=box)
    pairs = np.diff(tree.count_neighbors(tree, edges, cumulative=True)).astype(np.float64) / 2.0  # ordered pairs / 2
    n, volume = len(centres), float(np.prod(box))
    shells = 4.0 / 3.0 * math.pi * np.diff(edges**3)
    return pairs / (n * (n - 1) / (2.0 * volume) * shells)
