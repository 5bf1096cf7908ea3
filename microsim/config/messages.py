"""The one-line message of any problem of a config (docs/conventions.md §9): the dotted key, the
value given (an excerpt of it), what is accepted."""

from __future__ import annotations

from microsim.config import fields
from microsim.core.schema import excerpt


class ConfigError(ValueError):
    """A bad config: the message is one line naming the key and what is accepted."""


def describe_error(error: dict, data: dict, model) -> str:
    """One line for one pydantic error of validating ``data`` as the section ``model``: the dotted
    key, the value given, what is accepted."""
    node, owner, keys, value = model, None, [], data
    for part in error["loc"]:
        if isinstance(part, int):
            keys[-1] += f"[{part}]"
            value = value[part] if isinstance(value, list) and part < len(value) else None
            continue
        member = fields.tagged_member(node, part)
        if member is not None:  # a discriminator tag in the error path: step into that kind
            node = member
            continue
        keys.append(part)
        value = value.get(part) if isinstance(value, dict) else None
        owner, node = node, fields.field_of(node, part)
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
        return f"{key}: missing; {fields.accepted(node, error)}"
    if kind in ("union_tag_invalid", "union_tag_not_found"):
        tags = ", ".join(repr(fields.kind_of(m)) for m in fields.union_members(node))
        given = value.get("kind") if isinstance(value, dict) else None
        if given is None:
            return f"{key}.kind: missing; accepted: {tags}"
        return f"{key}.kind = {given!r}: unknown kind; accepted: {tags}"
    if kind == "string_pattern_mismatch":  # the only pattern: no control characters
        return f"{key}{shown}: contains a control character; accepted: printable text"
    problem = "out of range" if kind in _RANGE_ERRORS else error["msg"].lower()
    if kind in ("too_short", "too_long") and isinstance(value, list):
        problem = f"{len(value):,} items, out of range"
    return f"{key}{shown}: {problem}; {fields.accepted(node, error)}"


_RANGE_ERRORS = {"greater_than", "greater_than_equal", "less_than", "less_than_equal", "too_short", "too_long"}
