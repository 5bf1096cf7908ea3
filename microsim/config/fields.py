"""What a field of a config section accepts, read from its pydantic model (the schema), in words.

The one-line messages (:mod:`microsim.config.messages`) and the keys' reference
(:mod:`microsim.config.reference`) both state what a key accepts from here, so the two say the same.
"""

from __future__ import annotations

import math
import types
import typing
from typing import Annotated, Literal, Union

import annotated_types
from pydantic import BaseModel


def field_of(model, name):
    """What field ``name`` of a model class holds: a model class, a tagged union, a list or a FieldInfo."""
    if not (isinstance(model, type) and issubclass(model, BaseModel)) or name not in model.model_fields:
        return None
    info = model.model_fields[name]
    inner = _unwrap(info.annotation)
    if (isinstance(inner, type) and issubclass(inner, BaseModel)) or union_members(inner):
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


def union_members(annotation) -> list:
    """The section models of a union discriminated by ``kind`` (else an empty list)."""
    if typing.get_origin(annotation) is Annotated:
        annotation = typing.get_args(annotation)[0]
    if typing.get_origin(annotation) is Union:
        members = [a for a in typing.get_args(annotation) if isinstance(a, type) and issubclass(a, BaseModel)]
        return members if all("kind" in m.model_fields for m in members) else []
    return []


def kind_of(member) -> str:
    return typing.get_args(member.model_fields["kind"].annotation)[0]


def tagged_member(union, tag):
    for member in union_members(union):
        if kind_of(member) == tag:
            return member
    return None


def accepted(field, error) -> str:
    """What a field accepts, from its type and its numeric bounds."""
    if isinstance(field, _ItemField):
        if isinstance(error["loc"][-1], int):
            return "accepted: a number in " + _range(typing.get_args(field.item)[1:])
        return "accepted: a list of numbers, each in " + _range(typing.get_args(field.item)[1:]) + _length(field.info)
    if isinstance(field, type) and issubclass(field, BaseModel):
        return "accepted: a table with keys " + ", ".join(field.model_fields)
    if union_members(field):
        return "accepted: a table with a kind among " + ", ".join(kind_of(m) for m in union_members(field))
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
