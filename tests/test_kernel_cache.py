"""numba caches of microsim's kernels carry a stamp of the sources they carry (microsim/tracer/jit/kernel_cache.py)."""

import os
import pickle
from pathlib import Path

import pytest
from numba.core import caching

from microsim.tracer.jit import kernel_cache
from microsim.tracer.jit.kernel_cache import PackageStamped, package_stamp


def test_the_package_stamp_follows_every_source_and_skips_lock_files_and_broken_links(tmp_path):
    (tmp_path / "a.py").write_text("X = 1\n")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "b.py").write_text("Y = 2\n")
    first = package_stamp(tmp_path)
    os.symlink(tmp_path / "missing.py", tmp_path / ".#a.py")  # an editor's lock file: a dangling link
    (tmp_path / ".hidden.py").write_text("Z = 3\n")
    assert package_stamp(tmp_path) == first
    (tmp_path / "sub" / "b.py").write_text("Y = 3\n")
    assert package_stamp(tmp_path) != first


def test_every_numba_locator_adds_the_carried_stamp_for_microsim_files_only(tmp_path):
    locators = kernel_cache.cache_impl()._locator_classes
    assert all(issubclass(locator, PackageStamped) for locator in locators)
    in_tree = next(locator for locator in locators if issubclass(locator, caching.InTreeCacheLocator))

    def kernel():
        return 0

    inside = in_tree.from_function(kernel, kernel_cache.__file__)
    assert inside.get_source_stamp()[1:] == (*(package_stamp(root) for root in kernel_cache.tracer_sources()),
                                              kernel_cache.plugin_stamp())
    assert isinstance(inside.get_source_stamp(), kernel_cache.Stamp)
    assert kernel_cache.geometry_folder() in kernel_cache.tracer_sources()
    model = in_tree.from_function(kernel, str(kernel_cache.PACKAGE / "models" / "hfunctions.py"))
    assert model.get_source_stamp()[-3] == package_stamp(kernel_cache.PACKAGE / "models")
    outside_file = tmp_path / "elsewhere.py"
    outside_file.write_text("def kernel():\n    return 0\n")
    outside = in_tree.from_function(kernel, str(outside_file))
    assert outside.get_source_stamp() == caching.InTreeCacheLocator.get_source_stamp(outside)


def test_a_run_compiles_nothing_once_its_tracer_is_compiled_ahead(tmp_path):
    """A run compiles nothing once its tracer is compiled ahead: runner.Run.compile compiles
    every kernel the run calls, for its number of albedos, so that in an empty numba cache no
    unit compiles (a compile there would be unannounced, inside the time left and paths/s, and
    on forked workers, where nothing sees it)."""
    import subprocess
    import sys

    code = """
from numba.core import event
from microsim import config; from microsim.run import runner
cfg = config.validate({"scene": {"kind": "halfspace_medium", "phase": "isotropic"},
                       "material": {"kind": "lambert", "albedo": [0.3, 0.9]}, "illumination": {"theta_i_deg": [30.0]},
                       "sensor": {"cells": 50}, "run": {"paths": 2000, "realizations": 2}})
runner.Run.of(cfg).compile()
compiled = []
class Listener(event.Listener):
    def on_start(self, ev):
        compiled.append(ev.data["dispatcher"].py_func.__name__)
    def on_end(self, ev):
        pass
event.register("numba:compile", Listener())
from microsim.testing import trace_albedos
trace_albedos(cfg)
print(compiled)
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env={**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)})
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


#: edits of a copy of the sources, each with whether it recompiles the tracer's kernels
EDITS = (
    ("microsim/analysis/compare.py", "docstring", False),
    ("microsim/cli/__init__.py", "docstring", False),
    ("microsim/tables/__init__.py", "docstring", False),
    ("microsim/models/lambert.py", "docstring", False),
    ("microsim/core/files.py", "docstring", False),
    ("microsim/geometry/plane.py", "constant", True),
    ("microsim/tracer/materials/lambert.py", "constant", True),
    ("microsim/core/tally.py", "constant", True),
)


def test_a_kernel_recompiles_for_an_edit_of_what_it_carries_and_for_no_other(tmp_path):
    """In a copy of the sources laid out as a wheel installs them (microsim/geometry inside the
    package), a tracer kernel loads from the cache when nothing it carries changed: edits of
    the analysis, the command line, the table reader, a model and the file helpers, all at once
    (one process), recompile nothing; an edit of a generator, a tracer module or the tally's
    constants, each alone, recompiles it."""
    import shutil
    import subprocess
    import sys

    root = kernel_cache.PACKAGE.parent
    shutil.copytree(root / "microsim", tmp_path / "microsim", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(kernel_cache.geometry_folder(), tmp_path / "microsim" / "geometry",
                    ignore=shutil.ignore_patterns("__pycache__"))
    code = ("import microsim.geometry\n"
            "from microsim.tracer.jit import kernel_cache\n"
            "assert kernel_cache.geometry_folder().parent == kernel_cache.PACKAGE\n"
            "from microsim.tracer.jit.compile_watch import CompileWatch\n"
            "with CompileWatch() as watch:\n"
            "    from microsim.physics.rng import stream_key\n"
            "    stream_key(1, 2, 3)\n"
            "print(watch.seconds > 0)")

    def compiles() -> bool:
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path,
                              env={k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"})
        assert done.returncode == 0, done.stderr
        return done.stdout.split()[-1] == "True"

    def edit(name: str, what: str) -> None:
        path = tmp_path / name
        text = path.read_text()
        path.write_text(text.replace('"""', '"""Edited. ', 1) if what == "docstring" else text + "\nAN_EDITED_CONSTANT = 1\n")

    assert compiles()  # a fresh copy: nothing cached
    assert not compiles()  # loaded from the cache
    for name, what, recompiles in EDITS:
        if not recompiles:
            edit(name, what)
    assert not compiles(), "an edit of a file no kernel carries recompiled one"  # all of them at once: none
    seen = []
    for name, what, recompiles in EDITS:
        if recompiles:
            edit(name, what)
            seen.append((name, compiles()))  # one at a time: each recompiles
    assert seen == [(name, True) for name, _, recompiles in EDITS if recompiles]


def test_a_plugin_registered_from_another_file_joins_the_stamp(tmp_path, monkeypatch):
    """An estimator's hook compiled into microsim's kernels from another module
    (microsim.tracer.jit.dispatch): an edit of its file changes the stamp; microsim's own files are stamped
    already and are not added."""
    monkeypatch.setattr(kernel_cache, "PLUGIN_SOURCES", set())
    kernel_cache.add_plugin_source(kernel_cache.__file__)
    assert kernel_cache.plugin_stamp() == b""
    plugin = tmp_path / "plugin.py"
    plugin.write_text("X = 1\n")
    kernel_cache.add_plugin_source(plugin)
    first = kernel_cache.plugin_stamp()
    plugin.write_text("X = 2\n")
    assert kernel_cache.plugin_stamp() not in (first, b"")


def test_an_index_that_names_a_module_this_process_cannot_import_is_a_stale_one():
    """A kernel compiled with a plugin's record (its class in a module of its own) is listed in
    numba's index by type: a process without that module recompiles instead of failing."""
    from numba.core import caching

    assert getattr(caching.IndexDataCacheFile._load_index, "tolerant", False)
    unreadable = b"cno_such_plugin_module\nRecord\n."  # a pickle of a class of a missing module
    assert kernel_cache._tolerant(lambda index: pickle.loads(unreadable))(None) == {}


def test_a_plugin_registered_after_a_kernel_was_defined_makes_its_cache_stale(tmp_path, monkeypatch):
    """numba takes a kernel's stamp when the kernel is defined, before plugins register: a cache
    entry saved before a plugin's file changed is not loaded after (the index's stamp is brought
    up to date as it is read and written)."""
    from numba.core import caching

    monkeypatch.setattr(kernel_cache, "PLUGIN_SOURCES", set())
    index = caching.IndexDataCacheFile(str(tmp_path), "kernel", kernel_cache.Stamp(("own", kernel_cache.plugin_stamp())))
    index.save("key", b"machine code")
    assert index.load("key") == b"machine code"
    plugin = tmp_path / "plugin.py"
    plugin.write_text("X = 1\n")
    kernel_cache.add_plugin_source(plugin)
    assert index.load("key") is None  # stale: compiled again
    index.save("key", b"new machine code")
    assert index.load("key") == b"new machine code"
    plugin.write_text("X = 22\n")
    assert index.load("key") is None


#: the chunk kernels of every tracer: what Run.compile compiles ahead and a run's threads call
CHUNK_KERNELS = (
    ("microsim.tracer.integrators.direct", "trace_chunks"),
    ("microsim.tracer.integrators.sphere_grid", "trace_chunks"),
    ("microsim.tracer.integrators.grid", "trace_chunks"),
    ("microsim.tracer.integrators.vcavity", "trace_chunks_analytic"),
    ("microsim.tracer.integrators.vcavity", "trace_chunks_embree"),
    ("microsim.tracer.integrators.medium", "trace_medium_chunks"),
)
#: every scene kind's example, and the examples of its other intersectors
TYPED_EXAMPLES = [(kind, None) for kind in ("plane", "mesh", "halfspace_medium", "packed_spheres")] + [
    ("micrograins", "grid"), ("micrograins", "embree"), ("poisson_spheres", "grid"), ("poisson_spheres", "embree"),
    ("heightfield", "grid"),
    ("heightfield", "triangles"), ("vcavities", "analytic"), ("vcavities", "embree")]


@pytest.mark.parametrize("kind, intersector", TYPED_EXAMPLES)
@pytest.mark.parametrize("albedos", [1, 2])
def test_a_tracer_is_compiled_ahead_on_the_types_its_runs_trace(kind, intersector, albedos, monkeypatch):
    """Run.compile calls each chunk kernel on the types a run's threads call it on: a run of
    several chunks a unit on two threads, one or two albedos. numba compiles a kernel once for
    each distinct type signature, so one more signature is a second compile of the whole tracer
    (15-25 s). The kernels are replaced by recorders of their arguments' numba types: nothing is
    compiled or traced."""
    import importlib

    import numba

    from microsim import config
    from microsim.testing import trace_albedos
    from microsim.testing.scenes import example
    from microsim.tracer.integrators.scheduler import CHUNK_PATHS

    seen = {}
    for module, name in CHUNK_KERNELS:
        monkeypatch.setattr(importlib.import_module(module), name,
                            lambda *args, key=(module, name): seen.setdefault(key, set()).add(numba.typeof(args)))
    data = example(kind)
    if intersector is not None:
        data["scene"]["intersector"] = intersector
    if "albedo" not in data["material"]:
        data["material"] = {"kind": "lambert"}
    if albedos > 1 and "base" in data:
        data["base"] = {"kind": "absorber"}  # several albedos from one run: the base must absorb
    data["material"]["albedo"] = [0.3, 0.6] if albedos > 1 else 0.6
    data["run"]["paths"] = 3 * CHUNK_PATHS * data["run"]["realizations"]
    trace_albedos(config.validate(data), threads=2)
    assert len(seen) == 1, seen.keys()
    (kernel, signatures), = seen.items()
    assert len(signatures) == 1, (kernel, [str(s) for s in signatures])
