"""A material kind's definition (Mitsuba 3's one plugin, one file): the base class every kind
of this package derives from, and the registry.

A kind is one module of :mod:`microsim.tracer.materials` with one :class:`Material` subclass:
its ``kind`` name and parameters with their accepted ranges (the ``[material]`` / ``[base]``
tables of docs/conventions.md §4, validated by :mod:`microsim.config`), its parameter row (the
parameters in the order they are declared, and what the kernels derive from them once, read by
position), its ``albedo_bound`` (used by generators for default slab depths) and its kernels
``sample`` and ``lobes`` (Python in numba's subset). Defining the subclass registers it in
``MATERIALS`` and gives it its ``code``, the next integer (the order of registration is the
order in which the package imports its kinds); the module names the code in a constant for code
that names a kind (numba reads module globals, not class attributes). The config schema, the
scene's material table, the generators and the kernels' switch (:mod:`.kernels`) all derive from
the registry. ``tests/test_materials.py`` checks every registered kind's sampling against its
``evaluate`` and ``pdf`` (a chi-square test on the hemisphere).
"""

from __future__ import annotations

import typing
from typing import ClassVar

from microsim.core.schema import Section

#: kind name -> definition, in the order of registration (each kind's code is its position)
MATERIALS: dict[str, type["Material"]] = {}
#: most albedos of a Lambertian material traced together (conventions §4)
MAX_ALBEDOS = 16
#: whether the kernels' switch over the kinds is built (:mod:`.kernels`): a kind defined after is refused
SEALED = [False]

class Material(Section):
    """A material kind: ``kind``, then its parameters in row order; ``code`` for the tracer;
    ``example``, parameters of one instance, which the tests check the kind's kernels with."""

    #: the tracer's code of the kind, given at registration (its position in MATERIALS)
    code: ClassVar[int]
    example: ClassVar[dict]
    #: what the kind reflects by Dirac delta lobes ("" if nothing): next-event estimation does not
    #: see it (:func:`evaluate` leaves it out), the exit binning does
    delta_lobes: ClassVar[str] = ""
    #: whether the kind scatters into a continuum of directions (its ``lobes`` are not all 0)
    continuous: ClassVar[bool] = True

    @classmethod
    def __pydantic_init_subclass__(cls, **kwargs):
        super().__pydantic_init_subclass__(**kwargs)
        name = typing.get_args(cls.model_fields["kind"].annotation)[0]
        if name in MATERIALS:
            raise TypeError(f"material kind {name!r} is defined twice")
        if not isinstance(getattr(cls, "example", None), dict):
            raise TypeError(f"material kind {name!r} needs an example (example: ClassVar[dict] = {{parameters}})")
        if "sample" not in cls.__dict__:
            raise TypeError(f"material kind {name!r} needs its sampling (a staticmethod sample(prm, states, i, d, n))")
        if SEALED[0]:
            raise TypeError(f"material kind {name!r}: a kind is a module that microsim/tracer/materials/__init__.py "
                            "imports before the kernels' switch over the kinds is built")
        cls.code = len(MATERIALS)
        MATERIALS[name] = cls

    @classmethod
    def example_instance(cls) -> "Material":
        """The kind made with its ``example`` parameters."""
        kind = typing.get_args(cls.model_fields["kind"].annotation)[0]
        return cls.model_validate({"kind": kind, **cls.example})

    @classmethod
    def parameter_names(cls) -> tuple[str, ...]:
        return tuple(name for name in cls.model_fields if name != "kind")

    def row(self) -> tuple[float, ...]:
        """The parameters in declaration order: the material's row of a scene's material table."""
        return tuple(float(getattr(self, name)) for name in self.parameter_names())

    @classmethod
    def row_size(cls) -> int:
        """Entries of the kind's row: its parameters, and what the kernels derive from them."""
        return len(cls.parameter_names())

    def albedo_bound(self) -> float:
        """An upper estimate of the weight factor of one interaction (for default slab depths):
        1, all of it, unless the kind knows better."""
        return 1.0

    # The kind's kernels: Python in numba's subset, compiled into :func:`scatter`, :func:`evaluate`
    # and :func:`pdf` for every registered kind (module doc). ``prm`` is the kind's row.

    @staticmethod
    def sample(prm, states, i, d, n):
        """Light arriving along d on the outward normal n: (wo, weight factor, fraction cut),
        wo drawn with the random stream of row i of ``states`` (module doc, :func:`scatter`)."""
        raise NotImplementedError

    @staticmethod
    def lobes(prm, white, wi, wo, n):
        """f(wi, wo) |n . wo| of the lobes that are not a delta, for wi and wo both above the
        surface; with ``white``, of the kind whose diffuse albedo is 1 (what its sampler draws
        directions by: :func:`pdf`). A kind of delta lobes only keeps this 0."""
        return 0.0


def codes() -> set[int]:
    """Kind codes of every defined material."""
    return {m.code for m in MATERIALS.values()}


def row_length() -> int:
    """Width of a material table row: the longest row of any kind."""
    return max(m.row_size() for m in MATERIALS.values())
