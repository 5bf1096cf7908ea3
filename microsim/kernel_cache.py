"""numba's on-disk cache of microsim's kernels, invalidated by any change to microsim's sources.

numba stamps a cached kernel with the source of its own file only, but a kernel carries the
machine code of the kernels it calls from other modules (inlined or linked): after an edit of
``materials.scatter`` alone, the cached ``advance`` of the surface tracer would keep running the
old ``scatter``. The locator below stamps every kernel defined in the microsim package (and in
the checkout's benchmarks/ and tests/, which call them) with the hash of all microsim sources,
so that any edit recompiles them all. Caches stay in ``__pycache__`` beside the sources.
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path

from numba.core import caching
from numba.core.caching import InTreeCacheLocator

#: the class whose list of locators numba tries in order (renamed from _CacheImpl in numba 0.60)
_CACHE_IMPL = getattr(caching, "CacheImpl", None) or caching._CacheImpl

PACKAGE = Path(__file__).resolve().parent
#: files whose kernels get the package stamp: the package, and the checkout's callers of it
STAMPED = (PACKAGE, PACKAGE.parent / "benchmarks", PACKAGE.parent / "tests")


@functools.lru_cache(maxsize=None)
def package_stamp() -> bytes:
    """SHA-256 over the path and contents of every Python file of the microsim package."""
    digest = hashlib.sha256()
    for path in sorted(PACKAGE.rglob("*.py")):
        digest.update(str(path.relative_to(PACKAGE)).encode())
        digest.update(path.read_bytes())
    return digest.digest()


class PackageStampedLocator(InTreeCacheLocator):
    """numba's in-tree cache locator, with the package stamp as the source stamp."""

    @classmethod
    def from_function(cls, py_func, py_file):
        path = Path(py_file).resolve()
        if not any(path.is_relative_to(root) for root in STAMPED):
            return None
        return super().from_function(py_func, py_file)

    def get_source_stamp(self):
        return package_stamp()


def install() -> None:
    """Put the locator first among numba's (idempotent)."""
    if PackageStampedLocator not in _CACHE_IMPL._locator_classes:
        _CACHE_IMPL._locator_classes.insert(0, PackageStampedLocator)
