"""The example config of every scene kind, ready to trace from any directory.

Contract: :func:`example` is a deep copy of the ``EXAMPLE`` of a kind's generator module
(``microsim.geometry.SCENES[kind].EXAMPLE``: a small whole run config with a fixed seed, see
geometry/__init__.py), with the file its scene names (``scene.path``, relative to the
repository's root) made absolute, so that it traces from whatever directory a test or the
fuzzer runs in; changing the copy changes no other. The examples' files are the repository's
own (runs/meshes, runs/heightfields): a checkout, or an editable install, has them.
"""

from __future__ import annotations

import copy
from pathlib import Path

from microsim.geometry import SCENES

#: the repository's root (microsim/testing/ lies two folders below it)
ROOT = Path(__file__).resolve().parents[2]


def kinds() -> list[str]:
    """Every registered scene kind, in the registry's order."""
    return list(SCENES)


def example(kind: str) -> dict:
    """The kind's EXAMPLE, a copy of its own, with its ``scene.path`` resolved against ROOT."""
    data = copy.deepcopy(SCENES[kind].EXAMPLE)
    path = data["scene"].get("path")
    if path is not None and not Path(path).is_absolute():
        data["scene"]["path"] = str(ROOT / path)
    return data
