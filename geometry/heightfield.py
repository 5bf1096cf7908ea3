"""A periodic height array, triangulated: one period of a surface repeated in x and y
(docs/conventions.md §5.7).

Two sources of heights:

- ``path`` names a ``.npy`` file, or a ``.npz`` whose array ``height`` (or its only array) is
  taken: a square array h (n x n samples) of one period, sample (i, j) at (i pixel, j pixel),
  height ``height_scale`` h. Nothing is random: every realization is the same tile.
- ``generator = "gaussian"``: a random Gaussian surface drawn afresh every realization
  (:mod:`microsim.geometry.gaussian_surface`): ``roughness`` (or ``rms_slope``, the same number), or
  ``roughness_x`` + ``roughness_y``, in the ``microfacet`` model's Beckmann alpha meaning (the
  facets' slopes have variance alpha^2 / 2 along each axis), ``correlation_length`` (the
  Gaussian autocorrelation's length, geometric mean of x and y), ``pixel`` (default:
  correlation_length / SAMPLES_PER_CORRELATION) and ``tile`` (default: gaussian_surface.default_tile).

The period is n ``pixel``, and the grid wraps (the sample after the last is the first). Each
grid cell is two triangles (:func:`triangulate`), each its own flat facet or, with ``shading =
"smooth"``, shaded by its vertex normals interpolated: a heightfield is a
:mod:`microsim.geometry.periodic_tile` like a user's mesh, laid and summarized as it is (not run through
the mesh checks: a periodic grid is a surface over the tile by construction); a generated one
records in ``scene/`` per realization what a file's records once (area,
mean_cosine, rms_slope, z_top, ...). With ``intersector = "grid"`` (the default) the scene also
carries its grid (:func:`height_grid`), which the tracer walks instead of handing the triangles
to Embree (:mod:`microsim.tracer.integrators.grid`: the same hits, faster). With ``statistics = true``
each realization's measured
NDF, visible NDF and G1 are stored too (:mod:`microsim.geometry.surface_statistics`).
"""

from __future__ import annotations

import hashlib
import math
from typing import Literal

import numba
import numpy as np
import pydantic
from pydantic import Field

from microsim.core.schema import Section
from microsim.geometry import gaussian_surface, periodic_tile, surface_statistics
from microsim.geometry.periodic_tile import Tile
from microsim.physics import distributions as nd
from microsim.tracer.integrators.grid import HeightGrid
from microsim.tracer.scene import Scene

KIND = "heightfield"
INTEGRATOR = "surface"
#: a small whole run config of this kind, fixed seed (the generator protocol, geometry/__init__.py): what
#: the conformance test of every kind (tests/test_scene_kinds.py) and the CLI fuzzer start from
#: (its file: relative to the repository's root, a config of runs/; microsim.testing.scenes.example resolves it)
EXAMPLE = {"scene": {"kind": "heightfield", "path": "runs/heightfields/dunes.npy", "pixel": 1.0,
                     "height_scale": 0.15},
           "material": {"kind": "lambert", "albedo": 0.4},
           "illumination": {"theta_i_deg": [0.0, 60.0]}, "sensor": {"cells": 24},
           "run": {"paths": 4000, "realizations": 4, "seed": 1}}
#: what sets the scene's size, for the memory refusal (microsim.run.memory.check_memory)
SIZE = "take fewer samples (a smaller array in scene.path; a shorter scene.tile or a larger scene.pixel)"
#: how a .npy and a .npz (a zip file) begin
NPY_MAGIC, NPZ_MAGIC = b"\x93NUMPY", b"PK\x03\x04"
#: most samples a side of a height array
MAX_SAMPLES = 4096
#: keys of a generated surface only, and of a height file only
GENERATOR_KEYS = ("roughness", "roughness_x", "roughness_y", "rms_slope", "correlation_length", "tile")
FILE_KEYS = ("height_scale",)
#: the generator protocol's, as every periodic tile has it (the grid intersector walks the grid
#: whichever backend the run names: scene/intersector says so)
for_backend = periodic_tile.for_backend
#: a heightfield's facets are a pixel across: its copies beyond the sides (those within
#: BASE_MARGIN and one pixel of a side, about 0.04 + 4 / n) add at most this share on grids of 80
#: samples a side or more (more on smaller grids, whose few triangles weigh nothing in memory)
COPIES_SHARE = 0.1


class Config(Section):
    kind: Literal["heightfield"]
    path: str | None = Field(None, min_length=1, description="the heights: a .npy file, or a .npz with an array "
                             "'height' (or one array), square, one period (relative to the directory microsim runs "
                             "in); or give generator")
    generator: Literal["gaussian"] | None = Field(None, description="a random surface drawn every realization "
                                                  "instead of a file: gaussian (Gaussian heights and autocorrelation)")
    pixel: float | None = Field(None, gt=0.0, le=1e9, description="spacing of the samples in x and y (default: 1 "
                                "for a file; correlation_length / 8 for a generated surface)")
    height_scale: float | None = Field(None, gt=0.0, le=1e9, description="factor applied to a file's heights "
                                       "(default 1)")
    roughness: float | None = Field(None, ge=nd.ROUGHNESS_MIN, le=nd.ROUGHNESS_MAX,
                                    description="generated: Beckmann alpha of the facets' slopes, both axes")
    roughness_x: float | None = Field(None, ge=nd.ROUGHNESS_MIN, le=nd.ROUGHNESS_MAX,
                                      description="generated: alpha along x")
    roughness_y: float | None = Field(None, ge=nd.ROUGHNESS_MIN, le=nd.ROUGHNESS_MAX,
                                      description="generated: alpha along y")
    rms_slope: float | None = Field(None, ge=nd.ROUGHNESS_MIN, le=nd.ROUGHNESS_MAX,
                                    description="generated: RMS of the slope's magnitude, sqrt(<|grad h|^2>) (the "
                                    "isotropic alpha)")
    correlation_length: float | None = Field(None, gt=0.0, le=1e9, description="generated: length l of the "
                                             "Gaussian autocorrelation exp(-r^2 / l^2) (geometric mean of x and y; "
                                             "default 1)")
    tile: float | None = Field(None, gt=0.0, le=1e9, description="generated: the period (default: 16 correlation "
                               "lengths, longer where grazing rays need it; whole pixels)")
    shading: Literal["flat", "smooth"] = Field("flat", description=periodic_tile.SHADING_DESCRIPTION)
    intersector: Literal["triangles", "grid"] = Field("grid", description="how rays meet the triangles: "
                                                      "triangles (Embree) or grid (a walk over the grid's cells, no "
                                                      "Embree scene; the same triangles)")
    statistics: bool = surface_statistics.statistics_key()
    statistics_rays: int | None = surface_statistics.rays_key()

    @pydantic.model_validator(mode="after")
    def _one_source(self):
        given = self.model_fields_set
        surface_statistics.check_keys(self)
        if (self.path is None) == (self.generator is None):
            raise ValueError("scene.path: give either path (a height file) or generator = \"gaussian\", "
                             f"{'not both' if self.path is not None else 'one of them'}")
        wrong = [key for key in (FILE_KEYS if self.generator else GENERATOR_KEYS) if key in given]
        if wrong:
            what = "a height file" if self.generator else "generator = \"gaussian\""
            raise ValueError(f"scene.{wrong[0]}: for {what} only")
        if self.generator is None:
            return self
        forms = [key for key in ("roughness", "rms_slope") if key in given]
        axes = [key for key in ("roughness_x", "roughness_y") if key in given]
        accepted = f"[{nd.ROUGHNESS_MIN:g}, {nd.ROUGHNESS_MAX:g}]"
        if len(forms) + bool(axes) != 1 or len(axes) == 1:
            raise ValueError(f"scene.roughness: give one of roughness, rms_slope, or roughness_x and roughness_y, "
                             f"each in {accepted}")
        if self.pixel is not None and self.pixel > self.correlation:
            raise ValueError(f"scene.correlation_length = {self.correlation:g} is below scene.pixel = "
                             f"{self.pixel:g}; accepted: correlation_length >= pixel (at least one sample a "
                             f"correlation length; default pixel: correlation_length / "
                             f"{gaussian_surface.SAMPLES_PER_CORRELATION})")
        return self

    @property
    def correlation(self) -> float:
        """correlation_length, 1 where not given (None stays out of the config's TOML, which a
        height file's config must not hold)."""
        return 1.0 if self.correlation_length is None else self.correlation_length

    @property
    def height_factor(self) -> float:
        """height_scale, 1 where not given."""
        return 1.0 if self.height_scale is None else self.height_scale

    @property
    def roughnesses(self) -> tuple[float, float]:
        if self.roughness_x is not None:
            return self.roughness_x, self.roughness_y
        alpha = self.roughness if self.roughness is not None else self.rms_slope
        return alpha, alpha


def heights(config) -> tuple[np.ndarray, str]:
    """The config's height array, scaled, and the file's SHA-256; ValueError, one line naming
    scene.path."""
    scene = config.scene
    key, file = periodic_tile.source(config)
    try:
        data = file.read_bytes()
    except OSError as err:
        raise ValueError(f"{key}: cannot be read ({err.strerror})") from None
    if not data.startswith((NPY_MAGIC, NPZ_MAGIC)):
        raise ValueError(f"{key}: not a NumPy file (a .npy starts with {NPY_MAGIC!r}, a .npz is a zip file; this "
                         f"one starts with {data[:8]!r}): write the heights with numpy.save or numpy.savez")
    try:
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
    return h.astype(np.float64) * scene.height_factor, hashlib.sha256(data).hexdigest()


def triangulate(h: np.ndarray, pixel: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ((n + 1)^2, 3) and faces (2 n^2, 3) of the periodic grid of heights ``h`` (n x n):
    the last row and column of vertices repeat the first a period away. Cell (i, j) is split
    along its diagonal from (i, j) to (i + 1, j + 1) where i + j is even, along the other one
    where it is odd (microsim.geometry.gaussian_surface: the facets' slopes along x and y are then not
    correlated on average)."""
    return _triangulate(np.ascontiguousarray(h, np.float64), float(pixel))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _triangulate(h, pixel):
    """:func:`triangulate`: vertex (i, j) at row i (n + 1) + j; the first triangles of the cells
    in row-major order, then the second ones."""
    n = len(h)
    vertices = np.empty(((n + 1) * (n + 1), 3))
    for i in range(n + 1):
        for j in range(n + 1):
            v = i * (n + 1) + j
            vertices[v, 0], vertices[v, 1], vertices[v, 2] = i * pixel, j * pixel, h[i % n, j % n]
    faces = np.empty((2 * n * n, 3), np.int64)
    for i in range(n):
        for j in range(n):
            cell = i * n + j
            a = i * (n + 1) + j  # corner (i, j); b (i + 1, j), c (i + 1, j + 1), d (i, j + 1)
            b, c, d = a + n + 1, a + n + 2, a + 1
            if (i + j) % 2 == 0:
                faces[cell, 0], faces[cell, 1], faces[cell, 2] = a, b, c
                faces[n * n + cell, 0], faces[n * n + cell, 1], faces[n * n + cell, 2] = a, c, d
            else:
                faces[cell, 0], faces[cell, 1], faces[cell, 2] = a, b, d
                faces[n * n + cell, 0], faces[n * n + cell, 1], faces[n * n + cell, 2] = b, c, d
    return vertices, faces


def load(config) -> tuple[Tile, str]:
    """The checked tile of the config's height file and the file's SHA-256, read once
    (:func:`microsim.geometry.periodic_tile.remembered`)."""
    return periodic_tile.remembered(config, _read)


def _read(config) -> tuple[Tile, str]:
    """The file's tile. A periodic grid's triangles are a surface over the tile by construction
    (their seams match, they face up, none is degenerate): the mesh checks have nothing to find,
    and are not run (their edge matching takes about a minute at 2048^2 samples)."""
    h, digest = heights(config)
    pixel = file_pixel(config.scene)
    periodic_tile.require_period(f"scene.pixel = {pixel:g}", len(h) * pixel)
    return Tile.of(*triangulate(h, pixel), len(h) * pixel), digest


def file_pixel(scene) -> float:
    return scene.pixel if scene.pixel is not None else 1.0


def check(config) -> None:
    if config.scene.generator is None:
        load(config)
    else:
        _generated(config)


def _generated(config) -> dict:
    """The resolved parameters of a generated surface (module doc); ValueError, one line, for a
    tile too short for its correlation or with more than MAX_SAMPLES samples a side."""
    scene = config.scene
    alpha_x, alpha_y = scene.roughnesses
    pixel = scene.pixel if scene.pixel is not None else \
        scene.correlation / gaussian_surface.SAMPLES_PER_CORRELATION
    field = gaussian_surface.field_parameters(alpha_x, alpha_y, scene.correlation, pixel)
    longest = max(field["correlation_x"], field["correlation_y"])
    grazing = math.radians(max(max(config.illumination.theta_i_deg), 85.0))
    default, floor = gaussian_surface.default_tile(field["sigma"], longest, pixel, grazing)
    samples = round((scene.tile if scene.tile is not None else default) / pixel)
    shortest = gaussian_surface.MIN_TILE_CORRELATIONS * longest
    if samples * pixel < shortest * (1 - 1e-9):
        if scene.tile is not None:
            raise ValueError(f"scene.tile = {scene.tile:g}: shorter than {gaussian_surface.MIN_TILE_CORRELATIONS} "
                             f"correlation lengths ({longest:.4g} along the longer axis); accepted: tile >= "
                             f"{shortest:.4g}")
        raise ValueError(f"scene.pixel = {pixel:g}: the default tile of {samples} samples is shorter than "
                         f"{gaussian_surface.MIN_TILE_CORRELATIONS} correlation lengths ({shortest:.4g}); accepted: "
                         f"pixel >= {shortest / gaussian_surface.MAX_DEFAULT_SAMPLES:.4g}, or give scene.tile (up to "
                         f"{MAX_SAMPLES} samples)")
    periodic_tile.require_period(f"scene.tile = {samples * pixel:g}" if scene.tile is not None
                                 else f"scene.correlation_length = {scene.correlation:g}", samples * pixel)
    if not 2 <= samples <= MAX_SAMPLES:
        raise ValueError(f"scene.tile = {samples * pixel:g}: {samples} samples of scene.pixel = {pixel:g} a side; "
                         f"accepted: 2 to {MAX_SAMPLES}")
    period = samples * pixel
    return {"kind": KIND, "generator": scene.generator, **_tracing(scene), "roughness_x": alpha_x, "roughness_y": alpha_y,
            "correlation_length": scene.correlation, **field, "pixel": pixel, "samples": samples,
            "samples_per_correlation": scene.correlation / pixel, "period": period, "period_y": period,
            "tile": period, "tile_default": scene.tile is None, "tile_bias_floor": floor, "surface_triangles": 2 * samples**2,
            "max_mesh_error": 0.0}


def resolve(config) -> dict:
    scene = config.scene
    statistics = surface_statistics.resolve(config, isotropic=scene.generator is not None
                                            and scene.roughnesses[0] == scene.roughnesses[1])
    if scene.generator is not None:
        return {**_generated(config), **statistics}
    tile, digest = load(config)
    return {"kind": KIND, "path": scene.path, **_tracing(scene), "pixel": file_pixel(scene),
            "height_scale": scene.height_factor,
            "sha256": digest, **periodic_tile.summary(tile), **statistics}


def _tracing(scene) -> dict:
    """How the surface is shaded and met, as both sources resolve it."""
    return {"shading": scene.shading, "intersector": scene.intersector}


def scene_bytes(resolved: dict) -> int:
    """The triangles: each a pixel across, so that few are copied beyond the sides (COPIES_SHARE)."""
    return int((1.0 + COPIES_SHARE) * resolved["surface_triangles"] * periodic_tile.triangle_bytes(resolved)) + 4096


def realize(resolved: dict, rng: np.random.Generator) -> Tile:
    """The tile of one generated surface of ``resolved`` (a generator's), drawn from ``rng``."""
    pixel = resolved["pixel"]
    h = gaussian_surface.heights(resolved["samples"], pixel, resolved["sigma"], resolved["correlation_x"],
                                 resolved["correlation_y"], rng)
    return Tile.of(*triangulate(h, pixel), resolved["period"])


def generate(resolved: dict, config, rng: np.random.Generator) -> Scene:
    """The tile (:func:`microsim.geometry.periodic_tile.build`): the file's, or a Gaussian surface drawn
    from ``rng``, whose own summary (area, mean_cosine, rms_slope, heights) the scene's info
    carries; with ``statistics``, the realization's NDF and masking measured."""
    if resolved.get("generator") is None:
        tile, laid = load(config)[0], resolved
        scene = periodic_tile.build(tile, laid, config.material, config.base)
    else:
        tile = realize(resolved, rng)
        own = periodic_tile.summary(tile)
        laid = {**resolved, **own}
        scene = periodic_tile.build(tile, laid, config.material, config.base)
        scene.info.update({key: own[key] for key in own.keys() - resolved.keys()})
        scene.info.update(zip(("measured_roughness_x", "measured_roughness_y"), periodic_tile.roughness(tile)))
    if resolved.get("intersector") == "grid":
        scene.grid = height_grid(tile, laid, scene, config.base is not None)
    return surface_statistics.add(scene, tile, resolved, config, rng)


def height_grid(tile: Tile, laid: dict, scene: Scene, has_base: bool) -> HeightGrid:
    """The grid the grid backend walks (microsim.tracer.integrators.grid): the tile's heights (its
    vertices as :func:`triangulate` lays them), where its own faces and the base lie in ``scene``."""
    n = math.isqrt(len(tile.vertices)) - 1
    heights = tile.vertices[:, 2].reshape(n + 1, n + 1)[:n, :n]
    base = {"base_z": laid["base_z"], "base_prim": scene.n_triangles - 2} if has_base else {}
    return HeightGrid.of(heights, laid["pixel"], periodic_tile.first_own_face(tile), **base)
