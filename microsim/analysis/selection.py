"""What a comparison reads of a table: the rows of an order (``--order``), of the cells or of what
another judge compares (:mod:`microsim.analysis.judges`), checked present and finite (ValueError, one line, naming the dataset), and
which cells have signal.

Metrics are taken over the cells with signal, where the table value exceeds ``SIGNAL_TO_NOISE``
standard errors (a relative error means nothing on a cell the simulation did not resolve). NaN
or infinity, in the table or in the model, is an error, never a cell silently left out.
"""

from __future__ import annotations

import numpy as np

from microsim.core.table_layout import may_lack

SIGNAL_TO_NOISE = 3.0
#: --order choice -> row of the table's brdf_order (None: all orders, the table's brdf; BASE: the
#: part of order 1 scattered by the base, brdf_order1_base, in tables of scenes with a base)
BASE = "base"
#: orders 1 and 2 together, brdf_orders12 (the f2 of Meneveaux et al. 2015, Sec. 3.3)
ORDERS12 = "orders12"
ORDER_ROWS = {"all": None, "1": 0, "2": 1, "3": 2, "4+": 3, "1+2": ORDERS12, "1-base": BASE}
def signal_or_refusal(table, sim, stderr, order: str) -> np.ndarray:
    """:func:`with_signal` of the table's ``order``; ValueError (one line) if no cell has signal."""
    signal = with_signal(sim, stderr)
    if not signal.any():
        raise ValueError(f"table {table.path}: no cell of order {order} has signal (a value above "
                         f"{SIGNAL_TO_NOISE:g} standard errors): nothing to compare; trace more paths or use fewer cells")
    return signal


def with_signal(sim, stderr) -> np.ndarray:
    """The cells where the table has signal: value above SIGNAL_TO_NOISE standard errors."""
    return (stderr > 0) & (sim > SIGNAL_TO_NOISE * stderr)


def selection(table, order: str):
    """(dataset names, f_C, its standard error, albedo, its standard error) of the table's
    ``order`` (a key of ORDER_ROWS), checked present and finite (ValueError, one line)."""
    if order not in ORDER_ROWS:
        raise ValueError(f"order {order!r}; accepted: {', '.join(ORDER_ROWS)}")
    row = ORDER_ROWS[order]
    if row == BASE and not {"brdf_order1_base", "albedo_order1_base"} <= table.arrays.keys():
        why = predates(table, "brdf_order1_base") or "its scene has no base"
        raise ValueError(f"--order 1-base: table {table.path} has no brdf_order1_base and albedo_order1_base ({why})")
    if row == ORDERS12 and not {"brdf_orders12", "albedo_orders12"} <= table.arrays.keys():
        why = predates(table, "brdf_orders12") or f"a table of format {table.format_version} holds them: it is damaged"
        raise ValueError(f"--order 1+2: table {table.path} has no brdf_orders12 and albedo_orders12 ({why})")
    selected = selected_rows(table, row)
    for name, values in zip(selected[0], selected[1:3]):
        require_finite(values, f"table {table.path}: {name} (order {order})")
    return selected


def extra_selection(table, order: str, judge):
    """(f, its standard error) of the table's values that ``judge`` (a
    :class:`microsim.analysis.judges.Judge` other than the cells') compares, of ``order``, each
    (n_i, n), checked present and finite (ValueError, one line). Orders 1 and 2 together and the
    base's part of order 1 are refused: the table holds neither for them, and the error of the
    sum of two order rows needs their covariance."""
    if order not in ORDER_ROWS:
        raise ValueError(f"order {order!r}; accepted: {', '.join(ORDER_ROWS)}")
    on, name = judge.on, judge.dataset
    row = ORDER_ROWS[order]
    if row == ORDERS12:
        raise ValueError(f"--order 1+2 with --{on}: the table holds its {name} by order but not the covariance of "
                         "orders 1 and 2, which the error of their sum needs; compare --order 1 and --order 2 apart")
    if row == BASE:
        raise ValueError(f"--order 1-base with --{on}: the table holds no base part of order 1 in {name}")
    dataset = name if row is None else f"{name}_order"
    missing = [k for k in (dataset, f"{dataset}_stderr", *judge.geometry) if k not in table.arrays]
    if missing:
        why = next(filter(None, (predates(table, k) for k in missing)), f"its config has no {judge.keys}")
        raise ValueError(f"--{on}: table {table.path} has no {', '.join(missing)} ({why})")
    names = (dataset, f"{dataset}_stderr")
    values, stderr = (table.arrays[k] if row is None else table.arrays[k][:, row] for k in names)
    for k, v in zip(names, (values, stderr)):
        require_finite(v, f"table {table.path}: {k} (order {order})", judge.unit + "s")
    return values, stderr


def predates(table, name: str) -> str:
    """Why the table lacks dataset ``name`` if its format predates it ("written in format 1.0,
    before it existed"), else "" (the table of its format holds it where its ``when`` holds:
    :func:`microsim.core.table_layout.may_lack`)."""
    from microsim.tables import DECLARED  # the estimators' declarations: not for the CLI's help

    declared = DECLARED.get(name)
    if declared is None or not may_lack(table.format_version, declared):
        return ""
    return f"written in format {table.format_version}, before it existed"


def selected_rows(table, row):
    """(dataset names, f_C, its standard error, albedo, its standard error) of an ORDER_ROWS row."""
    a = table.arrays
    if row is None:
        return ("brdf", "brdf_stderr"), table.brdf, table.brdf_stderr, table.albedo, table.albedo_stderr
    if row in (BASE, ORDERS12):
        name = "order1_base" if row == BASE else "orders12"
        return ((f"brdf_{name}", f"brdf_{name}_stderr"), a[f"brdf_{name}"], a[f"brdf_{name}_stderr"],
                a[f"albedo_{name}"], a[f"albedo_{name}_stderr"])
    return (("brdf_order", "brdf_order_stderr"), table.brdf_order[:, row, :], a["brdf_order_stderr"][:, row, :],
            a["albedo_order"][:, row], a["albedo_order_stderr"][:, row])


def config_degrees(radians: float) -> float:
    """Degrees as a config gives them: 30.0, not the 29.999999999999996 of a round trip."""
    return round(float(np.degrees(radians)), 9)


def require_finite(values: np.ndarray, what: str, unit: str = "cells") -> None:
    """Raise ValueError naming ``what`` if any cell (or other ``unit``) is NaN or infinite."""
    if bad := np.count_nonzero(~np.isfinite(values)):
        raise ValueError(f"{what} is NaN or infinite in {bad} of {values.size} {unit}")
