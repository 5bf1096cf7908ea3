"""HDF5 reference tables (CONVENTIONS 6): atomic writer and a small reader.

Layout (required by CONVENTIONS 6, plus extras marked +):

    attrs: microsim_version, config_toml, created_utc, seed, wall_time_s, name,
           + realizations, paths_per_realization, max_order, backend, backend_fallback
    incidence/theta, incidence/phi                     (n_i,) radians
    sensor/theta_lo, theta_hi, phi_lo, phi_hi          (n_c,) radians
    sensor/direction (n_c, 3), sensor/solid_angle, sensor/projected_solid_angle (n_c,)
    + sensor/ring_counts (n_rings,)
    brdf, brdf_stderr                                  (n_i, n_c) 1/sr
    brdf_order (n_i, 4, n_c), + brdf_order_stderr      orders 1, 2, 3, 4+
    albedo, albedo_stderr (n_i,), + albedo_order, albedo_order_stderr (n_i, 4)
    energy/transmitted, energy/truncated, + energy/absorbed, + */..._stderr (n_i,)
    + energy/balance: albedo + transmitted + truncated + absorbed, 1 in expectation
    paths (n_i,)
    scene/ attrs: resolved scene parameters, largest triangle count;
    + scene/<count> (R,): what each realization generated (spheres, images, triangles, ...)
    + diagnostics/segments, inside_hits, roulette_kills (n_i,)

The file is written under a temporary name in the same directory and renamed when complete.
"""

from __future__ import annotations

import datetime
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from . import __version__
from .frames import direction
from .integrators.records import COUNT_NAMES, ENERGY_NAMES
from .sensor import Sensor


def config_to_toml(config) -> str:
    """The validated config as TOML."""
    return dict_to_toml(config.model_dump(exclude_none=True))


def dict_to_toml(data: dict) -> str:
    """A config dictionary as TOML (two levels: tables of scalars and lists)."""
    lines = []
    for key, value in data.items():
        if not isinstance(value, dict):
            lines.append(f"{key} = {_toml_value(value)}")
    for key, value in data.items():
        if isinstance(value, dict):
            lines.append(f"\n[{key}]")
            lines.extend(f"{k} = {_toml_value(v)}" for k, v in value.items() if v is not None)
    return "\n".join(lines) + "\n"


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return repr(value)


def write(path: str | Path, result, config) -> Path:
    """Write the table of a :class:`microsim.runner.Result` atomically; return the path."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    plan, sensor = result.plan, result.sensor
    try:
        with h5py.File(tmp, "w") as h5:
            h5.attrs["microsim_version"] = __version__
            h5.attrs["config_toml"] = config_to_toml(config)
            h5.attrs["created_utc"] = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
            h5.attrs["seed"] = config.run.seed
            h5.attrs["wall_time_s"] = result.wall_time
            h5.attrs["name"] = config.name or ""
            h5.attrs["realizations"] = plan.realizations
            h5.attrs["paths_per_realization"] = plan.paths_per_realization
            h5.attrs["max_order"] = config.run.max_order
            h5.attrs["backend"] = plan.backend
            h5.attrs["backend_fallback"] = plan.backend_note
            h5["incidence/theta"] = plan.theta_i
            h5["incidence/phi"] = plan.phi_i
            t_lo, t_hi, p_lo, p_hi = sensor.cell_bounds()
            h5["sensor/theta_lo"], h5["sensor/theta_hi"] = t_lo, t_hi
            h5["sensor/phi_lo"], h5["sensor/phi_hi"] = p_lo, p_hi
            h5["sensor/direction"] = sensor.directions()
            h5["sensor/solid_angle"] = sensor.solid_angle()
            h5["sensor/projected_solid_angle"] = sensor.projected_solid_angle()
            h5["sensor/ring_counts"] = sensor.ring_counts
            h5["sensor"].attrs["cells_requested"] = plan.sensor_cells
            brdf = result.brdf
            h5["brdf"] = np.stack([e.mean[-1] for e in brdf])
            h5["brdf_stderr"] = np.stack([e.stderr[-1] for e in brdf])
            h5["brdf_order"] = np.stack([e.mean[:-1] for e in brdf])
            h5["brdf_order_stderr"] = np.stack([e.stderr[:-1] for e in brdf])
            h5["albedo"] = np.array([a.mean[-1] for a in result.albedo])
            h5["albedo_stderr"] = np.array([a.stderr[-1] for a in result.albedo])
            h5["albedo_order"] = np.stack([a.mean[:-1] for a in result.albedo])
            h5["albedo_order_stderr"] = np.stack([a.stderr[:-1] for a in result.albedo])
            for j, name in enumerate((*ENERGY_NAMES, "balance")):
                h5[f"energy/{name}"] = np.array([e.mean[j] for e in result.energy])
                h5[f"energy/{name}_stderr"] = np.array([e.stderr[j] for e in result.energy])
            h5["paths"] = result.paths
            for j, name in enumerate(COUNT_NAMES):
                h5[f"diagnostics/{name}"] = result.counts[:, j]
            scene = h5.create_group("scene")
            for key, value in plan.scene.items():
                scene.attrs[key] = value
            infos = [result.scene_info[r] for r in sorted(result.scene_info)]
            for key in infos[0].keys() - plan.scene.keys():  # what varies between realizations
                scene[key] = np.array([info[key] for info in infos])
            scene.attrs["triangles"] = max(info["triangles"] for info in infos)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


@dataclass
class Table:
    """A table read back: named arrays, provenance attrs and resolved scene parameters."""

    path: Path
    attrs: dict
    scene: dict
    theta_i: np.ndarray
    phi_i: np.ndarray
    sensor: Sensor
    direction: np.ndarray
    projected_solid_angle: np.ndarray
    brdf: np.ndarray
    brdf_stderr: np.ndarray
    brdf_order: np.ndarray
    albedo: np.ndarray
    albedo_stderr: np.ndarray
    transmitted: np.ndarray
    truncated: np.ndarray
    paths: np.ndarray
    arrays: dict = field(default_factory=dict)  # every dataset, by its HDF5 path

    @property
    def wi(self) -> np.ndarray:
        """Incidence directions (n_i, 3)."""
        return direction(self.theta_i, self.phi_i)


def load(path: str | Path) -> Table:
    """Read a table written by :func:`write` (raises OSError / KeyError on a foreign file)."""
    path = Path(path)
    with h5py.File(path, "r") as h5:
        arrays = {}
        h5.visititems(lambda name, obj: arrays.__setitem__(name, obj[()]) if isinstance(obj, h5py.Dataset) else None)
        attrs = {k: _plain(v) for k, v in h5.attrs.items()}
        scene = {k: _plain(v) for k, v in h5["scene"].attrs.items()}
    sensor = Sensor.from_ring_counts(arrays["sensor/ring_counts"])
    return Table(
        path, attrs, scene, arrays["incidence/theta"], arrays["incidence/phi"], sensor,
        arrays["sensor/direction"], arrays["sensor/projected_solid_angle"], arrays["brdf"], arrays["brdf_stderr"],
        arrays["brdf_order"], arrays["albedo"], arrays["albedo_stderr"], arrays["energy/transmitted"],
        arrays["energy/truncated"], arrays["paths"], arrays,
    )


def _plain(value):
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value
