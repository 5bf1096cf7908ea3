"""The writer of HDF5 tables (conventions §6): a table written whole under a temporary name,
every dataset with its checksums (:mod:`microsim.tables.checksums`) and its netCDF-4 labels
(:mod:`microsim.tables.netcdf`), then renamed; never over a table that appeared meanwhile
(:class:`TableExists`). Also the config as the TOML a table stores.
"""

from __future__ import annotations

import datetime
import json
import os
import tempfile
from pathlib import Path

import h5py
import numpy as np

from microsim import __version__
from microsim.core import table_layout
from microsim.core.tally import COUNT_NAMES, ENERGY_NAMES
from microsim.tables import netcdf
from microsim.tables.checksums import store
from microsim.tables.layout import COORDINATE_NAMES, declarations
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
    """Write the table of a :class:`microsim.run.reduction.Result` atomically; return the path.

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
            store(h5, "incidence/theta", plan.theta_i)
            store(h5, "incidence/phi", plan.phi_i)
            for name, bounds in zip(("theta_lo", "theta_hi", "phi_lo", "phi_hi"), sensor.cell_bounds()):
                store(h5, f"sensor/{name}", bounds)
            store(h5, "sensor/direction", sensor.directions())
            store(h5, "sensor/solid_angle", sensor.solid_angle())
            store(h5, "sensor/projected_solid_angle", sensor.projected_solid_angle())
            store(h5, "sensor/ring_counts", sensor.ring_counts)
            h5["sensor"].attrs["cells_requested"] = plan.sensor_cells
            for estimator in result.estimators:
                estimator.write(lambda name, data: store(h5, name, data), result.estimates)
                h5.attrs.update(estimator.attributes())
            for j, name in enumerate((*ENERGY_NAMES, "balance")):
                store(h5, f"energy/{name}", np.array([e.mean[j] for e in result.energy]))
                store(h5, f"energy/{name}_stderr", np.array([e.stderr[j] for e in result.energy]))
            store(h5, "paths", result.paths)
            for j, name in enumerate(COUNT_NAMES):
                store(h5, f"diagnostics/{name}", result.counts[:, j])
            scene = h5.create_group("scene")
            for key, value in plan.scene.items():
                scene.attrs[key] = value
            infos = [result.scene_info[r] for r in sorted(result.scene_info)]
            for key in infos[0].keys() - plan.scene.keys():  # what varies between realizations
                store(scene, key, np.array([info[key] for info in infos]))
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
    store(h5, "theta_o", theta_o)
    store(h5, "phi_o", phi_o)
    store(h5, "theta_o_bounds", np.stack([t_lo, t_hi], axis=1))
    store(h5, "phi_o_bounds", np.stack([p_lo, p_hi], axis=1))


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
    scales = {axis: netcdf.dimension(h5, axis, _scale_values(axis, size), store) for axis, size in sizes.items()}
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
