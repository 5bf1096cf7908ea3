"""A periodic height array, triangulated: one period of a surface repeated in x and y
(docs/conventions.md §5.7).

``path`` names a ``.npy`` file, or a ``.npz`` whose array ``height`` (or its only array) is
taken: a square array h (n x n samples) of one period, sample (i, j) at (i pixel, j pixel),
height ``height_scale`` h; the period is n ``pixel``, and the grid wraps (the sample after the
last is the first). Each grid cell is two triangles (split along its diagonal from (i, j) to
(i + 1, j + 1)), each its own flat facet: a heightfield is a :mod:`geometry.periodic_tile` like
a user's mesh, checked, laid and summarized as it is. Gaussian random surfaces generated per
realization are planned.
"""

from __future__ import annotations

import hashlib
from typing import Literal

import numpy as np
from pydantic import Field

from microsim.scene import Scene
from microsim.schema import Section

from . import periodic_tile
from .periodic_tile import Tile

KIND = "heightfield"
INTEGRATOR = "surface"
#: the generator protocol's, as every periodic tile has them
for_backend, scene_bytes = periodic_tile.for_backend, periodic_tile.scene_bytes
#: most samples a side of a height array
MAX_SAMPLES = 4096


class Config(Section):
    kind: Literal["heightfield"]
    path: str = Field(min_length=1, description="the heights: a .npy file, or a .npz with an array 'height' (or "
                                                "one array), square, one period (relative to the directory "
                                                "microsim runs in)")
    pixel: float = Field(1.0, gt=0.0, le=1e9, description="spacing of the samples in x and y")
    height_scale: float = Field(1.0, gt=0.0, le=1e9, description="factor applied to the heights")


def heights(config) -> tuple[np.ndarray, str]:
    """The config's height array, scaled, and the file's SHA-256; ValueError, one line naming
    scene.path."""
    scene = config.scene
    key, file = periodic_tile.source(config)
    try:
        data = file.read_bytes()
        loaded = np.load(file, allow_pickle=False)
        if isinstance(loaded, np.lib.npyio.NpzFile):
            names = loaded.files
            loaded = loaded["height" if "height" in names else names[0]] if len(names) == 1 or "height" in names \
                else None
            if loaded is None:
                raise ValueError(f"arrays {names}, none named 'height'")
    except Exception as err:  # numpy raises what its readers raise
        raise ValueError(f"{key}: cannot be read as a height array ({' '.join(str(err).split())[:200]})") from None
    h = np.asarray(loaded)
    if h.ndim != 2 or h.shape[0] != h.shape[1] or not 2 <= h.shape[0] <= MAX_SAMPLES or h.dtype.kind not in "iuf":
        raise ValueError(f"{key}: an array of shape {h.shape} and type {h.dtype}; accepted: a square array of numbers, "
                         f"2 to {MAX_SAMPLES} samples a side (rectangular ones are planned)")
    if bad := np.count_nonzero(~np.isfinite(h)):
        raise ValueError(f"{key}: {bad} of {h.size} heights are NaN or infinite")
    return h.astype(np.float64) * scene.height_scale, hashlib.sha256(data).hexdigest()


def triangulate(h: np.ndarray, pixel: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ((n + 1)^2, 3) and faces (2 n^2, 3) of the periodic grid of heights ``h`` (n x n):
    the last row and column of vertices repeat the first a period away."""
    n = len(h)
    wrapped = np.pad(h, ((0, 1), (0, 1)), mode="wrap")
    x = np.arange(n + 1) * pixel
    gx, gy = np.meshgrid(x, x, indexing="ij")
    vertices = np.column_stack([gx.ravel(), gy.ravel(), wrapped.ravel()])
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a = (i * (n + 1) + j).ravel()
    b, c, d = a + n + 1, a + n + 2, a + 1
    faces = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    return vertices, faces


def load(config) -> tuple[Tile, str]:
    """The checked tile of the config's heights and the file's SHA-256, read once
    (:func:`geometry.periodic_tile.remembered`)."""
    return periodic_tile.remembered(config, _read)


def _read(config) -> tuple[Tile, str]:
    h, digest = heights(config)
    vertices, faces = triangulate(h, config.scene.pixel)
    tile = periodic_tile.checked(f"scene.path = {config.scene.path!r}", vertices, faces, len(h) * config.scene.pixel,
                                 closed_by_base=config.base is not None)
    return tile, digest


def check(config) -> None:
    load(config)


def resolve(config) -> dict:
    scene = config.scene
    tile, digest = load(config)
    return {"kind": KIND, "path": scene.path, "pixel": scene.pixel, "height_scale": scene.height_scale,
            "sha256": digest, **periodic_tile.summary(tile)}


def generate(resolved: dict, config, rng: np.random.Generator) -> Scene:
    """The tile (:func:`geometry.periodic_tile.build`); nothing is random."""
    return periodic_tile.build(load(config)[0], resolved, config.material, config.base)
