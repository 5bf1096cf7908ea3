"""numba set up for microsim's kernels, installed when numba is first imported.

microsim's kernels need two changes to numba (:mod:`microsim.tracer.jit.kernel_cache`: a cache stamp over
every microsim source; :mod:`microsim.tracer.jit.inlining`: a shorter inliner). Both must be in place before
the first ``@numba.njit(cache=True)`` of microsim is decorated, yet importing numba costs about
half a second: ``microsim --help``, ``microsim models`` and a refused argument must not pay it.
So ``import microsim`` installs nothing but a finder that runs :func:`install` as soon as numba
itself has been imported, by whichever module imports it first (or at once, if it already is).
"""

from __future__ import annotations

import importlib.abc
import importlib.util
import sys


def install() -> None:
    """Install microsim's changes to numba (idempotent)."""
    from microsim.tracer.jit import inlining, kernel_cache

    kernel_cache.install()
    inlining.install()


class _AfterNumbaImport(importlib.abc.MetaPathFinder):
    """Finds numba as the other finders do, and has its loader call :func:`install` once numba's
    package has run; removes itself on first use."""

    def find_spec(self, fullname, path, target=None):
        if fullname != "numba":
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(fullname)
        if spec is None or spec.loader is None:
            return spec
        load = spec.loader.exec_module

        def exec_module(module):
            load(module)
            install()

        spec.loader.exec_module = exec_module
        return spec


def install_when_numba_loads() -> None:
    """:func:`install` now if numba is imported, else right after it is."""
    if "numba" in sys.modules:
        install()
    elif not any(isinstance(finder, _AfterNumbaImport) for finder in sys.meta_path):
        sys.meta_path.insert(0, _AfterNumbaImport())
