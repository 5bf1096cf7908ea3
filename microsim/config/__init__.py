"""Run configs (docs/conventions.md §4): TOML in, validated pydantic models out, one-line errors.

Every section is a strict pydantic model (:mod:`microsim.config.sections`): unknown keys, wrong
types and out-of-range values are rejected. Scene kinds come from the generator registry
(``geometry.SCENES``) and material kinds from the material registry
(``microsim.tracer.materials.MATERIALS``), each with its own model, selected by ``kind``.
:func:`load` turns any problem into a :class:`ConfigError` whose message is one line naming the
key and the accepted values (:mod:`microsim.config.messages`); :func:`keys` lists every key with
what it accepts (:mod:`microsim.config.reference`).
"""

from microsim.config.loading import load, read, set_dotted, validate
from microsim.config.messages import ConfigError
from microsim.config.reference import Key, keys
from microsim.config.sections import Config, Illumination, Run, SensorSection

__all__ = ["Config", "ConfigError", "Illumination", "Key", "Run", "SensorSection", "keys", "load", "read",
           "set_dotted", "validate"]
