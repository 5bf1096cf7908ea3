"""Analytic BRDF models behind one API (docs/conventions.md §8).

    from microsim import models
    m = models.create("lambert_sphere", albedo=0.8)
    f = m(wi, wo)          # wi, wo: (..., 3) unit vectors; f: (...,) in 1/sr

Every module of this package that defines a model registers it with ``@register``; the
modules are imported here so that ``create`` sees all of them (a plugin registry in the
manner of Mitsuba 3).
"""

import importlib
import pkgutil

from microsim.models.base import BRDFModel, Param, available, create, get, listing, register
from microsim.models.user_models import FunctionModel, UserModelError, as_model, model_class

for _module in pkgutil.iter_modules(__path__):
    importlib.import_module(f"{__name__}.{_module.name}")

__all__ = ["BRDFModel", "FunctionModel", "Param", "UserModelError", "as_model", "available", "create", "get",
           "listing", "model_class", "register"]
