"""Every key of a run's config as the reference documents it, read from the schema (the same
source as validation)."""

from __future__ import annotations

import dataclasses

from microsim.config import fields
from microsim.config.sections import AnyMaterial, Config, Illumination, Run, Scene, SensorSection


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
        members = fields.union_members(model) or [model]
        names = dict.fromkeys(name for member in members for name in member.model_fields)
        for name in names:
            holders = [m for m in members if name in m.model_fields]
            if name == "kind":  # every member's tag
                out.append(_key(f"{section}.kind", holders[0], name, members))
                continue
            each = [_key(f"{section}.{name}", m, name) for m in holders]
            tags = [fields.kind_of(m) for m in holders] if len(members) > 1 else [""]
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
        accepted = ", ".join(repr(fields.kind_of(m)) for m in members)
    else:
        accepted = fields.accepted(fields.field_of(model, name), {"loc": (name,)}).removeprefix("accepted: ")
    if info.is_required():
        default = "required"
    else:
        default = repr(info.default) if info.default is not None else "unset"
    doc = info.description or ("the kind: which of the kinds named under accepted" if name == "kind" else "")
    return Key(dotted, "", accepted, default, doc)
