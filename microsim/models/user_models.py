"""Models a user brings: a plain function or a :class:`BRDFModel` subclass, from Python or, with
``--model module:Name`` or ``--model path.py:Name``, from the command line (docs/conventions.md §8).

A plain function ``f(wi, wo, **params)`` receives float64 arrays of shape (N, 3) of unit
directions both above the horizon (the rest are 0, as for every model) and returns f in 1/sr,
shape (N,) or a number. Its parameters after ``wi, wo`` become the model's, each taking any real
value, with the function's default as its default (a parameter without one must be given);
``microsim fit`` frees them by name. For declared ranges, choices or a paper reference, write a
:class:`BRDFModel` subclass instead (see :mod:`microsim.models.lambert` for the smallest one);
it needs no registration.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import sys
from pathlib import Path

import numpy as np

from microsim.core.files import not_a_file
from microsim.models.base import BRDFModel, Param, get


class UserModelError(ValueError):
    """A user model that cannot be loaded or used; the message is one line."""


class FunctionModel(BRDFModel):
    """A plain function as a model (see the module doc); made by :func:`from_function`."""

    function = None

    def _eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        values = np.asarray(type(self).function(wi, wo, **self.values), dtype=np.float64)
        if values.ndim == 0:
            return np.full(len(wi), float(values))
        if values.shape != (len(wi),):
            raise UserModelError(f"model {self.name} returned values of shape {values.shape} for {len(wi)} pairs of "
                                 f"directions; expected ({len(wi)},)")
        return values


def from_function(function) -> type[BRDFModel]:
    """A model class of the plain function ``function(wi, wo, **params)`` (module doc)."""
    try:
        signature = inspect.signature(function)
    except (TypeError, ValueError):
        raise UserModelError(f"{function!r}: cannot read its parameters; expected f(wi, wo, **params)") from None
    arguments = list(signature.parameters.values())
    positional = [p for p in arguments if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    if len(positional) < 2 or any(p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD) for p in arguments):
        raise UserModelError(f"{_name(function)}: expected a function f(wi, wo, **params) of named parameters")
    params = []
    for p in arguments[2:]:
        default = p.default if p.default is not p.empty else None
        if default is not None and (isinstance(default, bool) or not isinstance(default, (int, float))):
            raise UserModelError(f"{_name(function)}: parameter {p.name} has the default {default!r}; a function's "
                                 "parameters are numbers (a BRDFModel subclass declares choices)")
        params.append(Param(p.name, "a parameter of the user's function (any real value)",
                            None if default is None else float(default)))
    name = _name(function)
    module = getattr(function, "__module__", None) or "?"
    return type(f"FunctionModel_{name}", (FunctionModel,), {
        "name": name, "params": tuple(params), "function": staticmethod(function),
        "reference": f"user function {module}.{getattr(function, '__qualname__', name)}"})


def _name(function) -> str:
    return getattr(function, "__name__", None) or type(function).__name__


def model_class(spec) -> type[BRDFModel]:
    """The model class ``spec`` stands for: a registered model's name, a :class:`BRDFModel`
    subclass, or a plain function (:func:`from_function`)."""
    if isinstance(spec, str):
        return get(spec)
    if isinstance(spec, type) and issubclass(spec, BRDFModel):
        for attribute in ("name", "params", "reference"):
            if not hasattr(spec, attribute):
                raise UserModelError(f"{spec.__name__}: a BRDFModel subclass declares name, params and reference; "
                                     f"{attribute} is missing")
        return spec
    if isinstance(spec, type) or not callable(spec):
        raise UserModelError(f"{spec!r}: expected a model's name, a BRDFModel subclass or a function f(wi, wo, **params)")
    return from_function(spec)


def as_model(spec, **values):
    """A model to evaluate: ``spec`` itself if it is a model already (a :class:`BRDFModel`, or
    any object with ``name``, ``values`` and ``__call__(wi, wo)``), else ``model_class(spec)``
    made with the parameters ``values``."""
    if isinstance(spec, BRDFModel) or (callable(spec) and hasattr(spec, "values") and hasattr(spec, "name")
                                       and not isinstance(spec, type)):
        if values:
            raise UserModelError(f"{spec!r} is a model made already; give its parameters when making it")
        return spec
    return model_class(spec)(**values)


def load(text: str) -> type[BRDFModel]:
    """The model class that ``--model`` names: a registered name, or ``module:Name`` (a module
    importable from the current directory or the installed packages) or ``path.py:Name`` (a
    file); UserModelError (one line) if it cannot be loaded."""
    where, colon, attribute = text.rpartition(":")
    if not colon and (text.endswith(".py") or "/" in text):
        raise UserModelError(f"a model of your own is named path.py:Name, Name the class or function in the file "
                             f"to use (e.g. {text}:MyModel)")
    if not colon:
        return get(text)
    if not where or not attribute.isidentifier():
        raise UserModelError(f"{text!r}: expected a registered model's name, module:Name or path.py:Name")
    module = _load_file(Path(where)) if where.endswith(".py") or "/" in where else _import(where)
    try:
        obj = getattr(module, attribute)
    except AttributeError:
        raise UserModelError(f"{where} has no {attribute}") from None
    return model_class(obj)


def _import(name: str):
    here = str(Path.cwd())
    sys.path.insert(0, here)  # as ``python -m`` would find it
    try:
        return importlib.import_module(name)
    except Exception as err:  # noqa: BLE001 - the user's module: its error in one line
        raise UserModelError(f"importing {name} raised {type(err).__name__}: {_one_line(err)}") from None
    finally:
        if here in sys.path:
            sys.path.remove(here)


def _load_file(path: Path):
    if why := not_a_file(path):
        raise UserModelError(f"{path}: {why}")
    name = f"microsim_user_model_{abs(hash(str(path.resolve())))}"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # as an import does (dataclasses and pickling look their module up)
    try:
        spec.loader.exec_module(module)
    except Exception as err:  # noqa: BLE001 - the user's file: its error in one line
        del sys.modules[name]
        raise UserModelError(f"running {path} raised {type(err).__name__}: {_one_line(err)}") from None
    return module


def _one_line(err: BaseException) -> str:
    return " ".join(str(err).split())[:300] or "(no message)"
