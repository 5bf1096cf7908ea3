"""numba's on-disk cache of microsim's kernels, invalidated by any change to the sources a kernel
can carry: microsim's and geometry's.

numba stamps a cached kernel with the source of its own file only, but a kernel carries the
machine code of the kernels it calls from other modules (inlined or linked) and the values of
their module constants: after an edit of ``materials.scatter`` alone, the cached ``advance`` of
the surface tracer would keep running the old ``scatter``. :func:`install` wraps each of numba's
cache locators, in numba's own order (so ``NUMBA_CACHE_DIR`` and read-only installs behave as
usual), so that a kernel defined in the microsim package, or in the checkout's benchmarks/ and
tests/ (which call them), is stamped with its own file's stamp and the hash of every source of
microsim and of geometry (its generators hand kernels their records and constants): any edit of
either recompiles them all (README, numba caches).
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent
#: the packages whose sources the stamp covers: microsim, and the scene generators beside it
STAMP_SOURCES = (PACKAGE, PACKAGE.parent / "geometry")
#: files whose kernels get the package stamp: the package, and the checkout's callers of it
STAMPED = (PACKAGE, PACKAGE.parent / "benchmarks", PACKAGE.parent / "tests")


def sources(root: Path = PACKAGE) -> list[Path]:
    """The package's Python files, skipping editor lock files and other dotfiles and broken links."""
    return sorted(p for p in root.rglob("*.py") if p.is_file() and not p.name.startswith("."))


def package_stamp(root: Path = PACKAGE) -> bytes:
    """SHA-256 over the relative path and contents of every file of :func:`sources` (recomputed
    when a file's modification time or size changes)."""
    files = sources(root)
    return _digest(root, tuple((p, p.stat().st_mtime_ns, p.stat().st_size) for p in files))


@functools.lru_cache(maxsize=8)
def _digest(root: Path, files: tuple) -> bytes:
    digest = hashlib.sha256()
    for path, _, _ in files:
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    return digest.digest()


class PackageStamped:
    """Mixin of a numba cache locator: adds the package stamp to the stamp of a stamped file."""

    def get_source_stamp(self):
        stamp = super().get_source_stamp()
        py_file = getattr(self, "_py_file", None)
        if py_file is not None and is_stamped(Path(py_file)):
            return stamp, *(package_stamp(root) for root in STAMP_SOURCES)
        return stamp


def is_stamped(path: Path) -> bool:
    path = path.resolve()
    return any(path.is_relative_to(root) for root in STAMPED)


def cache_impl():
    """The numba class whose list of locators numba tries in order (named _CacheImpl before 0.60)."""
    from numba.core import caching

    return getattr(caching, "CacheImpl", None) or caching._CacheImpl


def install() -> None:
    """Wrap every numba cache locator with :class:`PackageStamped` (idempotent)."""
    locators = cache_impl()._locator_classes
    for j, locator in enumerate(locators):
        if not issubclass(locator, PackageStamped):
            locators[j] = type(locator.__name__, (PackageStamped, locator), {})
