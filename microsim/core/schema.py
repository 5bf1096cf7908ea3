"""Base of every config section: strict types, no unknown keys (docs/conventions.md §4)."""

from pydantic import BaseModel, ConfigDict


class Section(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)
