"""Property-based fuzzing of ``microsim run``, shared by the suite (tests/test_fuzz_cli.py,
reduced size) and benchmarks/fuzz_cli.py (full size).

Contract: :func:`check` runs one case drawn by :func:`cases` in-process and asserts what the
command line promises: exit 0 with a loadable table (or a sweep's tables and index) and nothing
left behind, or exit 2 with one line on stderr and nothing written; never a traceback.

A case is a config and a command line drawn by hypothesis: the example config of a scene kind
(every kind of ``microsim.geometry.SCENES``, its ``EXAMPLE`` through
:func:`microsim.testing.scenes.example`, so that a new kind is fuzzed with no change here) at
the cheap counts of ``COMMON``, then up to four mutations (a key of any section, known or not,
set to an edge value -- zero, negative, NaN, infinity, huge, a wrong type -- or deleted),
optionally a ``[sweep]`` with good or bad keys, optionally a file that is not TOML at all; and
flags with good and bad values. Counts (paths, realizations, cells, tile, depth, statistics
rays) are drawn either cheap and valid or invalid, so that a valid case traces in a fraction of
a second.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
from pathlib import Path

from hypothesis import strategies as st

from microsim import tables
from microsim.app.sweep import INDEX
from microsim.cli import main
from microsim.geometry import SCENES
from microsim.testing.scenes import example

#: the sections that replace an example's: counts cheap enough for a case to trace in a fraction of a second
COMMON = {"illumination": {"theta_i_deg": [0.0, 60.0]}, "sensor": {"cells": 24},
          "run": {"paths": 120, "realizations": 2, "seed": 1}}

NAN, INF = math.nan, math.inf
#: values no key should take silently
EDGES = st.sampled_from([0, -1, 1, 2, 0.5, -0.0, 1e-300, 1e300, NAN, INF, -INF, 10**30, 2**63, -(2**63), "", "x",
                         "nan", True, False, [], [1, 2], [NAN], {}, {"a": 1}, 3.7, 90, 91, -90, 1000])
ANY = st.one_of(EDGES, st.floats(allow_nan=True, allow_infinity=True), st.integers(-(2**70), 2**70),
                st.text(max_size=6), st.lists(st.floats(-100, 100), max_size=3))


def cheap_or_bad(valid: st.SearchStrategy) -> st.SearchStrategy:
    """A value that is valid and cheap to trace, or one that must be refused (never valid and huge)."""
    bad = st.sampled_from([0, -1, -5.5, NAN, INF, -INF, 10**13, 10**30, "x", [], {}, True])
    return st.one_of(valid, bad)


#: keys whose valid values can be expensive: drawn cheap or bad only
BOUNDED = {
    ("run", "paths"): cheap_or_bad(st.integers(1, 300)),
    ("run", "realizations"): cheap_or_bad(st.integers(2, 4)),
    ("sensor", "cells"): cheap_or_bad(st.integers(1, 400)),
    ("sensor", "retro_rings"): cheap_or_bad(st.integers(0, 20)),
    ("scene", "tile"): cheap_or_bad(st.floats(4.0, 10.0)),
    ("scene", "depth"): cheap_or_bad(st.floats(0.5, 6.0)),
    ("scene", "subdivisions"): cheap_or_bad(st.integers(0, 2)),
    ("scene", "mesh_error"): cheap_or_bad(st.floats(0.05, 0.5)),
    ("scene", "statistics_rays"): cheap_or_bad(st.integers(16, 64)),
}
#: other keys mutated with any value: the schema's and some it does not know
KEYS = [("scene", k) for k in sorted({key for module in SCENES.values() for key in module.Config.model_fields}
                                     - {key for section, key in BOUNDED if section == "scene"}) + ["bogus"]] + \
       [("material", k) for k in ("kind", "albedo", "eta", "k", "bogus")] + \
       [("base", k) for k in ("kind", "albedo")] + \
       [("illumination", k) for k in ("theta_i_deg", "phi_i_deg", "bogus")] + \
       [("sensor", k) for k in ("retro_max_deg", "bogus")] + \
       [("run", k) for k in ("seed", "max_order", "backend", "bogus")] + \
       [(None, "name"), (None, "bogus"), (None, "scene"), (None, "run")]

mutation = st.one_of(
    st.sampled_from(sorted(BOUNDED, key=str)).flatmap(lambda key: st.tuples(st.just(key), BOUNDED[key])),
    st.tuples(st.sampled_from(KEYS), ANY),
    st.tuples(st.sampled_from(sorted(BOUNDED, key=str) + KEYS), st.just("<delete>")),
)

sweep = st.one_of(
    st.fixed_dictionaries({"material.albedo": st.sampled_from([[0.4, 0.6], [0.5, 1.5], [], [NAN], 0.5])}),
    st.fixed_dictionaries({"run.seed": st.sampled_from([[1, 2], [1, 1], [-1]])},
                          optional={"mode": st.sampled_from(["grid", "zip", "cross", 3])}),
    st.dictionaries(st.sampled_from(["scene.nope", "material.albedo.x", "run", "", ".", "illumination.theta_i_deg"]),
                    st.sampled_from([[0.5], [[30.0]], [1, 2], "x"]), min_size=1, max_size=2),
)

flags = st.lists(st.one_of(
    st.tuples(st.just("--paths"), st.sampled_from(["1", "50", "0", "-3", "1e3", "x", str(10**13), "nan"])),
    st.tuples(st.just("--workers"), st.sampled_from(["1", "2", "0", "-1", "300", "x"])),
    st.tuples(st.just("--threads"), st.sampled_from(["1", "2", "0", "1000", "x"])),
    st.tuples(st.just("--seed"), st.sampled_from(["0", "7", "-1", str(2**63), "x"])),
    st.tuples(st.just("--backend"), st.sampled_from(["auto", "direct", "embreex", "gpu"])),
    st.tuples(st.just("--executor"), st.sampled_from(["local", "cloud", "dask"])),
    st.tuples(st.just("--scheduler"), st.sampled_from(["nonsense", "foo://h:1", "tcp://h:99999", "ucx://h:1"])),
    st.tuples(st.sampled_from(["--resume", "--force", "--bogus"])),
), max_size=3)

garbage = st.one_of(st.binary(max_size=40), st.text(max_size=40).map(str.encode),
                    st.just(b"[scene\nkind = "), st.just(b"\xff\xfe not utf-8"))


#: what an earlier run may have left where this one keeps its units: nothing, an empty store (a
#: SIGKILL before the first unit), a store of junk units and a damaged manifest, or a file
LEFTOVERS = st.sampled_from([None, None, None, None, "empty", "junk", "file"])


def leave(kind, store: Path) -> None:
    if kind == "empty":
        store.mkdir()
        (store / "manifest.json").write_text("{}")
    elif kind == "junk":
        store.mkdir()
        (store / "manifest.json").write_text("not json")
        (store / "r0_i0.0123456789abcdef.npz").write_bytes(b"not a unit")
    elif kind == "file":
        store.write_text("not a store")


@st.composite
def cases(draw):
    """(config file bytes, extra flags, whether it is a sweep, what was left in the unit store)."""
    if draw(st.integers(0, 19)) == 0:
        return draw(garbage), [], False, None
    kind = draw(st.sampled_from(sorted(SCENES)))
    data = {**example(kind), **json.loads(json.dumps(COMMON))}  # copies of their own
    for (section, key), value in draw(st.lists(mutation, max_size=4)):
        node = data if section is None else data.setdefault(section, {})
        if not isinstance(node, dict):
            continue
        if value == "<delete>":
            node.pop(key, None)
        else:
            node[key] = value
    points = draw(sweep) if draw(st.integers(0, 4)) == 0 else None
    if points is not None:
        data["sweep"] = points
    leftover = draw(LEFTOVERS) if points is None else None
    return to_toml(data).encode(), [item for flag in draw(flags) for item in flag], points is not None, leftover


def to_toml(data: dict) -> str:
    """Any nesting as inline tables; NaN and infinity as TOML writes them."""
    return "".join(f"{_key(k)} = {_value(v)}\n" for k, v in data.items())


def _key(key: str) -> str:
    return json.dumps(key)


def _value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    return "{" + ", ".join(f"{_key(k)} = {_value(v)}" for k, v in value.items()) + "}"


def check(folder: Path, text: bytes, extra: list[str], is_sweep: bool, leftover=None) -> tuple[int, str]:
    """Run one case in ``folder`` (empty but for what this writes) and assert the contract;
    return the exit status and what it wrote on stderr."""
    config = folder / "case.toml"
    config.write_bytes(text)
    out = folder / ("out" if is_sweep else "out.h5")
    leave(leftover, folder / "out.h5.partial")
    before = snapshot(folder)
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        status = main(["run", str(config), "--out", str(out), *extra])
    err = stderr.getvalue()
    left = sorted(p.name for p in folder.iterdir() if p.name != config.name)
    assert "Traceback" not in err, err
    assert status in (0, 2), (status, err)
    if status == 2:
        lines = err.splitlines()
        assert len(lines) == 1 and lines[0].startswith("microsim: error: "), err
        assert snapshot(folder) == before, f"a refused case changed {left}: {err}"
        return status, err
    written = [out] if not is_sweep else [p for p in out.iterdir() if p.suffix == ".h5"]
    if out.name.endswith(".h5") and not out.exists():  # a run of several albedos: one table each
        written = [folder / name for name in left if name.endswith(".h5")]
    assert written and all(tables.load(p) is not None for p in written), (left, stdout.getvalue())
    assert not any(name.endswith(".partial") for name in left), left
    if is_sweep:
        assert (out / INDEX).exists() and not any(p.name.endswith(".partial") for p in out.iterdir())
    return status, err


def snapshot(folder: Path) -> dict:
    """Every file under ``folder``, by relative path, with its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() if p.is_file() else None for p in sorted(folder.rglob("*"))}
