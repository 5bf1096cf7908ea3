"""Surface materials, one kind a module (Mitsuba 3's one plugin, one file): :mod:`.base` holds the
definition every kind derives from and the registry; the kinds are registered in the order of
KINDS, which gives them their codes (0, 1, ...); :mod:`.kernels`, imported after them, compiles
the tracer's ``scatter``, ``evaluate`` and ``pdf`` over every kind. A new kind is a module named
in KINDS.
"""

import importlib

#: the kind modules, in the order of registration (their codes)
KINDS = ("absorber", "lambert", "conductor", "interfaced_lambert", "mirror")
for _kind in KINDS:
    importlib.import_module(f"{__name__}.{_kind}")

from microsim.tracer.materials.absorber import ABSORBER, Absorber
from microsim.tracer.materials.base import MATERIALS, MAX_ALBEDOS, Material, codes, row_length
from microsim.tracer.materials.conductor import CONDUCTOR, Conductor
from microsim.tracer.materials.interfaced_lambert import INTERFACED_LAMBERT, MAX_BODY_BOUNCES, InterfacedLambert
from microsim.tracer.materials.kernels import evaluate, pdf, scatter
from microsim.tracer.materials.lambert import LAMBERT, Lambert
from microsim.tracer.materials.mirror import MIRROR, Mirror

__all__ = ["ABSORBER", "CONDUCTOR", "INTERFACED_LAMBERT", "KINDS", "LAMBERT", "MATERIALS", "MAX_ALBEDOS",
           "MAX_BODY_BOUNCES", "MIRROR", "Absorber", "Conductor", "InterfacedLambert", "Lambert", "Material", "Mirror",
           "codes", "evaluate", "pdf", "row_length", "scatter"]
