"""What a comparison reads of a table: the rows of an order (``--order``), of the cells, points
or retro rings, checked present and finite (ValueError, one line, naming the dataset), and
which cells have signal.

Metrics are taken over the cells with signal, where the table value exceeds ``SIGNAL_TO_NOISE``
standard errors (a relative error means nothing on a cell the simulation did not resolve). NaN
or infinity, in the table or in the model, is an error, never a cell silently left out.
"""

from __future__ import annotations

import numpy as np

SIGNAL_TO_NOISE = 3.0
#: --order choice -> row of the table's brdf_order (None: all orders, the table's brdf; BASE: the
#: part of order 1 scattered by the base, brdf_order1_base, in tables of scenes with a base)
BASE = "base"
#: orders 1 and 2 together, brdf_orders12 (the f2 of Meneveaux et al. 2015, Sec. 3.3)
ORDERS12 = "orders12"
ORDER_ROWS = {"all": None, "1": 0, "2": 1, "3": 2, "4+": 3, "1+2": ORDERS12, "1-base": BASE}
#: what --points and --retro compare on (PointComparison.on): the word for one, the datasets, the
#: count of those judged, and the config that makes them
ON = {
    "points": ("point", "brdf_points", "points_compared", "[sensor] directions_deg or retro_points_deg"),
    "retro": ("ring", "brdf_retro", "rings_with_signal", "[sensor] retro_rings"),
}


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
        raise ValueError(f"--order 1-base: table {table.path} has no brdf_order1_base and albedo_order1_base "
                         "(its scene has no base, or it was written before they existed)")
    if row == ORDERS12 and not {"brdf_orders12", "albedo_orders12"} <= table.arrays.keys():
        raise ValueError(f"--order 1+2: table {table.path} has no brdf_orders12 and albedo_orders12 "
                         "(it was written before they existed)")
    selected = selected_rows(table, row)
    for name, values in zip(selected[0], selected[1:3]):
        require_finite(values, f"table {table.path}: {name} (order {order})")
    return selected


def extra_selection(table, order: str, on: str):
    """(f, its standard error) of the table's points (``on`` = "points") or retro rings
    ("retro") of ``order``, each (n_i, n), checked present and finite (ValueError, one line)."""
    if order not in ORDER_ROWS:
        raise ValueError(f"order {order!r}; accepted: {', '.join(ORDER_ROWS)}")
    _, name, _, config = ON[on]
    row = ORDER_ROWS[order]
    if row == ORDERS12:
        raise ValueError(f"--order 1+2 with --{on}: the table holds its {name} by order but not the covariance of "
                         "orders 1 and 2, which the error of their sum needs; compare --order 1 and --order 2 apart")
    if row == BASE:
        raise ValueError(f"--order 1-base with --{on}: the table holds no base part of order 1 in {name}")
    dataset = name if row is None else f"{name}_order"
    geometry = ("sensor/points_direction",) if on == "points" else \
        ("sensor/retro_gamma_lo", "sensor/retro_gamma_hi", "sensor/retro_projected_solid_angle")
    missing = [k for k in (dataset, f"{dataset}_stderr", *geometry) if k not in table.arrays]
    if missing:
        raise ValueError(f"--{on}: table {table.path} has no {', '.join(missing)} (its config has no {config}, or it "
                         "was written before they existed)")
    names = (dataset, f"{dataset}_stderr")
    values, stderr = (table.arrays[k] if row is None else table.arrays[k][:, row] for k in names)
    for k, v in zip(names, (values, stderr)):
        require_finite(v, f"table {table.path}: {k} (order {order})", ON[on][0] + "s")
    return values, stderr


def points_covariance(table, order: str) -> np.ndarray | None:
    """(n_i, n_d, n_d) the covariance of the mean of the table's points of ``order`` (checked
    by :func:`extra_selection`), brdf_points_covariance or a row of brdf_points_order_covariance;
    None for a table without it (written before it existed). ValueError (one line) if not finite."""
    row = ORDER_ROWS[order]
    name = "brdf_points_covariance" if row is None else "brdf_points_order_covariance"
    if name not in table.arrays:
        return None
    covariance = table.arrays[name] if row is None else table.arrays[name][:, row]
    require_finite(covariance, f"table {table.path}: {name} (order {order})", "entries")
    return covariance


def repeated_points(directions: np.ndarray) -> np.ndarray:
    """(n_i, n_d) True where a point's direction (n_i, n_d, 3) is an earlier point's of its
    incidence (normal incidence: the retro point at gamma = 0 is the direction [0, 0]): the same
    estimate, compared once."""
    gap = np.linalg.norm(directions[:, :, None] - directions[:, None, :], axis=-1)
    earlier = np.tril(np.ones(gap.shape[1:], bool), -1)
    return np.any((gap < 1e-12) & earlier, axis=2)


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
