"""A config from its TOML file or a dictionary, validated; any problem a :class:`ConfigError` of one line."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pydantic

from microsim import geometry
from microsim.config.messages import ConfigError, describe_error
from microsim.config.sections import Config


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
        raise ConfigError(describe_error(first, data, Config)) from None
    try:
        geometry.SCENES[config.scene.kind].check(config)
    except ValueError as err:
        raise ConfigError(str(err)) from None
    return config
