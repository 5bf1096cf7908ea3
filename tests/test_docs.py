"""The documentation: the site builds with ``mkdocs build --strict`` (no broken link, anchor or
reference), names every CLI option, config key, model and table dataset, and its getting-started
commands run as written (at fewer paths); the README's links resolve inside the repository, and
no file of the project refers to a path outside it, nor to its own issues by number."""

import html
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from microsim.cli import main

ROOT = Path(__file__).resolve().parent.parent
#: the getting-started commands run at this many paths an incidence
FEW_PATHS = "20000"


@pytest.fixture(scope="module")
def site_text(tmp_path_factory) -> str:
    """The text of every page of the site, built with --strict."""
    site = tmp_path_factory.mktemp("site")
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)], cwd=ROOT,
                          capture_output=True, text=True, env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert done.returncode == 0, done.stderr
    pages = sorted(site.rglob("index.html"))
    assert len(pages) > 30
    return "\n".join(html.unescape(re.sub(r"<[^>]+>", " ", page.read_text())) for page in pages)


def test_every_cli_option_config_key_model_and_dataset_is_in_the_docs(site_text):
    from microsim import cli, config, models, tables
    from microsim.app import sweep
    from microsim.core import table_layout

    words = set(re.findall(r"[^\s,;()\[\]]+", site_text))
    missing = [f"microsim {name}" for name in cli.cli.commands if f"microsim {name}" not in site_text]
    for name, command in cli.cli.commands.items():
        missing += [f"{name} {opt}" for param in command.params for opt in param.opts
                    if param.param_type_name == "option" and opt not in words]
    missing += [key.name for key in config.keys() + sweep.keys() if key.name not in site_text]
    missing += [name for name in models.available() if name not in words]
    missing += [d.name for d in tables.DATASETS if d.name not in words]
    missing += [a.name for a in tables.ATTRIBUTES if a.name not in words]
    assert missing == []


def test_the_check_sees_what_is_missing(site_text):
    """The check itself: a name the docs do not have is missing."""
    assert "--no-such-option" not in set(re.findall(r"[^\s,;()\[\]]+", site_text))


def test_the_home_page_lists_every_scene_kind_and_the_frames_are_stated_once():
    """The home page's table of scenes links every registered kind's page; the pages that say in
    which frame a table's cells lie say the scene's (the cells' azimuths are phi_o itself), and
    none says the cells are in relative azimuth."""
    from microsim.geometry import SCENES

    home = (ROOT / "docs" / "index.md").read_text()
    table = home.split("## What it traces")[1].split("\n\n")[1]
    assert sorted(re.findall(r"\(guide/scenes/(\w+)\.md\)", table)) == sorted(SCENES)
    for page in ("conventions.md", "guide/config.md", "reference/table-format.md", "guide/points.md"):
        text = " ".join((ROOT / "docs" / page).read_text().split())
        assert "scene's frame" in text or "the scene's" in text, page
        assert not re.search(r"cells?[^.]{0,40}(in|are|lie in) (the )?relative azimuth", text), page


def getting_started_commands() -> list[str]:
    page = (ROOT / "docs" / "getting-started.md").read_text()
    blocks = re.findall(r"```bash\n(.*?)```", page, re.S)
    return [line.strip() for block in blocks for line in block.splitlines() if line.strip()]


def test_getting_started_runs_as_written(tmp_path, monkeypatch, capsys):
    """Install, a first table, compare, fit: every command of the page, in a directory with the
    repository's runs/, at FEW_PATHS paths an incidence (the install is what .ci/run does)."""
    commands = getting_started_commands()
    install = [c for c in commands if not c.startswith("microsim ")]
    assert install == ["python3 -m venv .venv && . .venv/bin/activate && pip install -e ."]
    runs = [c for c in commands if c.startswith("microsim run ")]
    assert runs and all(re.search(r"--paths \d+", c) for c in runs)
    (tmp_path / "runs").symlink_to(ROOT / "runs")
    monkeypatch.chdir(tmp_path)
    for command in commands[len(install):]:
        argv = shlex.split(re.sub(r"--paths \d+", f"--paths {FEW_PATHS}", command))[1:]
        assert main(argv) == 0, (command, capsys.readouterr().err)
    assert sorted(p.name for p in tmp_path.glob("*.h5")) == ["halfspace_lambert_sphere.h5", "spheres_phi030.h5"]
    assert list((tmp_path / "figures").glob("*.png"))


LINK = re.compile(r"\]\(([^)\s]+)\)")


def test_the_readme_s_links_resolve_inside_the_repository():
    targets = LINK.findall((ROOT / "README.md").read_text())
    assert len(targets) > 10
    for target in targets:
        assert not re.match(r"[a-z]+:", target), f"README links outside the repository: {target}"
        path = (ROOT / target.split("#")[0]).resolve()
        assert path.is_file() and ROOT in path.parents, target


#: what a reference to a file outside the repository looks like (assembled, not to match itself)
OUTSIDE = re.compile("|".join([r"\.\./shared", "CONVEN" + r"TIONS \d", r"CONVEN" + r"TIONS\.md",
                               r"(lambert_sphere_brdf|interfaced_lambertian_microfacets|micrograin_bsdf_anisotropic|"
                               r"vmf_diffuse_brdf)\.t" + "xt"]))


def test_no_file_of_the_project_refers_to_a_path_outside_it():
    files = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                           capture_output=True, text=True, check=True).stdout.split()
    found = []
    for name in files:
        path = ROOT / name
        if path.suffix in {".png", ".h5", ".npz", ".npy"} or not path.is_file():
            continue
        for number, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
            if OUTSIDE.search(line):
                found.append(f"{name}:{number}: {line.strip()[:80]}")
    assert found == []


#: a reference to this project's history by number: the word issue or defect, a number
HISTORY_TAG = re.compile(r"\b(issue|defect)s? ?#?[0-9]+", re.I)
#: what may precede a tag that cites another project's tracker: its name (a few words before,
#: within the sentence) or a URL
EXTERNAL = re.compile(r"\b(numba|embreex?|mitsuba|drjit|llvm|trimesh|h5py|scipy|pydantic|numpy|dask|hypothesis|"
                      r"mkdocs|xarray|click|rich)\b('s)?[^.;:]{0,30}$|https?://\S*$", re.I)
#: where the project states its claims (CHANGELOG.md holds the history, and is not scanned)
CLAIM_PLACES = ("microsim/", "geometry/", "tests/", "benchmarks/", "docs/", "runs/", "README.md")


def history_tags(text: str) -> list[tuple[int, str]]:
    """(line number, line) of each line that refers to this project's issues or defects by number."""
    return [(number, line) for number, line in enumerate(text.splitlines(), 1)
            if any(not EXTERNAL.search(line[:tag.start()]) for tag in HISTORY_TAG.finditer(line))]


def test_no_file_tells_history_by_issue_number():
    """Code, tests, benchmarks and docs state claims, not history: no "issue N" or "defect N" of
    this project (another project's, cited by its name or a URL, is allowed)."""
    files = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard", *CLAIM_PLACES],
                           cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    found = []
    for name in files:
        path = ROOT / name
        if path.suffix in {".png", ".h5", ".npz", ".npy", ".ply"} or not path.is_file():
            continue
        found += [f"{name}:{number}: {line.strip()[:80]}"
                  for number, line in history_tags(path.read_text(errors="replace"))]
    assert len(files) > 100
    assert found == []


def test_the_history_check_sees_a_tag_and_allows_another_project_s():
    """The check itself (the tags assembled, so that this file holds none)."""
    tag = "Iss" + "ue 24, def" + "ect 14"
    assert history_tags(f'"""{tag}: a run compiled twice."""\n# see is' + "sue #7") == [
        (1, f'"""{tag}: a run compiled twice."""'), (2, "# see is" + "sue #7")]
    assert history_tags("(numba is" + "sue #8989: quadratic copies)") == []
    assert history_tags("https://github.com/numba/numba/pull/1 is" + "sue 3") == []
    assert history_tags("numba compiles. Is" + "sue 3") != []


def unnamed_modules(page: str) -> list[str]:
    """Modules of microsim/ and geometry/ that the architecture page does not name: a module by
    its file name (``name.py``), a package by its folder (``name/``)."""
    missing = []
    for folder in ("microsim", "geometry"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            named = f"{path.parent.name}/" if path.name == "__init__.py" else path.name
            if f"`{named}" not in page and f"{named}`" not in page and f" {named}" not in page:
                missing.append(str(path.relative_to(ROOT)))
    return missing


def test_the_architecture_page_names_every_module_and_the_readme_every_layer():
    page = (ROOT / "docs" / "developer" / "architecture.md").read_text()
    assert unnamed_modules(page) == []
    assert unnamed_modules(page.replace("`fresnel.py`", "")) == ["microsim/physics/fresnel.py"]
    readme = (ROOT / "README.md").read_text()
    layers = sorted(p.parent.name for p in (ROOT / "microsim").glob("*/__init__.py"))
    assert [layer for layer in layers if f"`{layer}/`" not in readme] == []


def unmapped_modules(page: str) -> list[str]:
    """Modules of microsim/ and geometry/ without a row in the testing page's module-to-test map,
    and test files the map names that tests/ does not hold."""
    section = page.split("\n## Module-to-test map\n", 1)[1].split("\n## ", 1)[0]
    rows = re.findall(r"^\| `([\w/.]+\.py)` \|(.*)\|$", section, flags=re.M)
    mapped = {module for module, _ in rows}
    missing = [str(path.relative_to(ROOT)) for folder in ("microsim", "geometry")
               for path in sorted((ROOT / folder).rglob("*.py")) if str(path.relative_to(ROOT)) not in mapped]
    named = {name for _, tests in rows for name in re.findall(r"`((?:test_\w+|conftest|toy_estimator)\.py)`", tests)}
    return missing + sorted(f"tests/{name}" for name in named if not (ROOT / "tests" / name).is_file())


def test_the_testing_page_maps_every_module_to_its_tests():
    page = (ROOT / "docs" / "developer" / "testing.md").read_text()
    assert unmapped_modules(page) == []
    assert unmapped_modules(page.replace("| `microsim/physics/fresnel.py` |", "| fresnel |")) == \
        ["microsim/physics/fresnel.py"]
    assert unmapped_modules(page.replace("`test_sensor.py`", "`test_no_such_file.py`")) == \
        ["tests/test_no_such_file.py"]

