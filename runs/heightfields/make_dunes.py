"""Write ``runs/heightfields/dunes.npy``: one period of a dune field, the heights of
``runs/heightfield_dunes.toml``.

A periodic array of ``N x N`` float32 heights (sample (i, j) at (i, j) pixels; the grid wraps), the
sum of three parts, each periodic over the N-pixel tile because every wave vector is a whole
number of cycles a period:

- dunes: crests across the wave vector ``DUNE_K`` (cycles a period in x, y; about 31 pixels
  apart), with the asymmetric profile of wind-blown sand, a gentle windward (stoss) side and a
  steep lee side (the first ``HARMONICS`` terms of a sawtooth, sum sin(n t) / n^1.5); their
  crests wander (the phase t moved by the terms ``DUNE_WANDER``, slow sinusoids across the tile)
  and their height varies along them (``DUNE_VARIATION``);
- ripples: the same profile, ``RIPPLE_HEIGHT`` of the dunes', finer (``RIPPLE_K``, about 9
  pixels apart), wandering (``RIPPLE_WANDER``);
- roughness: a Gaussian random field, white noise filtered by 1 / (1 + (f / ``NOISE_CORNER``)^2)
  (f in cycles a period), ``NOISE_HEIGHT`` of the dunes' RMS height.

Every random phase and the noise come from one generator seeded with ``SEED``: the file is the
same at every run. The array is normalized to mean 0 and to a root-mean-square slope of 1 over
the triangles the heightfield scene makes of it (pixel = 1; every triangle has the same
projected area, so this is the projected-area weighting of the table's scene/ rms_slope; and it
does not depend on which diagonal splits a cell, :func:`mean_square_slope`): with ``pixel = 1``
the config's ``height_scale`` is the table's rms_slope, to float32 rounding. The script prints
the largest slope of a triangle (4.7 times the RMS: the lee faces; height_scale = 0.15 puts them
at 35 deg, about sand's angle of repose).
128 x 128 samples (2 x 128^2 = 32768 triangles), .npy of 65 664 bytes.

Regenerate (deterministic, numpy only), from anywhere::

    python runs/heightfields/make_dunes.py
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

N = 128  # samples a side (one period)
SEED = 28
DUNE_K = (4, 1)  # the dunes' wave vector, cycles a period in x and y
#: the crests' wandering: (radians of phase, wave vector) terms of sin(2 pi m.x / N + random phase)
DUNE_WANDER = ((0.9, (0, 1)), (0.5, (1, 2)))
#: the crests' height varies by this fraction along them: 1 + VARIATION sin(2 pi m.x / N + phase)
DUNE_VARIATION = (0.25, (2, -1))
RIPPLE_K = (14, 3)  # the ripples' wave vector
RIPPLE_WANDER = ((0.7, (0, 3)), (0.4, (2, 5)))
RIPPLE_HEIGHT = 0.05  # of the dunes'
HARMONICS = 5
NOISE_CORNER = 10.0  # cycles a period
NOISE_HEIGHT = 0.05  # RMS, of the dunes' RMS
OUT = Path(__file__).resolve().parent / "dunes.npy"


def profile(t: np.ndarray) -> np.ndarray:
    """A dune's cross-section over a cycle t in radians: a gentle rise and a steep fall (the
    first HARMONICS terms of a sawtooth, softened as 1 / n^1.5)."""
    return sum(np.sin(n * t) / n**1.5 for n in range(1, HARMONICS + 1))


def crests(gx, gy, k, wander, rng) -> np.ndarray:
    """The profile along wave vector k (cycles a period), its phase moved by the terms
    ``wander`` of (radians, wave vector m): radians sin(2 pi m.x / N + phase), a random phase
    each."""
    t = 2 * np.pi * (k[0] * gx + k[1] * gy) / N
    for radians, m in wander:
        t = t + radians * np.sin(2 * np.pi * (m[0] * gx + m[1] * gy) / N + rng.uniform(0, 2 * np.pi))
    return profile(t)


def mean_square_slope(h: np.ndarray) -> float:
    """The mean over the triangles of the periodic grid (pixel 1) of their squared slope: a
    triangle's slopes along x and y are the height differences along its x and y edges, and a
    cell's two triangles have each of its four edges once, whichever diagonal splits it."""
    dx, dy = np.roll(h, -1, axis=0) - h, np.roll(h, -1, axis=1) - h
    return float(np.mean(dx**2 + dy**2))


def largest_slope(h: np.ndarray) -> float:
    """The largest slope of a triangle, whichever diagonal splits each cell (pixel 1)."""
    dx, dy = np.roll(h, -1, axis=0) - h, np.roll(h, -1, axis=1) - h
    dx_top, dy_right = np.roll(dx, -1, axis=1), np.roll(dy, -1, axis=0)
    return float(max(np.hypot(sx, sy).max() for sx in (dx, dx_top) for sy in (dy, dy_right)))


def dunes() -> np.ndarray:
    rng = np.random.default_rng(SEED)
    x = np.arange(N, dtype=np.float64)
    gx, gy = np.meshgrid(x, x, indexing="ij")
    fraction, m = DUNE_VARIATION
    h = crests(gx, gy, DUNE_K, DUNE_WANDER, rng) \
        * (1 + fraction * np.sin(2 * np.pi * (m[0] * gx + m[1] * gy) / N + rng.uniform(0, 2 * np.pi)))
    h += RIPPLE_HEIGHT * crests(gx, gy, RIPPLE_K, RIPPLE_WANDER, rng)
    f = np.fft.fftfreq(N, 1.0 / N)
    fx, fy = np.meshgrid(f, f, indexing="ij")
    spectrum = 1.0 / (1.0 + (fx**2 + fy**2) / NOISE_CORNER**2)
    noise = np.fft.ifft2(np.fft.fft2(rng.standard_normal((N, N))) * spectrum).real
    h += NOISE_HEIGHT * h.std() / noise.std() * noise
    h -= h.mean()
    return (h / np.sqrt(mean_square_slope(h))).astype(np.float32)


def main() -> None:
    h = dunes()
    np.save(OUT, h)
    data = OUT.read_bytes()
    h64 = h.astype(np.float64)
    print(f"{OUT}: {h.shape[0]} x {h.shape[1]} heights (float32), {len(data)} bytes, sha256 "
          f"{hashlib.sha256(data).hexdigest()}; RMS slope {np.sqrt(mean_square_slope(h64)):.6f} (pixel 1), "
          f"largest {largest_slope(h64):.3g}; heights {h.min():.3g} to {h.max():.3g}")


if __name__ == "__main__":
    main()
