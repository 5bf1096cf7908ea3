"""A table beside a model, rendered (``microsim render``, the optional extra ``render``).

The four papers show their BRDFs on objects; so does this: a unit sphere (or a user's mesh,
centred, its bounding box's longest side 2) seen from +z, lit once by a directional light (irradiance 1, arriving from
LIGHT, 55 degrees from the view) and once by a constant environment (radiance 1), each with the
table's tabulated BRDF, with the model's, and their relative difference (table - model) / model,
side by side with colour bars. Mitsuba 3's path tracer renders them (:mod:`microsim.interop.mitsuba`),
one bounce (the sphere cannot see itself), the same seed for table and model.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from microsim.core.files import atomic
from microsim.interop import mitsuba as plugin

#: where the directional light comes from (a direction towards it), in the camera's frame: the
#: camera looks down -z at the object
LIGHT = np.array([-1.0, 1.0, 1.0]) / np.sqrt(3.0)
#: the lights the object is rendered under
LIGHTS = ("directional", "environment")
#: the camera's distance and field of view (degrees): the unit sphere fills three quarters of the frame
CAMERA_DISTANCE, FIELD_OF_VIEW = 5.0, 30.0
#: mesh files Mitsuba reads, by suffix
MESH_TYPES = {".ply": "ply", ".obj": "obj"}
#: the suffixes of a render's file -> the format matplotlib writes it in
FORMATS = {".png": "png", ".jpg": "jpeg", ".jpeg": "jpeg", ".pdf": "pdf", ".svg": "svg"}


def scene(bsdf, light: str, size: int, spp: int, mesh: Path | None = None):
    """The Mitsuba scene of one render: the object with ``bsdf`` under ``light`` (module doc)."""
    mi = plugin.load()
    emitter = {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}} if light == "environment" else \
        {"type": "directional", "direction": (-LIGHT).tolist(), "irradiance": {"type": "rgb", "value": 1.0}}
    return mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 2},
        "sensor": {"type": "perspective", "fov": FIELD_OF_VIEW,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, CAMERA_DISTANCE], target=[0, 0, 0],
                                                              up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": size, "height": size, "pixel_format": "rgba",
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": spp}},
        "object": _object(mi, bsdf, mesh),
        "light": emitter,
    })


def _object(mi, bsdf, mesh: Path | None) -> dict:
    """The unit sphere, or ``mesh`` centred on it, its bounding box's longest side scaled to 2 (a
    ball becomes the unit sphere)."""
    if mesh is None:
        return {"type": "sphere", "bsdf": bsdf}
    shape = {"type": MESH_TYPES[mesh.suffix.lower()], "filename": str(mesh)}
    try:
        box = mi.load_dict(shape).bbox()
    except RuntimeError as err:
        raise ValueError(f"--mesh {mesh}: Mitsuba cannot read it ({str(err).strip().splitlines()[-1]})") from None
    centre = (np.array(box.min) + np.array(box.max)) / 2
    radius = float(np.max(np.array(box.max) - np.array(box.min))) / 2  # a ball's radius
    to_world = mi.ScalarTransform4f().scale(float(1.0 / radius)).translate([float(x) for x in -centre])
    return {**shape, "to_world": to_world, "bsdf": bsdf, "face_normals": False}


def render(bsdf, light: str, size: int = 256, spp: int = 64, seed: int = 0, mesh: Path | None = None):
    """The grey radiance (the red channel; the BRDFs are grey), (size, size)."""
    mi = plugin.load()
    try:
        image = mi.render(scene(bsdf, light, size, spp, mesh), spp=spp, seed=seed)
    except Exception as err:
        raise plugin.raised(bsdf, err) from None
    return np.asarray(image, dtype=np.float64)[..., 0]


def coverage(size: int = 256, spp: int = 64, mesh: Path | None = None) -> np.ndarray:
    """The share of each pixel the object covers, (size, size): the film's alpha under the
    directional light (an environment covers every pixel)."""
    mi = plugin.load()
    diffuse = mi.load_dict({"type": "diffuse"})
    return np.asarray(mi.render(scene(diffuse, "directional", size, spp, mesh), spp=spp), dtype=np.float64)[..., 3]


def relative_difference(table: np.ndarray, model: np.ndarray, covered: np.ndarray) -> np.ndarray:
    """(table - model) / model on the pixels the object covers entirely and the model lights; NaN elsewhere."""
    on = (covered > 0.999) & (model > 0)
    return np.where(on, (table - model) / np.where(on, model, 1.0), np.nan)


def comparison(table_bsdf, model_bsdf=None, size: int = 256, spp: int = 64, seed: int = 0, mesh=None) -> dict:
    """The renders of a comparison: {light: {"table": ..., "model": ..., "difference": ...}} (module doc)."""
    covered = coverage(size, spp, mesh)
    out = {}
    for light in LIGHTS:
        table = render(table_bsdf, light, size, spp, seed, mesh)
        out[light] = {"table": table, "covered": covered}
        if model_bsdf is not None:
            model = render(model_bsdf, light, size, spp, seed, mesh)
            out[light].update(model=model, difference=relative_difference(table, model, covered))
    return out


def figure(images: dict, out: Path, labels: tuple[str, str]) -> Path:
    """The picture of :func:`comparison`'s ``images`` at ``out``, in the format of its suffix
    (FORMATS; written under a temporary name and renamed): a row for each light, the table, the
    model (``labels``: their titles) and the relative difference, with colour bars."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    columns = 3 if "model" in images[LIGHTS[0]] else 1
    fig, axes = plt.subplots(len(LIGHTS), columns, figsize=(4.2 * columns, 3.6 * len(LIGHTS)), squeeze=False)
    for row, light in enumerate(LIGHTS):
        shown = images[light]
        top = np.percentile(np.concatenate([shown[k].ravel() for k in ("table", "model") if k in shown]), 99.5)
        for column, (key, title) in enumerate(zip(("table", "model"), labels)):
            if key in shown:
                axis = axes[row, column]
                picture = axis.imshow(shown[key], cmap="gray", vmin=0.0, vmax=top)
                axis.set_title(f"{title}\n({light} light)", fontsize=9)
                fig.colorbar(picture, ax=axis, fraction=0.046, label="radiance")
        if columns == 3:
            difference = shown["difference"]
            span = max(float(np.nanpercentile(np.abs(difference), 99)), 0.01)
            picture = axes[row, 2].imshow(difference, cmap="RdBu_r", vmin=-span, vmax=span)
            axes[row, 2].set_title(f"(table - model) / model\nmean {np.nanmean(difference):+.3f}", fontsize=9)
            fig.colorbar(picture, ax=axes[row, 2], fraction=0.046, label="relative difference")
    for axis in axes.ravel():
        axis.set_xticks([])
        axis.set_yticks([])
    fig.tight_layout()
    try:
        with atomic(out, suffix=out.suffix) as tmp:
            fig.savefig(tmp, dpi=110, format=FORMATS[out.suffix.lower()])
    finally:
        plt.close(fig)
    return out
