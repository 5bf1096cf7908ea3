"""numba caches of microsim's kernels carry a stamp of every microsim source (microsim/kernel_cache.py)."""

import os

from numba.core import caching

from microsim import kernel_cache
from microsim.kernel_cache import PackageStamped, package_stamp


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


def test_every_numba_locator_adds_the_package_stamp_for_microsim_files_only(tmp_path):
    locators = kernel_cache._CACHE_IMPL._locator_classes
    assert all(issubclass(locator, PackageStamped) for locator in locators)
    in_tree = next(locator for locator in locators if issubclass(locator, caching.InTreeCacheLocator))

    def kernel():
        return 0

    inside = in_tree.from_function(kernel, kernel_cache.__file__)
    assert inside.get_source_stamp()[1] == package_stamp()
    outside_file = tmp_path / "elsewhere.py"
    outside_file.write_text("def kernel():\n    return 0\n")
    outside = in_tree.from_function(kernel, str(outside_file))
    assert outside.get_source_stamp() == caching.InTreeCacheLocator.get_source_stamp(outside)
