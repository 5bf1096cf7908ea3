"""The checking reader of HDF5 tables (conventions §6).

:func:`load` checks that the datasets are present, readable (their checksums:
:mod:`microsim.tables.checksums`), consistently shaped and free of NaN, and that their values are
those a run can give; otherwise it raises :class:`TableError` with one line naming the dataset.
Tables written before the checksums still load.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from microsim.core import table_layout
from microsim.core.frames import direction
from microsim.core.orders import ORDERS
from microsim.tables import checksums
from microsim.tables.layout import AXES, REQUIRED
from microsim.tracer.sensor import Sensor


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

    @property
    def format_version(self) -> str:
        """The layout's version the table was written in (:func:`format_version`)."""
        return format_version(self.attrs)


def format_version(attrs) -> str:
    """The layout's version of a table of root attributes ``attrs`` (1.0 for a table without the attribute)."""
    return str(attrs.get("format_version", "1.0"))


class TableError(ValueError):
    """A damaged, incomplete or inconsistent table; the message is one line naming the dataset."""


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
    version = format_version(attrs)
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
            if digest is not None and _plain(digest) != checksums.digest(arrays[name]):
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
    sizes = {"incidences": theta.size, "cells": int(counts.sum()), "orders": ORDERS, "xyz": 3, "rings": counts.size,
             "bounds": 2, "realizations": realizations}
    declared = [(name, AXES[name]) for name in AXES if name in arrays]
    for name, axes in sorted(declared, key=lambda item: len(item[1])):  # an axis's own datasets first
        shape = arrays[name].shape
        for axis, n in zip(axes, shape):  # an estimator's axis (its points, its rings): the first that has it
            sizes.setdefault(table_layout.SAME_LENGTH.get(axis, axis), n)
        lengths = [sizes[table_layout.SAME_LENGTH.get(axis, axis)] for axis in axes[:len(shape)]]
        if len(shape) != len(axes) or shape != tuple(lengths):
            shown = tuple(sizes.get(table_layout.SAME_LENGTH.get(axis, axis), "any") for axis in axes)
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
