"""The model API of docs/conventions.md §8: parameters with declared domains, and the registry.

A model is a class with a ``name``, a tuple of :class:`Param`, a paper ``reference`` and an
``_eval(wi, wo)`` that receives only pairs of directions both above the horizon, as float64
arrays of shape (N, 3). :meth:`BRDFModel.__call__` handles broadcasting and the horizon.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np


@dataclass(frozen=True)
class Param:
    """One model parameter: its domain, default and meaning.

    A numeric parameter lies in [lo, hi] (open ends when ``lo_open`` / ``hi_open``); a choice
    parameter takes one of ``choices``; a ``text`` one, a path. ``default=None`` means the parameter is required
    (unless the model's :meth:`BRDFModel.resolve` derives it from another one), or, with
    ``optional=True``, that it may be left out: a key that only some settings take (a grain
    material's ``eta``), which ``resolve`` then requires, refuses or fills; left out and not
    filled, its value is None.
    """

    name: str
    doc: str
    default: float | str | None = None
    lo: float = -math.inf
    hi: float = math.inf
    lo_open: bool = False
    hi_open: bool = False
    choices: tuple[str, ...] | None = None
    optional: bool = False
    #: a text parameter (a file's path), taken as it is given
    text: bool = False

    def default_text(self) -> str:
        """The default as shown by ``microsim models``."""
        if self.default is not None:
            return f"default {self.default}"
        return "optional" if self.optional else "no default"

    def describe(self) -> str:
        """The accepted values, as shown in error messages and ``microsim models``."""
        if self.choices is not None:
            return "one of " + ", ".join(self.choices)
        if self.text:
            return "a path"
        left = "(" if self.lo_open else "["
        right = ")" if self.hi_open else "]"
        return f"{left}{_fmt(self.lo)}, {_fmt(self.hi)}{right}"

    def check(self, value):
        """Return ``value`` converted to the parameter's type, or raise ValueError naming it."""
        if self.choices is not None:
            if value not in self.choices:
                raise ValueError(f"{self.name} = {value!r} is not allowed; accepted: {self.describe()}")
            return value
        if self.text:
            if not isinstance(value, (str, Path)) or not str(value):
                raise ValueError(f"{self.name} = {value!r} is not a path; accepted: {self.describe()}")
            return str(value)
        if isinstance(value, str):
            try:
                value = float(value)
            except ValueError:
                raise ValueError(f"{self.name} = {value!r} is not a number; accepted: {self.describe()}") from None
        if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
            raise ValueError(f"{self.name} = {value!r} is not a number; accepted: {self.describe()}")
        v = float(value)
        too_low = v < self.lo or (self.lo_open and v == self.lo)
        too_high = v > self.hi or (self.hi_open and v == self.hi)
        if math.isnan(v) or too_low or too_high:
            raise ValueError(f"{self.name} = {value!r} is outside {self.describe()}")
        return v


def _fmt(x: float) -> str:
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return f"{x:g}"


class BRDFModel:
    """Base class of the analytic BRDFs: ``f = model(wi, wo)`` in 1/sr, never f * cos."""

    name: ClassVar[str]
    params: ClassVar[tuple[Param, ...]]
    reference: ClassVar[str]
    #: False for models whose published form is not reciprocal; ``nonreciprocal_reason`` says why.
    reciprocal: ClassVar[bool] = True
    nonreciprocal_reason: ClassVar[str] = ""

    def __init__(self, **values):
        known = {p.name: p for p in self.params}
        for key in values:
            if key not in known:
                raise ValueError(f"unknown parameter {key!r} for model {self.name!r}; accepted: {', '.join(known)}")
        checked = {key: known[key].check(v) for key, v in values.items()}
        checked = self.resolve(checked)
        for p in self.params:
            if p.name not in checked:
                if p.default is None and not p.optional:
                    raise ValueError(f"model {self.name!r} needs parameter {p.name} in {p.describe()}")
                checked[p.name] = p.default
        self.values = checked
        self.setup()

    def resolve(self, values: dict) -> dict:
        """Fill parameters derived from others (aliases such as ``beta`` -> ``beta_x``, ``beta_y``)."""
        return values

    def setup(self) -> None:
        """Precompute whatever depends only on the parameters."""

    def __getattr__(self, key):
        values = self.__dict__.get("values", {})
        if key in values:
            return values[key]
        raise AttributeError(key)

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.values.items())
        return f"{type(self).__name__}({args})"

    def __call__(self, wi, wo) -> np.ndarray:
        """f in 1/sr for directions ``wi``, ``wo`` of shape (..., 3) (broadcast), normalised:
        a model sees unit vectors whatever their length; ValueError for a vector of length 0,
        NaN or infinity. 0 where either direction lies below the horizon."""
        wi, wo = _unit(wi, "wi"), _unit(wo, "wo")
        wi, wo = np.broadcast_arrays(wi, wo)
        shape = wi.shape[:-1]
        wi = wi.reshape(-1, 3)
        wo = wo.reshape(-1, 3)
        out = np.zeros(wi.shape[0])
        above = (wi[:, 2] > 0.0) & (wo[:, 2] > 0.0)
        if above.any():
            out[above] = self._eval(np.ascontiguousarray(wi[above]), np.ascontiguousarray(wo[above]))
        return out.reshape(shape)

    def _eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        raise NotImplementedError


#: a direction whose length is 1 within this is not normalised again
UNIT_TOLERANCE = 1e-12


def _unit(w, name: str) -> np.ndarray:
    w = np.asarray(w, dtype=np.float64)
    if w.shape[-1:] != (3,):
        raise ValueError(f"{name}: directions of shape (..., 3) expected, got {w.shape}")
    length = np.sqrt(np.sum(w * w, axis=-1, keepdims=True))
    if not np.all(np.isfinite(length) & (length > 0.0)):
        raise ValueError(f"{name}: a direction of length 0, NaN or infinity")
    # a unit vector to rounding is taken as it is: a model's values do not move by an ulp
    return w / np.where(np.abs(length - 1.0) > UNIT_TOLERANCE, length, 1.0)


_REGISTRY: dict[str, type[BRDFModel]] = {}


def register(cls: type[BRDFModel]) -> type[BRDFModel]:
    """Class decorator adding a model to the registry under ``cls.name``."""
    _REGISTRY[cls.name] = cls
    return cls


def available() -> list[str]:
    """Names of the registered models."""
    return sorted(_REGISTRY.keys())


def get(name: str) -> type[BRDFModel]:
    """The model class registered as ``name``."""
    try:
        return _REGISTRY[name]
    except KeyError:
        raise ValueError(f"unknown model {name!r}; accepted: {', '.join(available())}") from None


def listing(names=None) -> list[str]:
    """The lines ``microsim models`` prints for the models ``names`` (default: every one): the
    name and reference, a note if not reciprocal, then each parameter, its accepted values, its
    default and its meaning, in aligned columns."""
    names = available() if names is None else list(names)
    classes = [get(name) for name in names]
    rows = [(p.name, p.describe(), p.default_text()) for cls in classes for p in cls.params]
    widths = [max((len(row[k]) for row in rows), default=0) for k in range(3)]
    lines = []
    for name, cls in zip(names, classes):
        lines.append(f"{name}: {cls.reference}")
        if not cls.reciprocal:
            lines.append(f"    (not reciprocal: {cls.nonreciprocal_reason})")
        for p in cls.params:
            cells = (p.name, p.describe(), p.default_text())
            lines.append("    " + "  ".join(f"{c:<{w}}" for c, w in zip(cells, widths)) + f"  {p.doc}")
    return lines


def create(name: str, **values) -> BRDFModel:
    """Build a model by name with parameters by name (conventions §8)."""
    return get(name)(**values)
