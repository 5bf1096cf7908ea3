"""The package's layers, its imports and its signatures.

microsim is a stack of layers (docs/developer/architecture.md), each a folder: a module imports
modules of its own layer and of lower ones, never of a higher one. Every import statement of every
module, those inside functions too, is an edge of the import graph; the graph has no cycle. That
importing a submodule runs its package's ``__init__`` first is not counted as an edge. The scene
generators of the repository's geometry/ folder are the layer ``microsim.geometry``.
"""

import ast
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
#: folder of the repository -> the package it is installed as
FOLDERS = {"microsim": "microsim", "geometry": "microsim.geometry"}
#: the layers, lowest first: a module of one imports none of a later one. The top-level modules
#: ``microsim`` (its ``__init__``) and ``microsim.__main__`` are the outermost shell; ``testing``,
#: what tests and benchmarks check the engine with, lies above it all (it runs the command line).
LAYERS = ("core", "physics", "tracer", "geometry", "config", "tables", "run", "models", "analysis", "interop",
          "app", "cli", "testing")
#: modules of the package itself, outside every layer: the outermost shell (``microsim``'s
#: ``__init__`` installs numba's setup; every layer may read its ``__version__``)
SHELL = {"microsim": "cli", "microsim.__main__": "cli"}


def module_name(path: Path) -> str:
    folder = next(f for f in FOLDERS if path.is_relative_to(ROOT / f))
    parts = path.relative_to(ROOT / folder).with_suffix("").parts
    parts = parts[:-1] if parts[-1] == "__init__" else parts
    return ".".join((FOLDERS[folder], *parts))


def imported(path: Path, name: str, modules: set[str]) -> set[str]:
    """The modules of the packages that ``path`` (module ``name``) imports, anywhere in it."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                stem = ".".join(base + ([node.module] if node.module else []))
            else:
                stem = node.module
            # ``from pkg import sub`` imports the submodule (the package's __init__ runs before any
            # of its submodules, and is not counted); ``from mod import name``, the module
            targets = [f"{stem}.{alias.name}" if f"{stem}.{alias.name}" in modules else stem for alias in node.names]
        else:
            continue
        for target in targets:
            while target and target not in modules:  # a name imported from a module: the module
                target = target.rpartition(".")[0]
            if target and target != name:
                found.add(target)
    return found


def module_paths() -> dict[str, Path]:
    return {module_name(p): p for folder in FOLDERS for p in (ROOT / folder).rglob("*.py")}


def import_graph() -> dict[str, set[str]]:
    paths = module_paths()
    modules = set(paths)
    return {name: imported(path, name, modules) for name, path in paths.items()}


def rank(module: str) -> int:
    """The position of ``module``'s layer in LAYERS."""
    layer = SHELL.get(module) or module.split(".")[1]
    return next(j for j, entry in enumerate(LAYERS) if layer == entry or layer in entry)


def upward_imports(graph: dict[str, set[str]]) -> list[str]:
    """Every edge from a module to one of a higher layer, or to one of another layer of the same rank."""
    found = []
    for module, targets in sorted(graph.items()):
        for target in sorted(targets):
            if target != "microsim" and (rank(target) > rank(module) or (
                    rank(target) == rank(module) and module.split(".")[1:2] != target.split(".")[1:2]
                    and module not in SHELL)):
                found.append(f"{module} -> {target}")
    return found


def test_every_module_belongs_to_a_layer():
    assert [m for m in module_paths() if m not in SHELL and m.split(".")[1] not in
            {name for entry in LAYERS for name in ((entry,) if isinstance(entry, str) else entry)}] == []


def test_no_module_imports_a_higher_layer():
    assert upward_imports(import_graph()) == []


def test_the_layer_check_sees_an_upward_import():
    """The check itself: the tracer importing the analysis, or the CLI importing the testing helpers, is found."""
    graph = {"microsim.tracer.sensor": {"microsim.core.frames", "microsim.analysis.compare"},
             "microsim.cli": {"microsim.testing", "microsim.app.session"}}
    assert upward_imports(graph) == ["microsim.cli -> microsim.testing",
                                     "microsim.tracer.sensor -> microsim.analysis.compare"]


def test_no_module_imports_geometry_as_a_top_level_package():
    """The generators are microsim.geometry: an import of ``geometry`` works only from the checkout."""
    found = [f"{p.relative_to(ROOT)}:{node.lineno}"
             for p in [*ROOT.glob("microsim/**/*.py"), *ROOT.glob("geometry/**/*.py"), *ROOT.glob("tests/**/*.py"),
                       *ROOT.glob("benchmarks/**/*.py"), *ROOT.glob("docs/**/*.py")]
             for node in ast.walk(ast.parse(p.read_text()))
             if isinstance(node, ast.Import) and any(a.name.split(".")[0] == "geometry" for a in node.names)
             or isinstance(node, ast.ImportFrom) and not node.level and (node.module or "").split(".")[0] == "geometry"]
    assert found == []


def cross_imports(source: str, local: set[str]) -> list[str]:
    """The modules of ``local`` (the modules of tests/) that the code ``source`` imports, as
    themselves or as ``tests.<module>``, and its relative imports, anywhere in it."""
    def of_tests(name: str) -> bool:
        parts = name.split(".")
        return parts[0] in local or parts[0] == "tests"

    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [alias.name for alias in node.names if of_tests(alias.name)]
        elif isinstance(node, ast.ImportFrom) and (node.level or of_tests(node.module or "")):
            found.append("." * node.level + (node.module or ""))
    return found


def puts_tests_on_path(source: str) -> bool:
    """Whether the code ``source`` adds to ``sys.path`` (insert, append, extend) something that
    names the tests folder."""
    for node in ast.walk(ast.parse(source)):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and node.func.attr in ("insert", "append", "extend") and ast.unparse(node.func.value) == "sys.path"
                and any(isinstance(arg, ast.Constant) and isinstance(arg.value, str) and "tests" in arg.value
                        for argument in node.args for arg in ast.walk(argument))):
            return True
    return False


def sharing_by_copy() -> list[str]:
    """Test files that import another module of tests/, and benchmarks that import one or put
    tests/ on sys.path: they share through microsim.testing instead."""
    local = {p.stem for p in (ROOT / "tests").glob("*.py")}
    found = [f"{p.relative_to(ROOT)} imports {name}" for p in sorted((ROOT / "tests").glob("test_*.py"))
             for name in cross_imports(p.read_text(), local - {p.stem})]
    for path in sorted((ROOT / "benchmarks").glob("*.py")):
        source = path.read_text()
        found += [f"{path.relative_to(ROOT)} imports {name}" for name in cross_imports(source, local)]
        found += [f"{path.relative_to(ROOT)} puts tests/ on sys.path"] if puts_tests_on_path(source) else []
    return found


def test_tests_and_benchmarks_share_through_microsim_testing():
    """No test file imports another module of tests/ (conftest's fixtures pytest gives the tests
    by name, unimported), and no benchmark imports one or puts tests/ on sys.path: what they
    share is in microsim.testing."""
    assert sharing_by_copy() == []


def test_the_sharing_check_sees_an_import_of_a_test_module_and_tests_on_the_path():
    """The check itself: an import of a module of tests/ (plain, from, inside a function,
    relative) and a sys.path entry naming tests/ are found; other imports and paths are not."""
    local = {"test_sweep", "conftest", "toy_estimator"}
    source = ("import os\nfrom test_sweep import same_table\nfrom microsim.testing import trace\n"
              "def f():\n    import toy_estimator\n    from . import helpers\n"
              "    from tests.refusals import SMALL_RUN\n")
    assert cross_imports(source, local) == ["test_sweep", "toy_estimator", ".", "tests.refusals"]
    assert puts_tests_on_path('import sys\nsys.path.insert(0, str(ROOT / "tests"))\n')
    assert not puts_tests_on_path('import sys\nsys.path.insert(0, str(Path(__file__).parent))\n')


def test_the_installed_packages_are_the_package_folders():
    """pyproject.toml's package list names every folder of microsim/ and geometry/ with an __init__."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    folders = {module_name(p) for folder in FOLDERS for p in (ROOT / folder).rglob("__init__.py")}
    assert set(project["packages"]) == folders
    assert project["package-dir"] == {"microsim.geometry": "geometry"}
    assert tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["name"] == "microsim-brdf"


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One cycle through each strongly connected component of more than one module."""
    index, low, stack, on_stack, found, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_no_import_circle_in_microsim_and_geometry():
    assert cycles(import_graph()) == []


def test_the_graph_sees_a_circle():
    """The check itself: a graph with a circle has one."""
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


#: the most arguments a function of microsim/ or geometry/ takes: more is a record to make
MAX_ARGUMENTS = 8


def long_signatures() -> list[str]:
    """Functions of the packages that take more than MAX_ARGUMENTS arguments (self and cls not
    counted; *args and **kwargs count one each)."""
    found = []
    for folder in FOLDERS:
        for path in sorted((ROOT / folder).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                    a = node.args
                    names = [x.arg for x in (*a.posonlyargs, *a.args)]
                    count = len(names) + len(a.kwonlyargs) + (a.vararg is not None) + (a.kwarg is not None)
                    count -= bool(names) and names[0] in ("self", "cls")
                    if count > MAX_ARGUMENTS:
                        found.append(f"{path.relative_to(ROOT)}:{node.lineno} {getattr(node, 'name', 'lambda')} ({count})")
    return found


def test_no_function_takes_more_than_8_arguments():
    assert long_signatures() == []


#: reads a table as a user would, then lists what that imported: numba, and microsim's modules
READ_A_TABLE = """
import sys
from microsim import tables
table = tables.load(sys.argv[1])
table.sensor.projected_solid_angle(), table.brdf, table.albedo, table.direction
print("numba" in sys.modules, " ".join(sorted(m for m in sys.modules if m.startswith("microsim"))))
"""


def test_reading_a_table_imports_no_kernel_module():
    """``microsim.tables.load`` and what a table holds (its sensor, its BRDF and albedo) import no
    numba, so no kernel module: the estimators' declarations are read, not their hooks."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", READ_A_TABLE, str(ROOT / "tests" / "data" / "table_format_1_0.h5")],
                          capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    numba, modules = done.stdout.split(" ", 1)
    assert numba == "False", modules
    assert not any(m.endswith(("_hooks", "sensor_kernels")) or ".integrators" in m or ".jit.dispatch" in m
                   for m in modules.split())
