"""Surface materials: one definition per kind, and their exact sampling in numba.

A material kind is defined once, as a config section below (Mitsuba 3's one plugin, one place):
its ``kind`` name and parameters with their accepted ranges (the ``[material]`` / ``[base]``
tables of docs/conventions.md §4, validated by :mod:`microsim.config`), its kind ``code``, its
parameter row (the parameters in the order they are declared, and what the kernels derive from them once,
read by position) and its ``albedo_bound`` (used by generators for default slab depths).
Defining a subclass registers it in ``MATERIALS`` (define kinds here: the config schema is built
from the registry when :mod:`microsim.config` is imported); the config schema, the scene's
material table and the generators all derive from that registry. The definition holds the
kind's kernels too, ``sample`` and ``lobes`` (Python in numba's subset), which the three kernels
below compile for every registered kind, chosen by the kind's code: a new kind is its definition
and nothing else (defined in this module: the switch over the kinds is built at its end). Each
definition is followed by the module constant of its code, for code that names a kind (numba reads module globals, not class attributes). A code that no definition holds
is refused when a material table is built, and the kernels raise rather than fall through. ``tests/test_materials.py`` checks every registered kind's
sampling against its ``evaluate`` and ``pdf`` (a chi-square test on the hemisphere).

The three kernels of one interaction, as pbrt's BxDFs and Mitsuba 3's BSDFs have them, with
``wi`` pointing away from the surface towards where the light came from (``wi = -d``), ``wo``
away from it, ``n`` the outward unit shading normal, all unit 3-tuples:

- :func:`scatter` samples the outgoing direction exactly and returns the factor by which the
  path weight is multiplied (0 ends the path: absorbed), and the fraction cut short;
- :func:`evaluate` is f(wi, wo) |n . wo|, of the lobes that are not a Dirac delta (zero for a
  mirror, a conductor, the smooth interface's reflection): what a point estimate at a direction
  (next-event estimation) adds;
- :func:`pdf` is the density per solid angle with which :func:`scatter` draws ``wo`` outside its
  delta lobes (it integrates to 1 less their probability). Where a kind's weight is a fixed
  function of the directions, it is evaluate / pdf; where it is random (the interfaced body's
  bounces), its mean is.
"""

from __future__ import annotations

import math
import typing
from typing import ClassVar, Literal

import numba
import numpy as np
import pydantic
from pydantic import Field

from microsim.core.schema import Section
from microsim.physics.fresnel import fresnel_conductor, fresnel_dielectric, internal_diffuse_reflectance
from microsim.physics.rng import uniform
from microsim.physics.sampling import from_local, reflect, sample_cosine

#: kind name -> definition, in the order of definition
MATERIALS: dict[str, type["Material"]] = {}

#: most albedos of a Lambertian material traced together (conventions §4)
MAX_ALBEDOS = 16
#: cap on the body bounces of one interfaced_lambert interaction; weight left is truncated
MAX_BODY_BOUNCES = 256
#: cosines at which a conductor's reflectance is probed for its largest value
_CONDUCTOR_PROBES = 101


class Material(Section):
    """A material kind: ``kind``, then its parameters in row order; ``code`` for the tracer;
    ``example``, parameters of one instance, which the tests check the kind's kernels with."""

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
        if not isinstance(getattr(cls, "code", None), int):
            raise TypeError(f"material kind {name!r} needs an integer code (code: ClassVar[int] = ...)")
        if name in MATERIALS or cls.code in codes():
            raise TypeError(f"material kind {name!r} (code {cls.code}) is defined twice")
        if not isinstance(getattr(cls, "example", None), dict):
            raise TypeError(f"material kind {name!r} needs an example (example: ClassVar[dict] = {{parameters}})")
        if "sample" not in cls.__dict__:
            raise TypeError(f"material kind {name!r} needs its sampling (a staticmethod sample(prm, states, i, d, n))")
        if "sample_of_kind" in globals():
            raise TypeError(f"material kind {name!r}: define material kinds in microsim/tracer/materials.py, where the "
                            "kernels' switch over them is built")
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


class Absorber(Material):
    """Absorbs everything."""

    kind: Literal["absorber"]
    code: ClassVar[int] = 0
    example: ClassVar[dict] = {}
    continuous: ClassVar[bool] = False

    def albedo_bound(self) -> float:
        return 0.0

    @staticmethod
    def sample(prm, states, i, d, n):
        return d, 0.0, 0.0


ABSORBER = Absorber.code


class Lambert(Material):
    """Lambertian reflector: cosine sampling about the shading normal, weight x albedo.

    ``albedo`` may be a list (conventions §4, every albedo from one run): the material scatters
    with the largest, and a run tallies each exit for every listed albedo
    (:class:`microsim.core.tally.Tally`)."""

    kind: Literal["lambert"]
    albedo: float | list[float] = Field(description="Lambertian albedo in [0, 1], or a list of them: every "
                                                    "albedo from one run")
    code: ClassVar[int] = 1
    example: ClassVar[dict] = {"albedo": 0.7}

    @pydantic.field_validator("albedo", mode="before")
    @classmethod
    def _one_or_several(cls, value):
        """A number in [0, 1], or a list of 1 to MAX_ALBEDOS distinct ones, the largest above 0
        (the message starts with the field's name; the config adds its section)."""
        accepted = (f"accepted: a number in [0, 1], or a list of 1 to {MAX_ALBEDOS} distinct numbers in [0, 1] "
                    "(the largest above 0)")
        numbers = value if isinstance(value, list) else [value]
        if not numbers or len(numbers) > MAX_ALBEDOS or any(
                isinstance(v, bool) or not isinstance(v, (int, float)) for v in numbers):
            raise ValueError(f"albedo = {value!r}: {accepted}")
        if not all(0.0 <= v <= 1.0 for v in numbers):
            raise ValueError(f"albedo = {value!r}: out of range; {accepted}")
        if isinstance(value, list) and (len(set(numbers)) != len(numbers) or max(numbers) <= 0.0):
            raise ValueError(f"albedo = {value!r}: {accepted}")
        return [float(v) for v in value] if isinstance(value, list) else float(value)

    @property
    def albedos(self) -> tuple[float, ...]:
        """Every albedo of the material, in the order given (one unless ``albedo`` is a list)."""
        return tuple(self.albedo) if isinstance(self.albedo, list) else (self.albedo,)

    def row(self) -> tuple[float, ...]:
        return (max(self.albedos),)

    def albedo_bound(self) -> float:
        return max(self.albedos)

    @staticmethod
    def sample(prm, states, i, d, n):
        return sample_cosine(states, i, n), prm[0], 0.0

    @staticmethod
    def lobes(prm, white, wi, wo, n):
        return (1.0 if white else prm[0]) * (wo[0] * n[0] + wo[1] * n[1] + wo[2] * n[2]) / math.pi


LAMBERT = Lambert.code


class Conductor(Material):
    """Smooth metal with complex index eta + i k: mirror reflection, weight x Fresnel reflectance
    (exact unpolarised form, :mod:`microsim.physics.fresnel`)."""

    kind: Literal["conductor"]
    eta: float = Field(gt=0.0, le=100.0, description="real part of the complex index")
    k: float = Field(ge=0.0, le=100.0, description="imaginary part of the complex index")
    code: ClassVar[int] = 2
    example: ClassVar[dict] = {"eta": 0.2, "k": 3.0}
    delta_lobes: ClassVar[str] = "its mirror reflection (Fresnel-weighted)"
    continuous: ClassVar[bool] = False

    def albedo_bound(self) -> float:
        cosines = np.linspace(0.0, 1.0, _CONDUCTOR_PROBES)
        return float(max(fresnel_conductor(c, self.eta, self.k) for c in cosines))

    @staticmethod
    def sample(prm, states, i, d, n):
        cos_i = -(d[0] * n[0] + d[1] * n[1] + d[2] * n[2])
        return reflect(d, n), fresnel_conductor(cos_i, prm[0], prm[1]), 0.0


CONDUCTOR = Conductor.code


class InterfacedLambert(Material):
    """A smooth dielectric interface (index ratio ``eta``) over a Lambertian body of albedo
    ``albedo``: the flat interfaced Lambertian of Meneveaux et al. 2015, Eq. 8-10.
    Fresnel reflection or refraction at the interface, then Lambertian bounces in the body with
    Fresnel (and total internal) reflection at the interface from inside until the light leaves.
    The whole excursion is one interaction."""

    kind: Literal["interfaced_lambert"]
    albedo: float = Field(ge=0.0, le=1.0, description="albedo K_d of the Lambertian body")
    eta: float = Field(ge=1.0, le=4.0, description="refractive index ratio n_i of the interface")
    code: ClassVar[int] = 3
    example: ClassVar[dict] = {"albedo": 0.7, "eta": 1.5}
    delta_lobes: ClassVar[str] = "the mirror reflection of its smooth interface"

    def albedo_bound(self) -> float:
        f0 = fresnel_dielectric(1.0, self.eta)
        return min(1.0, f0 + (1.0 - f0) * self.albedo)

    def row(self) -> tuple[float, ...]:
        """albedo, eta, and the body's internal diffuse reflectance r_i (Eq. 9-10): the chance that
        light inside is sent back by the interface, which :func:`evaluate` and :func:`pdf` read."""
        return self.albedo, self.eta, internal_diffuse_reflectance(self.eta)

    @classmethod
    def row_size(cls) -> int:
        return 3

    @staticmethod
    def sample(prm, states, i, d, n):
        return _interfaced_lambert(prm[0], prm[1], states, i, d, n)

    @staticmethod
    def lobes(prm, white, wi, wo, n):
        cos_i = wi[0] * n[0] + wi[1] * n[1] + wi[2] * n[2]
        cos_o = wo[0] * n[0] + wo[1] * n[1] + wo[2] * n[2]
        return _interfaced_lambert_body(1.0 if white else prm[0], prm[1], prm[2], cos_i, cos_o) * cos_o


INTERFACED_LAMBERT = InterfacedLambert.code


class Mirror(Material):
    """The perfect conductor (conventions §4): mirror reflection with F = 1 at every angle."""

    kind: Literal["mirror"]
    code: ClassVar[int] = 4
    example: ClassVar[dict] = {}
    delta_lobes: ClassVar[str] = "its mirror reflection"
    continuous: ClassVar[bool] = False

    @staticmethod
    def sample(prm, states, i, d, n):
        return reflect(d, n), 1.0, 0.0


MIRROR = Mirror.code


@numba.njit(cache=True, error_model="numpy", _nrt=False, inline="always")
def scatter(code, prm, states, i, d, n):
    """One interaction: returns (new direction, weight factor, truncated weight fraction).

    ``d`` is the propagation direction of the arriving ray (pointing into the surface), ``n``
    the outward unit shading normal, ``prm`` the material's parameter row. A weight factor of 0
    means the path ends. The kind of code ``code`` samples (its ``sample``).
    """
    return sample_of_kind(code, prm, states, i, d, n)


@numba.njit(cache=True, error_model="numpy", _nrt=False, inline="always")
def evaluate(code, prm, wi, wo, n):
    """f(wi, wo) |n . wo| of the material's lobes that are not a Dirac delta (module doc)."""
    return _continuous_lobes(code, prm, False, wi, wo, n)


@numba.njit(cache=True, error_model="numpy", _nrt=False, inline="always")
def pdf(code, prm, wi, wo, n):
    """Density per solid angle with which :func:`scatter` draws wo outside its delta lobes: the
    sampler draws directions as the white material would send them (the albedo goes into the
    weight), so the pdf is :func:`evaluate` of the kind with albedo 1."""
    return _continuous_lobes(code, prm, True, wi, wo, n)


@numba.njit(cache=True, error_model="numpy", _nrt=False, inline="always")
def _continuous_lobes(code, prm, white, wi, wo, n):
    """f |n . wo| of the lobes that are not a delta (of the white kind, with ``white``): 0 unless
    wi and wo are both above the surface, else the kind's ``lobes``."""
    cos_i = wi[0] * n[0] + wi[1] * n[1] + wi[2] * n[2]
    cos_o = wo[0] * n[0] + wo[1] * n[1] + wo[2] * n[2]
    if cos_i <= 0.0 or cos_o <= 0.0:
        return 0.0
    return lobes_of_kind(code, prm, white, wi, wo, n)


def _switch(method: str, arguments: str):
    """``method`` of every registered kind, chosen by ``code``: a numba function generated from
    the registry (``if code == <kind's code>: return <kind's method>(...)``, the kinds in order
    of definition), which kernels inline, each kind's function inlined in it. A code no kind
    holds raises. Built once every kind of this module is defined (at the end of the module)."""
    namespace, lines = {}, [f"def {method}_of_kind(code, {arguments}):"]
    for j, kind in enumerate(MATERIALS.values()):
        namespace[f"{method}_{j}"] = numba.njit(inline="always", error_model="numpy")(getattr(kind, method))
        lines.append(f"    if code == {kind.code}:\n        return {method}_{j}({arguments})")
    lines.append(f"    raise ValueError('{method}: unknown material kind code')")
    exec("\n".join(lines), namespace)
    return numba.njit(inline="always", error_model="numpy")(namespace[f"{method}_of_kind"])


@numba.njit(cache=True, error_model="numpy", _nrt=False)
def _interfaced_lambert_body(albedo, eta, r_i, cos_i, cos_o):
    """The body term of the flat interfaced Lambertian, Meneveaux et al. 2015, Eq. 8 at
    m = n: K_d T(mu_i) T(mu_o) / (pi eta^2 (1 - K_d r_i)), T = 1 - F. It is what the
    bounce-by-bounce sampler of :func:`_interfaced_lambert` gives on average: light enters with
    chance T(mu_i), each bounce multiplies the weight by K_d and leaves with chance 1 - r_i, in a
    direction of density T cos_t / pi inside, cos_t d(omega_t) = cos_o d(omega_o) / eta^2 out."""
    transmitted = (1.0 - fresnel_dielectric(cos_i, eta)) * (1.0 - fresnel_dielectric(cos_o, eta))
    return albedo * transmitted / (math.pi * eta * eta * (1.0 - albedo * r_i))


@numba.njit(cache=True, error_model="numpy", _nrt=False)
def _interfaced_lambert(albedo, eta, states, i, d, n):
    """Smooth dielectric over a Lambertian body, sampled bounce by bounce (see InterfacedLambert)."""
    cos_i = -(d[0] * n[0] + d[1] * n[1] + d[2] * n[2])
    if uniform(states, i) < fresnel_dielectric(cos_i, eta):
        return reflect(d, n), 1.0, 0.0
    weight = 1.0
    for _ in range(MAX_BODY_BOUNCES):
        weight *= albedo
        if weight == 0.0:
            return d, 0.0, 0.0
        # Lambertian body: cosine-distributed direction towards the interface (inside).
        u1 = uniform(states, i)
        u2 = uniform(states, i)
        sin_t = math.sqrt(u1)
        cos_t = math.sqrt(max(0.0, 1.0 - u1))
        if uniform(states, i) >= fresnel_dielectric(cos_t, 1.0 / eta):
            # Refraction out: Snell, sin_o = eta sin_t (no TIR here since F < 1).
            sin_o = min(eta * sin_t, 1.0)
            cos_o = math.sqrt(max(0.0, 1.0 - sin_o * sin_o))
            phi = 2.0 * math.pi * u2
            return from_local(sin_o * math.cos(phi), sin_o * math.sin(phi), cos_o, n), weight, 0.0
    return d, 0.0, weight


#: the kernels' switches over every kind above (:func:`_switch`); a kind defined later is refused
sample_of_kind = _switch("sample", "prm, states, i, d, n")
lobes_of_kind = _switch("lobes", "prm, white, wi, wo, n")
