"""numba's on-disk cache of microsim's kernels, invalidated by any change to the sources a kernel
can carry: the tracer's, the physics it calls, the scene generators that hand it records and
constants, and the contract's constants it indexes with.

numba stamps a cached kernel with the source of its own file only, but a kernel carries the
machine code of the kernels it calls from other modules (inlined or linked) and the values of
their module constants: after an edit of ``materials.scatter`` alone, the cached ``advance`` of
the surface tracer would keep running the old ``scatter``. :func:`install` wraps each of numba's
cache locators, in numba's own order (so ``NUMBA_CACHE_DIR`` and read-only installs behave as
usual), so that a kernel defined in the microsim package, or in the checkout's benchmarks/ and
tests/ (which call them), is stamped with its own file's stamp and the hash of what it can carry
(:func:`carried_sources`), and of every plugin registered from another module
(:func:`add_plugin_source`). An edit of the command line, the analysis, the tables or the docs
recompiles nothing (tests/test_kernel_cache.py).
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import pickle
from pathlib import Path

#: the microsim package's folder
PACKAGE = Path(__file__).resolve().parents[2]
#: the tracer's own folders: a kernel defined in them carries only TRACER_SOURCES
TRACER_FOLDERS = ("tracer", "physics")
#: the contract's modules whose constants the tracer's kernels index with (tally rows, orders)
CONTRACT_CONSTANTS = ("core/tally.py", "core/orders.py")
#: what the models' kernels, the testing helpers' and the checkout's add: the models
MODEL_SOURCES = ("models", "testing")
#: files whose kernels get the stamp: the package, and the checkout's callers of it
STAMPED = (PACKAGE, PACKAGE.parent / "benchmarks", PACKAGE.parent / "tests")
#: files outside the carried sources that hold kernels compiled into microsim's (an estimator's
#: hook registered from another module: :func:`add_plugin_source`)
PLUGIN_SOURCES: set[Path] = set()


@functools.cache
def geometry_folder() -> Path:
    """Where microsim.geometry's sources are: the repository's geometry/ folder in a checkout
    (an editable install maps it), microsim/geometry/ in an installed wheel."""
    return Path(importlib.util.find_spec("microsim.geometry").submodule_search_locations[0]).resolve()


def tracer_sources() -> tuple[Path, ...]:
    """What the tracer's kernels carry: the tracer and the physics it calls, the scene generators
    (they hand kernels records and constants), and CONTRACT_CONSTANTS."""
    return (*(PACKAGE / name for name in TRACER_FOLDERS), geometry_folder(),
            *(PACKAGE / name for name in CONTRACT_CONSTANTS))


def carried_sources(path: Path) -> tuple[Path, ...]:
    """What a kernel defined in file ``path`` carries: :func:`tracer_sources` for a kernel of
    the tracer or a generator; those and MODEL_SOURCES for one of the models, the testing
    helpers, or the checkout's tests and benchmarks (which may call a model's kernels)."""
    tracer = tracer_sources()
    if any(path.is_relative_to(root) for root in tracer):
        return tracer
    return (*tracer, *(PACKAGE / name for name in MODEL_SOURCES))


def sources(root: Path) -> list[Path]:
    """The Python files of ``root`` (a folder, or one file), skipping editor lock files and other
    dotfiles and broken links."""
    if root.is_file():
        return [root]
    return sorted(p for p in root.rglob("*.py") if p.is_file() and not p.name.startswith("."))


def package_stamp(root: Path) -> bytes:
    """SHA-256 over the relative path and contents of every file of :func:`sources` (recomputed
    when a file's modification time or size changes)."""
    files = sources(root)
    return _digest(root if root.is_dir() else root.parent, tuple((p, p.stat().st_mtime_ns, p.stat().st_size) for p in files))


@functools.lru_cache(maxsize=32)
def _digest(root: Path, files: tuple) -> bytes:
    digest = hashlib.sha256()
    for path, _, _ in files:
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    return digest.digest()


def add_plugin_source(path) -> None:
    """The kernels of file ``path`` are compiled into microsim's (a registered plugin): stamp
    microsim's kernels with it too, so that an edit of it recompiles them (unless it is one of
    the tracer's sources, which are stamped already)."""
    path = Path(path).resolve()
    if path.is_file() and not is_source(path):
        PLUGIN_SOURCES.add(path)


def is_source(path) -> bool:
    """Whether ``path`` is a file of :func:`tracer_sources`."""
    return any(Path(path).resolve().is_relative_to(root) for root in tracer_sources())


def plugin_stamp() -> bytes:
    """SHA-256 over the contents of every file of PLUGIN_SOURCES (b"" when there is none)."""
    if not PLUGIN_SOURCES:
        return b""
    files = tuple((p, p.stat().st_mtime_ns, p.stat().st_size) for p in sorted(PLUGIN_SOURCES))
    return _digest(Path("/"), files)


class Stamp(tuple):
    """The stamp of a stamped kernel: its file's, its carried sources', and the plugins' last (numba
    reads a locator's stamp once, when a kernel is defined, before plugins register: the plugins'
    part is brought up to date whenever the cache index is read or written, :func:`install`)."""


class PackageStamped:
    """Mixin of a numba cache locator: adds the carried sources' and plugins' stamps to the stamp of a stamped file."""

    def get_source_stamp(self):
        stamp = super().get_source_stamp()
        py_file = getattr(self, "_py_file", None)
        if py_file is not None and is_stamped(Path(py_file)):
            carried = carried_sources(Path(py_file).resolve())
            return Stamp((stamp, *(package_stamp(root) for root in carried), plugin_stamp()))
        return stamp


def is_stamped(path: Path) -> bool:
    """Whether kernels of file ``path`` get the stamp: those of microsim, its generators, and the
    checkout's benchmarks and tests."""
    path = path.resolve()
    return any(path.is_relative_to(root) for root in (*STAMPED, geometry_folder()))


def cache_impl():
    """The numba class whose list of locators numba tries in order (named _CacheImpl before 0.60)."""
    from numba.core import caching

    return getattr(caching, "CacheImpl", None) or caching._CacheImpl


def install() -> None:
    """Wrap every numba cache locator with :class:`PackageStamped`, and numba's reading and
    writing of a cache index with :func:`_with_plugins` (and its reading with :func:`_tolerant`)
    (idempotent)."""
    from numba.core import caching

    locators = cache_impl()._locator_classes
    for j, locator in enumerate(locators):
        if not issubclass(locator, PackageStamped):
            locators[j] = type(locator.__name__, (PackageStamped, locator), {})
    index = caching.IndexDataCacheFile
    if not getattr(index._load_index, "tolerant", False):
        index._load_index = _with_plugins(_tolerant(index._load_index))
        index._save_index = _with_plugins(index._save_index)


def _with_plugins(method):
    """A method of numba's cache index file that first brings the plugins' part of a
    :class:`Stamp` up to date."""
    def call(self, *args):
        if isinstance(self._source_stamp, Stamp):
            self._source_stamp = Stamp((*self._source_stamp[:-1], plugin_stamp()))
        return method(self, *args)

    call.tolerant = getattr(method, "tolerant", False)
    return call


def _tolerant(load_index):
    """numba's ``_load_index``, except that an index it cannot unpickle is an empty one (stale: the
    kernel is compiled again, and the index rewritten). An index names the types of the kernels
    it holds; one compiled with a plugin's record (an estimator's tally defined in a module of its
    own) cannot be read by a process that cannot import that module."""
    def load(self):
        try:
            return load_index(self)
        except (ImportError, AttributeError, pickle.UnpicklingError, EOFError):
            return {}

    load.tolerant = True
    return load
