"""What microsim's tests and benchmarks check the engine with (as numpy.testing is numpy's).

The top layer: it may import every other one, and no module of microsim outside it imports it
(tests/test_layers.py). One module per idea, each with its contract in its docstring:

- :mod:`.runs`: the entry points, ``trace``, ``trace_albedos``, ``trace_realizations``: a config
  traced in memory (tests and benchmarks call these, never the runner);
- :mod:`.tables`: ``write_table``, ``trace_table`` (a config to a written, checked, loaded
  table: the ``simulate`` fixture), ``same_table`` (two tables bit for bit);
- :mod:`.bounds`: the two-sided bounds on a table's mean z^2;
- :mod:`.reciprocity`: incidences at ring centres, ``reciprocity_z`` and its power check;
- :mod:`.threads`: bit identity of tallies and tables for any number of threads;
- :mod:`.refusals`: bad input refused in one line, exit 2, nothing written;
- :mod:`.scenes`: the example config of every scene kind, ready to trace anywhere;
- :mod:`.fuzzing`: the hypothesis strategies and the contract check of the CLI fuzzer;
- :mod:`.materials`: ``material_check``, the chi-square test of a material's sampling;
- :mod:`.models`: what the analytic-model tests share;
- :mod:`.golden`: the golden tables and their checks on this host and on others;
- :mod:`.vcavities`: the V-cavity single-scattering cases of a test and a benchmark;
- :mod:`.surfaces`: small mesh and heightfield tiles made on the spot;
- :mod:`.configs`: small TOML configs several test files share;
- :mod:`.interruptions`: runs in processes of their own, stopped and killed.

The names below are importable from the package itself (``from microsim.testing import
material_check``); each submodule is imported when first asked for, so that importing one
helper loads no other (hypothesis, numba kernels).
"""

from __future__ import annotations

import importlib

#: name -> the submodule that defines it
_EXPORTS = {
    "trace": "runs", "trace_albedos": "runs", "trace_realizations": "runs",
    "write_table": "tables", "trace_table": "tables", "same_table": "tables",
    "chi2_bound": "bounds", "chi2_lower_bound": "bounds",
    "material_check": "materials", "MaterialCheck": "materials",
    "assert_refused": "refusals", "assert_run_refused": "refusals",
    "example": "scenes",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
