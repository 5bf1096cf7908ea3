"""Every dataset and attribute a table may hold: those :mod:`microsim.core.table_layout` declares,
and those of the estimators registered (each estimator's ``DATASETS`` and ``ATTRIBUTES``)."""

from __future__ import annotations

from microsim.core import table_layout
from microsim.tracer import estimators


def declarations() -> tuple[table_layout.Dataset, ...]:
    """Every dataset a table may hold, with the estimators registered now (a test registers one)."""
    return table_layout.CORE + estimators.datasets() + table_layout.COORDINATES


#: every dataset a table may hold (microsim.core.table_layout): the core ones, each estimator's, then
#: the root's coordinates and dimension scales
DATASETS = declarations()
#: the declaration of each dataset, by HDF5 path
DECLARED = {d.name: d for d in DATASETS}
#: the names of the root's coordinates and dimension scales
COORDINATE_NAMES = {d.name for d in table_layout.COORDINATES}
#: axes of every dataset whose shape is known, by HDF5 path
AXES = {d.name: d.axes for d in DATASETS if d.axes is not None}
#: datasets every table has: brdf_order1_base only where there is a base, so it is checked when present
REQUIRED = tuple(d.name for d in DATASETS if d.required)
#: every attribute a table may hold: the core ones, then each estimator's
ATTRIBUTES = table_layout.ATTRIBUTES + estimators.attributes()
