"""Run configs (docs/conventions.md §4): TOML in, validated pydantic models out, one-line errors.

Every section is a strict pydantic model: unknown keys, wrong types and out-of-range values
are rejected. Scene kinds come from the generator registry (``geometry.SCENES``) and material
kinds from the material registry (``microsim.tracer.materials.MATERIALS``), each with its own model,
selected by ``kind``. :func:`load` turns any problem into a :class:`ConfigError`
whose message is one line naming the key and the accepted values.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import tomllib
import types
import typing
from pathlib import Path
from typing import Annotated, Literal, Union

import annotated_types
import pydantic
from pydantic import BaseModel, Field

from microsim import geometry
from microsim.config import full_brdf
from microsim.config.full_brdf import MAX_INCIDENCES
from microsim.core.choices import BACKEND_CHOICES
from microsim.core.schema import Section
from microsim.tracer.materials import MATERIALS
from microsim.tracer.sensor import MAX_POINTS


def _is_number(value) -> bool:
    """A real number, of Python or numpy, not a bool."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


class ConfigError(ValueError):
    """A bad config: the message is one line naming the key and what is accepted."""


AnyMaterial = Annotated[Union[tuple(MATERIALS.values())], Field(discriminator="kind")]
Scene = Annotated[Union[tuple(g.Config for g in geometry.SCENES.values())], Field(discriminator="kind")]


class Illumination(Section):
    """Incidences: ``theta_i_deg`` a list; ``phi_i_deg`` one azimuth for all, or a list as long as
    ``theta_i_deg`` (one incidence per pair)."""

    theta_i_deg: list[Annotated[float, Field(ge=0.0, le=89.9)]] = Field(
        min_length=1, max_length=MAX_INCIDENCES, description="polar angle of each incidence, deg (one table row each); "
        "made by incidences where it is given")
    phi_i_deg: list[Annotated[float, Field(ge=-360.0, le=360.0)]] = Field(
        [0.0], min_length=1, max_length=MAX_INCIDENCES,
        description="one azimuth for all incidences, or one per theta_i_deg")
    incidences: int | None = Field(
        None, ge=2, le=MAX_INCIDENCES, description="a full BRDF: this many polar angles at the centres of the "
        "sensor's rings, from normal incidence to the last ring, those between keeping the widest gap in "
        "cos theta_i least, instead of theta_i_deg (microsim.config.full_brdf; what `--model table` and `microsim export` "
        "need: cos theta_i gaps of 0.25 at most, 6 incidences or more; fewer are refused before tracing)")
    azimuths: int | None = Field(None, ge=1, le=64, description="with incidences: each polar angle but 0 at this "
                                 "many azimuths 360 j / azimuths (an anisotropic scene's full BRDF; 1 if left out)")

    @pydantic.field_validator("theta_i_deg", mode="before")
    @classmethod
    def _scalar_to_list(cls, v):
        return [v] if isinstance(v, (int, float)) and not isinstance(v, bool) else v

    @pydantic.field_validator("phi_i_deg", mode="before")
    @classmethod
    def _one_azimuth(cls, v):
        """One number is kept as a list of one: the azimuth of every incidence."""
        return [v] if isinstance(v, (int, float)) and not isinstance(v, bool) else v

    @pydantic.model_validator(mode="after")
    def _paired(self):
        if len(self.phi_i_deg) not in (1, len(self.theta_i_deg)):
            raise ValueError(f"illumination.phi_i_deg: a list of {len(self.phi_i_deg)} azimuths for "
                             f"{len(self.theta_i_deg)} theta_i_deg; accepted: one number, or a list as long as "
                             "theta_i_deg")
        return self

    def azimuths_deg(self) -> list[float]:
        """phi_i of every incidence, paired with ``theta_i_deg``."""
        if len(self.phi_i_deg) == 1:
            return self.phi_i_deg * len(self.theta_i_deg)
        return list(self.phi_i_deg)


class SensorSection(Section):
    cells: int = Field(3240, ge=1, le=1_000_000, description="cells of the equal-solid-angle sensor, approximately "
                       "(the table stores the actual cells)")
    retro_rings: int = Field(0, ge=0, le=100_000, description="rings about the retro direction, tallied "
                             "apart from the cells (0: none); see microsim.tracer.sensor")
    retro_max_deg: float = Field(10.0, gt=0.0, le=90.0, description="phase angle the retro rings reach, deg")
    directions_deg: list[list[float]] = Field(
        [], description="exact directions [theta_o, phi_o] (phi_o the relative azimuth phi_o - phi_i; the "
                        "cells' azimuths are the scene's), deg, theta_o in [0, 90), "
                        f"phi_o in [-360, 360]: f there by next-event estimation (at most {MAX_POINTS} points "
                        "with retro_points_deg)")
    retro_points_deg: list[float] = Field(
        [], description="phase angles gamma in [0, 90) deg from the retro direction, towards the normal in the "
                        "plane of incidence: f there by next-event estimation")

    @pydantic.field_validator("directions_deg", mode="before")
    @classmethod
    def _directions(cls, value):
        """A list of [theta_o, phi_o] pairs of numbers, theta_o in [0, 90), phi_o in [-360, 360]."""
        accepted = "accepted: a list of [theta_o, phi_o] pairs, theta_o in [0, 90) and phi_o in [-360, 360] deg"
        value = value.tolist() if hasattr(value, "tolist") else value  # a numpy array from Python
        if not isinstance(value, (list, tuple)):
            raise ValueError(f"directions_deg = {excerpt(value)}: not a list; {accepted}")
        for k, pair in enumerate(value):
            if not isinstance(pair, (list, tuple)) or len(pair) != 2 or not all(map(_is_number, pair)):
                raise ValueError(f"directions_deg[{k}] = {excerpt(pair)}: not a pair of numbers; {accepted}")
            theta, phi = pair
            if not 0.0 <= theta < 90.0:
                where = "below the horizon" if theta >= 90.0 else "out of range"
                raise ValueError(f"directions_deg[{k}] = {excerpt(pair)}: theta_o {where}; {accepted}")
            if not -360.0 <= phi <= 360.0:
                raise ValueError(f"directions_deg[{k}] = {excerpt(pair)}: phi_o out of range; {accepted}")
        return [[float(theta), float(phi)] for theta, phi in value]

    @pydantic.field_validator("retro_points_deg", mode="before")
    @classmethod
    def _retro_points(cls, value):
        """A list of numbers in [0, 90)."""
        accepted = "accepted: a list of phase angles in [0, 90) deg"
        value = value.tolist() if hasattr(value, "tolist") else value  # a numpy array from Python
        if not isinstance(value, (list, tuple)) or not all(map(_is_number, value)):
            raise ValueError(f"retro_points_deg = {excerpt(value)}: not a list of numbers; {accepted}")
        for k, gamma in enumerate(value):
            if not 0.0 <= gamma < 90.0:
                raise ValueError(f"retro_points_deg[{k}] = {excerpt(gamma)}: out of range; {accepted}")
        return [float(gamma) for gamma in value]

    @pydantic.model_validator(mode="after")
    def _at_most_max_points(self):
        count = len(self.directions_deg) + len(self.retro_points_deg)
        if count > MAX_POINTS:
            # the key of the longer list: the one to shorten
            key = "directions_deg" if len(self.directions_deg) >= len(self.retro_points_deg) else "retro_points_deg"
            raise ValueError(f"sensor.{key}: {len(self.directions_deg):,} directions_deg and "
                             f"{len(self.retro_points_deg):,} retro_points_deg, {count:,} points; accepted: at "
                             f"most {MAX_POINTS} points together (each costs a shadow ray per scattering event)")
        return self

    @property
    def n_points(self) -> int:
        """Points of next-event estimation asked for (directions and retro points)."""
        return len(self.directions_deg) + len(self.retro_points_deg)


class Run(Section):
    paths: int = Field(ge=1, le=10**12, description="paths per incidence, over all realizations")
    realizations: int = Field(32, ge=2, le=100_000, description="independent geometry samples = batches of the standard errors")
    seed: int = Field(1, ge=0, le=2**63 - 1, description="random seed: of the geometry of each realization and of "
                      "the paths of each unit")
    max_order: int = Field(0, ge=0, le=1_000_000, description="the last scattering order traced (0: unlimited, "
                           "Russian roulette; 1: single scattering)")
    backend: Literal[BACKEND_CHOICES] = Field(
        "auto", description="how Embree is called: direct (numba, native spheres, threads) or embreex; "
                            "auto = direct where its binding loads")

    @pydantic.model_validator(mode="after")
    def _a_path_for_every_realization(self):
        """Every realization traces paths / realizations of them, rounded up: with fewer paths
        than realizations, the run would trace more paths than asked, one scene for each."""
        if self.paths < self.realizations:
            raise ValueError(f"run.paths = {self.paths:,}: fewer than run.realizations = {self.realizations:,}; "
                             "accepted: at least one path a realization (run.paths >= run.realizations)")
        return self


class Config(Section):
    name: str | None = Field(None, max_length=200, pattern=r"^[^\x00-\x1f\x7f]*$",
                             description="a label stored in the table (printable characters); not a file name")
    scene: Scene
    material: AnyMaterial
    base: AnyMaterial | None = None
    illumination: Illumination
    sensor: SensorSection = SensorSection()
    run: Run

    @pydantic.model_validator(mode="before")
    @classmethod
    def _full_brdf_incidences(cls, data):
        """illumination.incidences made into theta_i_deg and phi_i_deg (microsim.config.full_brdf)."""
        return full_brdf.expand(data, SensorSection.model_fields["cells"].default)

    @pydantic.model_validator(mode="after")
    def _points_see_light(self):
        """Next-event estimation sees the lobes that are not a Dirac delta: a scene whose every
        material reflects by delta lobes or absorbs has nothing to show it."""
        materials = [self.material] + ([self.base] if self.base is not None else [])
        if self.sensor.n_points and not any(m.continuous for m in materials):
            kinds = ", ".join(f"{name}.kind = {m.kind!r}" for name, m in zip(("material", "base"), materials))
            key = "sensor.directions_deg" if self.sensor.directions_deg else "sensor.retro_points_deg"
            raise ValueError(f"{key}: next-event estimation sees no light in this scene ({kinds}: delta lobes "
                             "or absorption only); accepted: a scene with a lambert or interfaced_lambert "
                             "material, or no points (the cells see delta lobes)")
        return self


def load(path: str | Path, overrides: dict | None = None) -> Config:
    """Read and validate a TOML config; ``overrides`` replace keys as {"run.paths": 1000} (dotted
    keys of any depth). A config with a ``[sweep]`` table is many configs: see
    :mod:`microsim.app.sweep`."""
    data = read(path, overrides)
    if "sweep" in data:
        raise ConfigError("sweep: this config is a sweep of several runs; `microsim run` traces it into a "
                          "directory (microsim.app.sweep)")
    return validate(data)


def read(path: str | Path, overrides: dict | None = None) -> dict:
    """The TOML of ``path`` as a dictionary, with ``overrides`` applied (:func:`set_dotted`);
    ConfigError (one line) if it cannot be read or parsed."""
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as err:
        raise ConfigError(f"config file {str(path)!r} is not UTF-8 text (byte 0x{err.object[err.start]:02x} at "
                          f"offset {err.start}); TOML files are UTF-8") from None
    except FileNotFoundError:
        raise ConfigError(f"config file {str(path)!r} not found") from None
    except OSError as err:
        raise ConfigError(f"config file {str(path)!r} cannot be read: {err.strerror}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"config file {str(path)!r} is not valid TOML: {err}") from None
    for dotted, value in (overrides or {}).items():
        set_dotted(data, dotted, value)
    return data


def set_dotted(data: dict, dotted: str, value) -> None:
    """data["a"]["b"]...["z"] = value for the key "a.b...z" (any depth), making the tables on the
    way; ConfigError if the key is empty or passes through a value that is not a table."""
    parts = dotted.split(".")
    if not all(parts):
        raise ConfigError(f"{dotted!r}: not a dotted key (like scene.volume_fraction)")
    node = data
    for depth, part in enumerate(parts[:-1]):
        node = node.setdefault(part, {})
        if not isinstance(node, dict):
            raise ConfigError(f"{dotted}: {'.'.join(parts[:depth + 1])} is a value, not a table")
    node[parts[-1]] = value


def validate(data: dict) -> Config:
    """Validate a config dictionary (as parsed from TOML)."""
    try:
        config = Config.model_validate(data)
    except pydantic.ValidationError as err:  # an unknown key first: it is often the misspelt missing one
        errors = err.errors()
        first = next((e for e in errors if e["type"] == "extra_forbidden"), errors[0])
        raise ConfigError(describe_error(first, data)) from None
    try:
        geometry.SCENES[config.scene.kind].check(config)
    except ValueError as err:
        raise ConfigError(str(err)) from None
    return config


@dataclasses.dataclass(frozen=True)
class Key:
    """One config key as the reference documents it: its dotted name, the scene or material kinds
    that have it ("" for every one), what it accepts, its default, its meaning."""

    name: str
    kinds: str
    accepted: str
    default: str
    doc: str


def keys() -> list[Key]:
    """Every key of a run's config, read from the schema (the same source as validation); the
    keys of ``[sweep]``: :func:`microsim.app.sweep.keys`. A key that only some kinds of a section
    have names them, and its accepted values, default and meaning are given per kind where the
    kinds differ."""
    out = [_key("name", Config, "name")]
    for section, model in (("scene", Scene), ("material", AnyMaterial), ("base", AnyMaterial),
                           ("illumination", Illumination), ("sensor", SensorSection), ("run", Run)):
        members = _union_members(model) or [model]
        names = dict.fromkeys(name for member in members for name in member.model_fields)
        for name in names:
            holders = [m for m in members if name in m.model_fields]
            if name == "kind":  # every member's tag
                out.append(_key(f"{section}.kind", holders[0], name, members))
                continue
            each = [_key(f"{section}.{name}", m, name) for m in holders]
            tags = [_kind_of(m) for m in holders] if len(members) > 1 else [""]
            out.append(dataclasses.replace(
                each[0], kinds="" if len(holders) == len(members) else ", ".join(tags),
                accepted=_per_kind(tags, [k.accepted for k in each]),
                default=_per_kind(tags, [k.default for k in each]), doc=_per_kind(tags, [k.doc for k in each])))
    return out


def _per_kind(tags: list[str], values: list[str]) -> str:
    """The one value, or each kind's where they differ."""
    return values[0] if len(set(values)) == 1 else "; ".join(f"{tag}: {value}" for tag, value in zip(tags, values))


def _key(dotted: str, model, name: str, members=None) -> Key:
    info = model.model_fields[name]
    if members is not None:  # the kind: every member's tag
        accepted = ", ".join(repr(_kind_of(m)) for m in members)
    else:
        accepted = _accepted(_field(model, name), {"loc": (name,)}).removeprefix("accepted: ")
    if info.is_required():
        default = "required"
    else:
        default = repr(info.default) if info.default is not None else "unset"
    doc = info.description or ("the kind: which of the kinds named under accepted" if name == "kind" else "")
    return Key(dotted, "", accepted, default, doc)


def describe_error(error: dict, data: dict) -> str:
    """One line for one pydantic error: the dotted key, the value given, what is accepted."""
    node, owner, keys, value = Config, None, [], data
    for part in error["loc"]:
        if isinstance(part, int):
            keys[-1] += f"[{part}]"
            value = value[part] if isinstance(value, list) and part < len(value) else None
            continue
        member = _tagged_member(node, part)
        if member is not None:  # a discriminator tag in the error path: step into that kind
            node = member
            continue
        keys.append(part)
        value = value.get(part) if isinstance(value, dict) else None
        owner, node = node, _field(node, part)
    key = ".".join(keys) or "config"
    kind = error["type"]
    if kind == "value_error":  # a rule of a section's own validator: its message is the line
        message = str(error["ctx"]["error"])
        if len(keys) > 1 and message.startswith((keys[-1] + " ", keys[-1] + "[")):  # a field's rule: add its section
            return ".".join(keys[:-1]) + "." + message
        return message
    shown = f" = {excerpt(value)}" if value is not None and not isinstance(value, dict) else ""
    if kind == "extra_forbidden":
        return f"{key}: unknown key; allowed keys here: {', '.join(owner.model_fields)}"
    if kind == "missing":
        return f"{key}: missing; {_accepted(node, error)}"
    if kind in ("union_tag_invalid", "union_tag_not_found"):
        tags = ", ".join(repr(_kind_of(m)) for m in _union_members(node))
        given = value.get("kind") if isinstance(value, dict) else None
        if given is None:
            return f"{key}.kind: missing; accepted: {tags}"
        return f"{key}.kind = {given!r}: unknown kind; accepted: {tags}"
    if kind == "string_pattern_mismatch":  # the only pattern: no control characters
        return f"{key}{shown}: contains a control character; accepted: printable text"
    problem = "out of range" if kind in _RANGE_ERRORS else error["msg"].lower()
    if kind in ("too_short", "too_long") and isinstance(value, list):
        problem = f"{len(value):,} items, out of range"
    return f"{key}{shown}: {problem}; {_accepted(node, error)}"


#: characters of a value a message quotes
EXCERPT = 60


def excerpt(value) -> str:
    """``repr(value)``, or its first items and length if that is longer than EXCERPT characters."""
    text = repr(value)
    if len(text) <= EXCERPT:
        return text
    if isinstance(value, list):
        head = ", ".join(excerpt(item) for item in value[:3])
        return f"[{head}, ... ({len(value):,} items)]"
    return text[:EXCERPT - 3] + "..."


_RANGE_ERRORS = {"greater_than", "greater_than_equal", "less_than", "less_than_equal", "too_short", "too_long"}


def _field(model, name):
    """What field ``name`` of a model class holds: a model class, a tagged union, a list or a FieldInfo."""
    if not (isinstance(model, type) and issubclass(model, BaseModel)) or name not in model.model_fields:
        return None
    info = model.model_fields[name]
    inner = _unwrap(info.annotation)
    if (isinstance(inner, type) and issubclass(inner, BaseModel)) or _union_members(inner):
        return inner
    if typing.get_origin(inner) is list:
        (item,) = typing.get_args(inner)
        return _ItemField(info, item)
    return info


class _ItemField:
    """A list field: its own constraints, and the constraints of each item."""

    def __init__(self, info, item):
        self.info, self.item = info, item


def _unwrap(annotation):
    """The type inside Optional[...] and Annotated[...]."""
    args = typing.get_args(annotation)
    if typing.get_origin(annotation) in (Union, types.UnionType):
        non_none = [a for a in args if a is not type(None)]
        if len(non_none) == 1:
            return _unwrap(non_none[0])
    if typing.get_origin(annotation) is Annotated:
        return _unwrap(args[0])
    return annotation


def _union_members(annotation) -> list:
    """The section models of a union discriminated by ``kind`` (else an empty list)."""
    if typing.get_origin(annotation) is Annotated:
        annotation = typing.get_args(annotation)[0]
    if typing.get_origin(annotation) is Union:
        members = [a for a in typing.get_args(annotation) if isinstance(a, type) and issubclass(a, BaseModel)]
        return members if all("kind" in m.model_fields for m in members) else []
    return []


def _kind_of(member) -> str:
    return typing.get_args(member.model_fields["kind"].annotation)[0]


def _tagged_member(union, tag):
    for member in _union_members(union):
        if _kind_of(member) == tag:
            return member
    return None


def _accepted(field, error) -> str:
    """What a field accepts, from its type and its numeric bounds."""
    if isinstance(field, _ItemField):
        if isinstance(error["loc"][-1], int):
            return "accepted: a number in " + _range(typing.get_args(field.item)[1:])
        return "accepted: a list of numbers, each in " + _range(typing.get_args(field.item)[1:]) + _length(field.info)
    if isinstance(field, type) and issubclass(field, BaseModel):
        return "accepted: a table with keys " + ", ".join(field.model_fields)
    if _union_members(field):
        return "accepted: a table with a kind among " + ", ".join(_kind_of(m) for m in _union_members(field))
    if field is None:
        return ""
    kind = _unwrap(field.annotation)
    if kind is float or kind is int:
        what = "an integer" if kind is int else "a number"
        return f"accepted: {what} in {_range(field.metadata)}"
    if kind is str:
        return "accepted: a string"
    if typing.get_origin(kind) is Literal:
        return "accepted: " + ", ".join(map(repr, typing.get_args(kind)))
    return f"accepted: {getattr(kind, '__name__', kind)}"


def _range(metadata) -> str:
    """Interval notation of the numeric bounds in a field's metadata."""
    lo, hi, lo_open, hi_open = -math.inf, math.inf, False, False
    for m in metadata:
        if isinstance(m, annotated_types.Gt):
            lo, lo_open = m.gt, True
        elif isinstance(m, annotated_types.Ge):
            lo, lo_open = m.ge, False
        elif isinstance(m, annotated_types.Lt):
            hi, hi_open = m.lt, True
        elif isinstance(m, annotated_types.Le):
            hi, hi_open = m.le, False
        elif hasattr(m, "metadata"):
            return _range(m.metadata)
    left = "(" if lo_open or math.isinf(lo) else "["
    right = ")" if hi_open or math.isinf(hi) else "]"
    return f"{left}{lo:g}, {hi:g}{right}"


def _length(info) -> str:
    """How many items a list field takes: " (1 to 256 of them)", " (at least 1)"."""
    lo = next((m.min_length for m in info.metadata if isinstance(m, annotated_types.MinLen)), None)
    hi = next((m.max_length for m in info.metadata if isinstance(m, annotated_types.MaxLen)), None)
    if lo is not None and hi is not None:
        return f" ({lo} to {hi} of them)"
    if hi is not None:
        return f" (at most {hi})"
    return f" (at least {lo})" if lo is not None else ""
