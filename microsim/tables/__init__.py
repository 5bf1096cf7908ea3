"""HDF5 reference tables (conventions §6): atomic writer and a checking reader.

The layout (every attribute and dataset, its axes, unit and meaning) is declared in
:mod:`microsim.core.table_layout` and by each estimator (:data:`DATASETS`,
:mod:`microsim.tables.layout`), from which the loader's checks and the documentation's
table-format page are derived.

Every dataset carries a Fletcher-32 checksum and the file is written in the HDF5 1.10 format,
whose metadata (headers, chunk indexes) carry checksums too, so damaged bytes fail on reading.
:func:`load` (:mod:`microsim.tables.reader`) checks that the datasets are present, readable,
consistently shaped and free of NaN, and raises :class:`TableError` with one line naming the
dataset otherwise; tables written before the checksums still load.

The datasets are labelled for netCDF-4 readers (format 1.1, :mod:`microsim.tables.netcdf`): each
axis is a dimension scale of the root, each dataset has its CF units and long name, and the root
holds the coordinates along the incidences and the cells, so that
``xarray.open_dataset(path, engine="h5netcdf")`` gives named dimensions and coordinates.

The file is written under a temporary name in the same directory and renamed when complete
(:func:`write`, :mod:`microsim.tables.writer`).
"""

from microsim.tables.layout import ATTRIBUTES, DATASETS, DECLARED
from microsim.tables.reader import Table, TableError, load
from microsim.tables.writer import TableExists, config_to_toml, dict_to_toml, write

__all__ = ["ATTRIBUTES", "DATASETS", "DECLARED", "Table", "TableError", "TableExists", "config_to_toml",
           "dict_to_toml", "load", "write"]
