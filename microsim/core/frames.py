"""Directions in the frame of docs/conventions.md §1: normal +z, phi measured from +x towards +y."""

import numpy as np


def direction(theta, phi=0.0) -> np.ndarray:
    """Unit vector(s) (..., 3) from polar angle ``theta`` and azimuth ``phi`` (radians)."""
    theta = np.asarray(theta, dtype=np.float64)
    phi = np.asarray(phi, dtype=np.float64)
    theta, phi = np.broadcast_arrays(theta, phi)
    s = np.sin(theta)
    return np.stack([s * np.cos(phi), s * np.sin(phi), np.cos(theta)], axis=-1)
