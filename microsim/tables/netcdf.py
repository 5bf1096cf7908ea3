"""HDF5 files that netCDF-4 readers open as labelled arrays (xarray with ``engine="h5netcdf"``).

netCDF-4 is HDF5 with two conventions, which h5py writes directly: each dimension is a
*dimension scale* (a dataset named after the dimension, holding its coordinate values) that
the datasets of that dimension attach to, axis by axis; and attributes named as the CF
conventions name them (``units``, ``long_name``, ``ancillary_variables``, ``coordinates``,
``bounds``). A dimension scale in the root group is seen from every group below it. The
tables (:mod:`microsim.tables`) and the regular-grid export (:mod:`microsim.interop.exporters`) both
write through here.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import h5py
import numpy as np

#: units as the table layout writes them -> as UDUNITS (CF) spells them
_CF_UNITS = {"": "1"}


def cf_units(unit: str) -> str:
    """A unit of the table layout in the spelling of CF (UDUNITS): ``"1"`` for a number."""
    return _CF_UNITS.get(unit, unit)


def dimension(group: h5py.Group, name: str, values: np.ndarray, store: Callable | None = None) -> h5py.Dataset:
    """The dimension scale ``name`` of ``group``, holding ``values`` (its coordinate values), made
    by ``store(group, name, values)`` if given (a writer's own way to store a dataset)."""
    if store is None:
        group.create_dataset(name, data=values)
    else:
        store(group, name, values)
    scale = group[name]
    scale.make_scale(name)
    return scale


def attach(dataset: h5py.Dataset, scales) -> None:
    """Attach the dimension scales ``scales`` to the axes of ``dataset``, one for each."""
    if len(scales) != dataset.ndim:
        raise ValueError(f"{dataset.name} has {dataset.ndim} axes, {len(scales)} dimensions given")
    for axis, scale in zip(dataset.dims, scales):
        axis.attach_scale(scale)


def describe(dataset: h5py.Dataset, unit: str, long_name: str, **more: str) -> None:
    """Write the CF attributes of ``dataset``: ``units`` (from the layout's spelling),
    ``long_name`` and any others given (``ancillary_variables``, ``coordinates``, ``bounds``)."""
    dataset.attrs["units"] = cf_units(unit)
    dataset.attrs["long_name"] = long_name
    for key, value in more.items():
        if value:
            dataset.attrs[key] = value


def datasets(group: h5py.Group, prefix: str = "") -> Iterator[tuple[str, h5py.Dataset]]:
    """Every dataset under ``group`` by every path that names it (a dataset hard-linked under
    two names comes twice), dimension scales included."""
    for key in group:
        obj = group[key]
        if isinstance(obj, h5py.Group):
            yield from datasets(obj, f"{prefix}{key}/")
        else:
            yield prefix + key, obj


def address(dataset: h5py.Dataset) -> int:
    """Where the dataset's header lies in its file: the same for every name of one dataset."""
    return h5py.h5o.get_info(dataset.id).addr


def ancillary(names, name: str) -> str:
    """The CF ``ancillary_variables`` of dataset ``name`` among ``names`` (paths in one file): its
    ``_stderr`` and ``_covariance``, where they exist, by their names within its group."""
    leaf = name.rsplit("/", 1)[-1]
    return " ".join(f"{leaf}{suffix}" for suffix in ("_stderr", "_covariance") if f"{name}{suffix}" in names)
