"""Sweeps (docs/conventions.md §4): a ``[sweep]`` table turns one config into many.

    [sweep]
    "scene.volume_fraction" = [0.1, 0.3]
    "material.albedo" = [0.5, 0.7, 0.9]
    mode = "grid"        # every combination (the default), or "zip": the i-th values together

Each point is the config with its dotted keys set (:func:`microsim.config.set_dotted`) and is
validated as any config is, before anything is traced: a bad key or value in any point is one
line naming the point. ``microsim run`` writes each point's ordinary table into the ``--out``
directory, named from its values (:attr:`Point.name`), and an index (``index.csv``) of every
point: its values, table, status and albedo per incidence.
"""

from __future__ import annotations

import copy
import csv
import itertools
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

from microsim import config as config_module
from microsim.config import ConfigError

MODES = ("grid", "zip")
#: the index a sweep writes beside its tables
INDEX = "index.csv"


@dataclass
class Point:
    """One point of a sweep: its dotted keys and values, and its validated config."""

    values: dict
    config: object

    @property
    def name(self) -> str:
        """File stem from the values: the last part of each key (the whole key where two share
        it) and its value, e.g. volume_fraction0.1_albedo0.5."""
        lasts = [key.rsplit(".", 1)[-1] for key in self.values]
        parts = []
        for key, last in zip(self.values, lasts):
            label = last if lasts.count(last) == 1 else key
            parts.append(f"{label}{_text(self.values[key])}")
        return re.sub(r"[^A-Za-z0-9.+=_-]", "-", "_".join(parts))


def points(data: dict) -> list[Point] | None:
    """The points of the config dictionary ``data`` (read with :func:`microsim.config.read`), or
    None if it has no ``[sweep]``. Raises ConfigError (one line) for a bad sweep or point."""
    if "sweep" not in data:
        return None
    sweep = dict(data["sweep"]) if isinstance(data["sweep"], dict) else None
    if sweep is None:
        raise ConfigError("sweep: must be a table of dotted keys and their lists of values")
    mode = sweep.pop("mode", "grid")
    if mode not in MODES:
        raise ConfigError(f"sweep.mode = {mode!r}; accepted: {', '.join(MODES)}")
    if not sweep:
        raise ConfigError("sweep: give at least one dotted key with a list of values")
    for key, values in sweep.items():
        if not isinstance(values, list) or not values:
            raise ConfigError(f"sweep.{key}: expected a non-empty list of values")
        if key.split(".")[0] in ("sweep", "name") or "." not in key:
            raise ConfigError(f"sweep.{key}: expected a dotted key inside a section, like scene.volume_fraction")
    keys = list(sweep)
    if mode == "zip":
        lengths = {len(v) for v in sweep.values()}
        if len(lengths) > 1:
            raise ConfigError(f"sweep: mode zip needs lists of one length; got {', '.join(f'{k}: {len(v)}' for k, v in sweep.items())}")
        combos = list(zip(*sweep.values()))
    else:
        combos = list(itertools.product(*sweep.values()))
    base = {k: v for k, v in data.items() if k != "sweep"}
    out = []
    for combo in combos:
        values = dict(zip(keys, combo))
        point_data = copy.deepcopy(base)
        label = ", ".join(f"{k} = {_text(v)}" for k, v in values.items())
        try:
            for key, value in values.items():
                config_module.set_dotted(point_data, key, value)
            point = Point(values, config_module.validate(point_data))
        except ConfigError as err:
            raise ConfigError(f"sweep point {label}: {err}") from None
        if isinstance(getattr(point.config.material, "albedo", None), list):
            raise ConfigError(f"sweep point {label}: material.albedo lists are not swept; sweep material.albedo instead")
        out.append(point)
    names = [p.name for p in out]
    if len(set(names)) != len(names):
        raise ConfigError("sweep: two points have the same values (a value is listed twice)")
    return out


def index_albedos(row: dict, theta_i, albedos) -> None:
    """Mark a point's row of the index done, with its albedo at each theta_i (radians)."""
    row["status"] = "done"
    for t, a in zip(theta_i, albedos):
        row[f"albedo_theta{math.degrees(t):g}"] = f"{a:.6g}"


def write_index(directory: Path, rows) -> None:
    """The sweep's INDEX in ``directory``, one row a point (values, table, status, albedos),
    replaced atomically."""
    columns = list(dict.fromkeys(key for row in rows for key in row))
    tmp = directory / f".{INDEX}.tmp"
    with open(tmp, "w", newline="") as handle:
        writer = csv.DictWriter(handle, columns, restval="")
        writer.writeheader()
        writer.writerows(rows)
    os.replace(tmp, directory / INDEX)


def keys() -> list[config_module.Key]:
    """The keys of ``[sweep]``, as :func:`microsim.config.keys` documents a run's."""
    return [config_module.Key("sweep.mode", "", ", ".join(map(repr, MODES)), repr(MODES[0]),
                              "grid: every combination of the listed values; zip: the i-th values together"),
            config_module.Key('sweep."section.key"', "", "a non-empty list of values of that key", "",
                              "a dotted key of the config and the values it takes: one run (one table) a point")]


def _text(value) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)
