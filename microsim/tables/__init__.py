"""HDF5 reference tables (conventions §6): atomic writer and a checking reader.

The layout (every attribute and dataset, its axes, unit and meaning) is declared in
:mod:`microsim.core.table_layout` and by each estimator (:data:`DATASETS`), from which the loader's
checks below and the documentation's table-format page are derived.

Every dataset carries a Fletcher-32 checksum and the file is written in the HDF5 1.10 format,
whose metadata (headers, chunk indexes) carry checksums too, so damaged bytes fail on reading.
:func:`load` checks that the datasets are present, readable, consistently shaped and free of NaN,
and raises :class:`TableError` with one line naming the dataset otherwise; tables written before
the checksums still load.

The datasets are labelled for netCDF-4 readers (format 1.1, :mod:`microsim.tables.netcdf`): each
axis is a dimension scale of the root, each dataset has its CF units and long name, and the root
holds the coordinates along the incidences and the cells, so that
``xarray.open_dataset(path, engine="h5netcdf")`` gives named dimensions and coordinates.

The file is written under a temporary name in the same directory and renamed when complete.
"""

from __future__ import annotations

import datetime
import hashlib
import json
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from microsim import __version__
from microsim.core import table_layout
from microsim.core.frames import direction
from microsim.core.orders import ORDERS
from microsim.core.tally import COUNT_NAMES, ENERGY_NAMES
from microsim.tables import netcdf
from microsim.tracer import estimators
from microsim.tracer.sensor import Sensor


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


class TableExists(FileExistsError):
    """The table's path was taken (by another run, or a user) while this one traced; the new table
    was kept under another name, ``kept``."""

    def __init__(self, path: Path, kept: Path):
        super().__init__(f"{path} appeared while the run traced; this run's table was kept as {kept} "
                         f"(pass --force to overwrite)")
        self.kept = kept


def write(path: str | Path, result, config, overwrite: bool = False) -> Path:
    """Write the table of a :class:`microsim.run.runner.Result` atomically; return the path.

    Without ``overwrite``, an existing file at ``path`` is never replaced, even one that appeared
    while the run traced: raises :class:`TableExists` and leaves both files as they were. The
    table of one albedo of a run of several stores the config of that albedo."""
    path = Path(path)
    if result.albedo_value is not None:
        config = config.model_copy(update={"material": config.material.model_copy(update={"albedo": result.albedo_value})})
    handle, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(handle)
    tmp = Path(name)
    umask = os.umask(0)
    os.umask(umask)
    tmp.chmod(0o666 & ~umask)  # mkstemp makes it private; a table is as readable as any new file
    plan, sensor = result.plan, result.sensor
    try:
        with h5py.File(tmp, "w", libver=("v110", "v110")) as h5:
            h5.attrs["format_version"] = table_layout.FORMAT_VERSION
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
            if plan.albedos:  # one table of a run of several albedos (conventions §4)
                h5.attrs["albedos_traced_together"] = np.array(plan.albedos)
                h5.attrs["albedo_traced"] = max(plan.albedos)
            _store(h5, "incidence/theta", plan.theta_i)
            _store(h5, "incidence/phi", plan.phi_i)
            for name, bounds in zip(("theta_lo", "theta_hi", "phi_lo", "phi_hi"), sensor.cell_bounds()):
                _store(h5, f"sensor/{name}", bounds)
            _store(h5, "sensor/direction", sensor.directions())
            _store(h5, "sensor/solid_angle", sensor.solid_angle())
            _store(h5, "sensor/projected_solid_angle", sensor.projected_solid_angle())
            _store(h5, "sensor/ring_counts", sensor.ring_counts)
            h5["sensor"].attrs["cells_requested"] = plan.sensor_cells
            for estimator in result.estimators:
                estimator.write(lambda name, data: _store(h5, name, data), result.estimates)
                h5.attrs.update(estimator.attributes())
            for j, name in enumerate((*ENERGY_NAMES, "balance")):
                _store(h5, f"energy/{name}", np.array([e.mean[j] for e in result.energy]))
                _store(h5, f"energy/{name}_stderr", np.array([e.stderr[j] for e in result.energy]))
            _store(h5, "paths", result.paths)
            for j, name in enumerate(COUNT_NAMES):
                _store(h5, f"diagnostics/{name}", result.counts[:, j])
            scene = h5.create_group("scene")
            for key, value in plan.scene.items():
                scene.attrs[key] = value
            infos = [result.scene_info[r] for r in sorted(result.scene_info)]
            for key in infos[0].keys() - plan.scene.keys():  # what varies between realizations
                _store(scene, key, np.array([info[key] for info in infos]))
            scene.attrs["triangles"] = max(info["triangles"] for info in infos)
            _store_coordinates(h5, sensor)
            _label(h5)
        _publish(tmp, path, overwrite)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


def _store_coordinates(h5: h5py.File, sensor: Sensor) -> None:
    """The root's coordinates (table_layout.COORDINATES): the incidences' angles under a second
    name, the cells' centres and bounds."""
    h5["theta_i"], h5["phi_i"] = h5["incidence/theta"], h5["incidence/phi"]
    theta_o, phi_o = sensor.cell_centres()
    t_lo, t_hi, p_lo, p_hi = sensor.cell_bounds()
    _store(h5, "theta_o", theta_o)
    _store(h5, "phi_o", phi_o)
    _store(h5, "theta_o_bounds", np.stack([t_lo, t_hi], axis=1))
    _store(h5, "phi_o_bounds", np.stack([p_lo, p_hi], axis=1))


def _label(h5: h5py.File) -> None:
    """Label every dataset for netCDF-4 readers (:mod:`microsim.tables.netcdf`): the dimension scales of
    its declared axes, its units and long name, its standard error as an ancillary variable, and
    at the root its coordinates. A dataset no one declared (an estimator registered without its
    ``DATASETS``) gets axes of its own, ``<name>_0``, ... and no unit: the table is written all
    the same."""
    declared = {d.name: d for d in declarations()}
    found = dict(netcdf.datasets(h5))
    axes = {name: _axes_of(name, dataset.ndim, declared) for name, dataset in found.items()}
    sizes = {}
    for name, dataset in found.items():
        for axis, size in zip(axes[name], dataset.shape):
            sizes.setdefault(axis, size)
    scales = {axis: netcdf.dimension(h5, axis, _scale_values(axis, size), _store) for axis, size in sizes.items()}
    for axis, scale in scales.items():
        netcdf.describe(scale, "", declared[axis].doc if axis in declared else f"the index along axis {axis}")
    done = set()
    for name, dataset in found.items():
        if netcdf.address(dataset) in done:  # a second name of a dataset (theta_i)
            continue
        done.add(netcdf.address(dataset))
        netcdf.attach(dataset, [scales[axis] for axis in axes[name]])
        declaration = _declaration(name, declared)
        at_root = "/" not in name and name not in COORDINATE_NAMES
        coordinates = " ".join(c for axis, c in (("incidences", "theta_i phi_i"), ("cells", "theta_o phi_o"))
                               if at_root and axis in axes[name])
        netcdf.describe(dataset, declaration.unit if declaration else "",
                        declaration.doc if declaration else "not declared",
                        ancillary_variables=netcdf.ancillary(found, name), coordinates=coordinates,
                        bounds=f"{name}_bounds" if f"{name}_bounds" in found else "")


def declarations() -> tuple[table_layout.Dataset, ...]:
    """Every dataset a table may hold, with the estimators registered now (a test registers one)."""
    return table_layout.CORE + estimators.datasets() + table_layout.COORDINATES


def _declaration(name: str, declared: dict) -> table_layout.Dataset | None:
    """The declaration of dataset ``name``: its own, for what a scene counts ``scene/<count>``,
    else None."""
    if name in declared:
        return declared[name]
    return declared["scene/<count>"] if name.startswith("scene/") else None


def _axes_of(name: str, ndim: int, declared: dict) -> tuple[str, ...]:
    """The axes of dataset ``name`` as declared; a scene's count of more axes than declared, the
    realizations then axes of its own (``<leaf>_1``, ...); an undeclared dataset, axes of its own."""
    declaration = _declaration(name, declared)
    if declaration is not None and len(declaration.axes) == ndim:
        return declaration.axes
    leaf = name.rsplit("/", 1)[-1]
    own = tuple(f"{leaf}_{k}" for k in range(ndim))
    return ("realizations", *own[1:]) if declaration is not None else own


def _scale_values(axis: str, size: int) -> np.ndarray:
    """What the dimension scale of ``axis`` holds (table_layout.SCALES)."""
    return np.arange(1, size + 1) if axis == "orders" else np.arange(size)


def _publish(tmp: Path, path: Path, overwrite: bool) -> None:
    """Rename the finished ``tmp`` to ``path``; without ``overwrite``, atomically refuse an existing
    ``path`` (a hard link fails if the name exists; where links are not supported, a check just
    before the rename narrows the window instead) and keep the table under a fresh name."""
    if overwrite:
        os.replace(tmp, path)
        return
    try:
        os.link(tmp, path)
    except FileExistsError:
        raise TableExists(path, _keep(tmp, path)) from None
    except OSError:  # a file system without hard links
        if path.exists():
            raise TableExists(path, _keep(tmp, path)) from None
        os.replace(tmp, path)
        return
    tmp.unlink()


def _keep(tmp: Path, path: Path) -> Path:
    """Link ``tmp`` to the first free name <stem>.<pid>[.<k>]<suffix> beside ``path``."""
    for k in range(1000):
        kept = path.with_name(f"{path.stem}.{os.getpid()}{f'.{k}' if k else ''}{path.suffix}")
        try:
            os.link(tmp, kept)
            return kept
        except FileExistsError:
            continue
    raise FileExistsError(f"no free name beside {path} to keep the table")


def _store(group, name: str, data) -> None:
    """One dataset with a Fletcher-32 checksum (h5py stores it chunked, as the checksum needs) and
    the SHA-256 of its bytes in an attribute: Fletcher-32 passes a chunk zeroed with its checksum,
    the digest (in the object header, which the 1.10 format checksums) does not."""
    data = np.asarray(data)
    dataset = group.create_dataset(name, data=data, fletcher32=True)
    dataset.attrs["sha256"] = _digest(data)


def _digest(data: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(data).tobytes()).hexdigest()


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


class TableError(ValueError):
    """A damaged, incomplete or inconsistent table; the message is one line naming the dataset."""


#: every dataset a table may hold (microsim.core.table_layout): the core ones, each estimator's, then
#: the root's coordinates and dimension scales
DATASETS = declarations()
#: the declaration of each dataset, by HDF5 path
DECLARED = {d.name: d for d in DATASETS}
COORDINATE_NAMES = {d.name for d in table_layout.COORDINATES}
#: axes of every dataset whose shape is known, by HDF5 path
AXES = {d.name: d.axes for d in DATASETS if d.axes is not None}
#: datasets every table has: brdf_order1_base only where there is a base, so it is checked when present
REQUIRED = tuple(d.name for d in DATASETS if d.required)
#: every attribute a table may hold: the core ones, then each estimator's
ATTRIBUTES = table_layout.ATTRIBUTES + estimators.attributes()


def load(path: str | Path) -> Table:
    """Read and check a table written by :func:`write`.

    Raises OSError when the file is missing or not HDF5, :class:`TableError` when it is damaged
    (a checksum mismatch), incomplete, inconsistently shaped or holds NaN.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    with h5py.File(path, "r") as h5:
        try:
            arrays = _read_datasets(h5)
            attrs = {k: _plain(v) for k, v in h5.attrs.items()}
            scene = {k: _plain(v) for k, v in h5["scene"].attrs.items()} if "scene" in h5 else None
        except (OSError, RuntimeError) as err:  # damaged metadata above the datasets: links, attributes
            raise TableError(f"HDF5 structure is damaged ({err})") from None
    if "microsim_version" not in attrs or "config_toml" not in attrs:
        raise TableError("not a microsim table (no microsim_version and config_toml attributes)")
    version = str(attrs.get("format_version", "1.0"))
    if version.split(".")[0] != table_layout.FORMAT_VERSION.split(".")[0]:
        raise TableError(f"format_version {version}: this microsim reads tables of format "
                         f"{table_layout.FORMAT_VERSION.split('.')[0]}.x")
    if scene is None:
        raise TableError("scene is missing")
    _check(arrays, attrs.get("realizations"))
    sensor = Sensor.from_ring_counts(arrays["sensor/ring_counts"])
    _check_values(arrays, sensor)
    return Table(
        path, attrs, scene, arrays["incidence/theta"], arrays["incidence/phi"], sensor,
        arrays["sensor/direction"], arrays["sensor/projected_solid_angle"], arrays["brdf"], arrays["brdf_stderr"],
        arrays["brdf_order"], arrays["albedo"], arrays["albedo_stderr"], arrays["energy/transmitted"],
        arrays["energy/truncated"], arrays["paths"], arrays,
    )


def _read_datasets(group: h5py.Group, prefix: str = "") -> dict:
    """Every dataset under ``group`` by its HDF5 path; one that cannot be opened or read raises TableError."""
    arrays = {}
    for key in group:
        name = prefix + key
        try:
            obj = group[key]
        except KeyError as err:  # how h5py reports a header it cannot read (a metadata checksum mismatch)
            raise TableError(f"{name} is damaged ({err.args[0]})") from None
        if isinstance(obj, h5py.Group):
            arrays.update(_read_datasets(obj, f"{name}/"))
        elif isinstance(obj, h5py.Dataset):
            try:
                arrays[name] = obj[()]
                digest = obj.attrs.get("sha256")
            except OSError as err:  # how h5py reports a failed Fletcher-32 check: a failed filter
                reason = "checksum mismatch" if obj.fletcher32 and "filter" in str(err) else str(err)
                raise TableError(f"dataset {name} is damaged ({reason})") from None
            if digest is not None and _plain(digest) != _digest(arrays[name]):
                raise TableError(f"dataset {name} is damaged (SHA-256 mismatch)")
    return arrays


def _check(arrays: dict, realizations) -> None:
    """Raise TableError unless ``arrays`` hold every required dataset, consistently shaped (the
    scene's datasets: one row for each of the ``realizations``), without NaN."""
    missing = [name for name in REQUIRED if name not in arrays]
    if missing:
        raise TableError(f"{', '.join(missing)} {'is' if len(missing) == 1 else 'are'} missing")
    for name in REQUIRED:
        if arrays[name].dtype.kind not in "biuf":
            raise TableError(f"{name} holds {arrays[name].dtype} values, expected numbers")
    counts, theta = arrays["sensor/ring_counts"], arrays["incidence/theta"]
    if counts.ndim != 1 or counts.size == 0 or np.any(counts < 1):
        raise TableError(f"sensor/ring_counts holds {counts.tolist()}, expected cell counts >= 1, one per ring")
    if theta.ndim != 1:
        raise TableError(f"incidence/theta has shape {theta.shape}, expected (incidences,)")
    rings = arrays["sensor/retro_gamma_lo"].size if "sensor/retro_gamma_lo" in arrays else 0
    points = arrays["sensor/points_kind"].size if "sensor/points_kind" in arrays else 0
    sizes = {"incidences": theta.size, "cells": int(counts.sum()), "orders": ORDERS, "xyz": 3, "retro_rings": rings,
             "points": points, "other_points": points, "rings": counts.size, "bounds": 2, "realizations": realizations}
    for name, axes in AXES.items():
        if name not in arrays:
            continue
        shape = arrays[name].shape
        expected = tuple(sizes.get(axis, n) for axis, n in zip(axes, shape))  # masking directions: free
        if len(shape) != len(axes) or shape != expected:
            shown = tuple(sizes.get(axis, "any") for axis in axes)
            raise TableError(f"{name} has shape {shape}, expected {shown} ({' x '.join(axes)})")
    for name, values in arrays.items():
        if values.dtype.kind == "f":
            if nan := np.count_nonzero(np.isnan(values)):
                raise TableError(f"{name} holds NaN in {nan} of {values.size} values")
            if infinite := np.count_nonzero(np.isinf(values)):
                raise TableError(f"{name} holds infinity in {infinite} of {values.size} values")


#: how far stored cell bounds may lie from those the ring counts give (radians: numpy's SIMD
#: kernels move them by a few ulps from one CPU to another)
BOUNDS_TOLERANCE = 1e-9


def _check_values(arrays: dict, sensor: Sensor) -> None:
    """Raise TableError unless the values are those a run can give (a table edited by another
    program): incidences above the horizon, errors, BRDF values, albedos and path counts not
    negative, and cell bounds that are the ones of the sensor the ring counts describe (the
    sensor compare and fit average over is rebuilt from the counts)."""
    theta = arrays["incidence/theta"]
    if np.any((theta < 0) | (theta >= np.pi / 2)):
        bad = theta[(theta < 0) | (theta >= np.pi / 2)][0]
        raise TableError(f"incidence/theta holds {bad:g} rad ({np.degrees(bad):g} deg), outside [0, pi/2)")
    phi = arrays["incidence/phi"]
    if np.any(np.abs(phi) > 2 * np.pi):
        raise TableError(f"incidence/phi holds {phi[np.abs(phi) > 2 * np.pi][0]:g} rad, outside [-2 pi, 2 pi]")
    for name, values in arrays.items():
        if values.dtype.kind in "iuf" and _never_negative(name) and (negative := np.count_nonzero(values < 0)):
            raise TableError(f"{name} holds a negative value in {negative} of {values.size} values")
    if np.any(arrays["paths"] < 1):
        raise TableError("paths holds a count below 1")
    for name, bounds in zip(("theta_lo", "theta_hi", "phi_lo", "phi_hi"), sensor.cell_bounds()):
        stored = arrays[f"sensor/{name}"]
        if not np.allclose(stored, bounds, rtol=0.0, atol=BOUNDS_TOLERANCE):
            cell = int(np.argmax(np.abs(stored - bounds)))
            raise TableError(f"sensor/{name} disagrees with sensor/ring_counts (cell {cell}: {stored[cell]:.9g} rad "
                             f"stored, {bounds[cell]:.9g} rad from the ring counts)")


def _never_negative(name: str) -> bool:
    """Datasets a run never makes negative: standard errors, BRDF values, albedos, energies
    (the balance included), the sensor's solid angles and the event counts (not covariances)."""
    leaf = name.rsplit("/", 1)[-1]
    if name.endswith("_covariance"):
        return False
    return (name.endswith("_stderr") or leaf.startswith(("brdf", "albedo")) or name.startswith("energy/")
            or leaf in ("solid_angle", "projected_solid_angle") or name.startswith("diagnostics/"))


def _plain(value):
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value
