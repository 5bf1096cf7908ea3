"""Base of every config section: strict types, no unknown keys (docs/conventions.md §4); and how a
section's validators quote and recognise values."""

import numbers

from pydantic import BaseModel, ConfigDict


class Section(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)


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


def is_number(value) -> bool:
    """A real number, of Python or numpy, not a bool."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool)
