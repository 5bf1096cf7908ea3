"""Tables as a user gets them, and whether two tables are the same.

Contract: :func:`write_table` traces a config (validated, or a dictionary as a TOML config
parses) with :func:`microsim.testing.runs.trace` and writes its HDF5 table at ``path``
(``tables.write``: checksums, a temporary name, then the rename), returning the path;
:func:`trace_table` does the same and reads the table back with ``tables.load`` (checked), as
the ``simulate`` fixture of tests/conftest.py does; :func:`write_plane_table` is the table of
the Lambertian plane that model tests judge models on. :func:`same_table` is bit identity of two
tables: every dataset (dtype, shape, bytes) and every attribute, at every level, but for the
provenance that differs between any two runs (``VOLATILE``).
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from microsim import tables
from microsim.testing.runs import trace, validated

#: provenance that differs between any two runs
VOLATILE = {"created_utc", "wall_time_s"}


#: attributes that hold HDF5 object references (the dimension scales')
REFERENCES = ("DIMENSION_LIST", "REFERENCE_LIST")


def write_table(config, path, workers: int = 1, threads: int = 1, **options) -> Path:
    """Trace ``config`` (one albedo) and write its table at ``path``; the path. ``options`` as
    :func:`microsim.testing.runs.trace`'s, and ``overwrite``."""
    overwrite = options.pop("overwrite", False)
    cfg = validated(config)
    return tables.write(path, trace(cfg, workers=workers, threads=threads, **options), cfg, overwrite=overwrite)


def trace_table(config, path, workers: int = 1, threads: int = 1, **options) -> tables.Table:
    """:func:`write_table`, then the table read back (checked) as a user would get it."""
    return tables.load(write_table(config, path, workers, threads, **options))


def write_plane_table(directory, paths: int) -> Path:
    """``directory``/plane.h5: the table of a Lambertian plane (albedo 0.5, exactly 0.5 / pi in
    expectation in every cell; 0 and 50 deg, 200 cells, 64 realizations, seed 9), on which the
    compare and user-model tests judge models; its path."""
    return write_table({
        "scene": {"kind": "plane"},
        "material": {"kind": "lambert", "albedo": 0.5},
        "illumination": {"theta_i_deg": [0.0, 50.0]},
        "sensor": {"cells": 200},
        "run": {"paths": paths, "realizations": 64, "seed": 9},
    }, Path(directory) / "plane.h5")


def same_table(a, b) -> bool:
    """Whether two tables hold the same datasets (dtype, shape and bytes) and the same attributes
    at every level, but for the provenance that differs between any two runs. The dimension
    scales' references (object addresses, which move with anything written before them) are
    compared as the names of the scales each axis is attached to."""
    def contents(path):
        items = {}
        with h5py.File(path, "r") as h5:
            def visit(name, obj):
                attrs = {k: np.asarray(v).tobytes() + str(np.asarray(v).dtype).encode() for k, v in obj.attrs.items()
                         if not (name == "" and k in VOLATILE) and k not in REFERENCES}
                if isinstance(obj, h5py.Dataset):
                    attrs["dimensions"] = [[scale.name for scale in axis.values()] for axis in obj.dims]
                data = (obj.dtype.str, obj.shape, obj[()].tobytes()) if isinstance(obj, h5py.Dataset) else None
                items[name] = (attrs, data)
            visit("", h5)
            h5.visititems(visit)
        return items

    return tables.load(a) is not None and contents(a) == contents(b)
