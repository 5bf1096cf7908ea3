"""`microsim run` end to end: determinism across workers, bad input."""

import os
import subprocess
import sys
import tomllib
from pathlib import Path

import h5py
import pytest

from microsim.cli import main
from microsim.testing import trace
from microsim.testing.configs import SPHERES
from microsim.testing.refusals import assert_run_refused

PROVENANCE = {"created_utc", "wall_time_s"}


def datasets(path):
    out = {}
    with h5py.File(path, "r") as h5:
        h5.visititems(lambda name, obj: out.__setitem__(name, obj[()]) if isinstance(obj, h5py.Dataset) else None)
        attrs = {k: v for k, v in h5.attrs.items() if k not in PROVENANCE}
        scene = dict(h5["scene"].attrs)
    return out, attrs, scene


def test_tables_are_bit_identical_for_any_number_of_workers_and_threads(tmp_path):
    config = tmp_path / "small.toml"
    config.write_text(SPHERES)
    tables = {}
    for flags in (["--workers", "1"], ["--workers", "2"], ["--threads", "2"], ["--workers", "2", "--threads", "2"]):
        out = tmp_path / f"{'-'.join(flags)}.h5"
        done = subprocess.run([sys.executable, "-m", "microsim", "run", str(config), "--out", str(out), *flags],
                              capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
        assert f"table written to {out}" in done.stdout
        tables[out.name] = datasets(out)
    (d1, a1, s1), *others = tables.values()
    for d2, a2, s2 in others:
        assert d1.keys() == d2.keys() and a1.keys() == a2.keys() and s1 == s2
        for key in d1:
            assert d1[key].dtype == d2[key].dtype and d1[key].tobytes() == d2[key].tobytes(), key
        for key in a1:
            assert a1[key] == a2[key], key


@pytest.mark.parametrize("how", ["same path", "symlink", "sweep"])
def test_the_table_never_replaces_its_config(tmp_path, capsys, how):
    """`run c.toml --out c.toml`, with or without --force, through a symlink or as a sweep's
    point, is refused in one line: a table never replaces its config."""
    text = SPHERES.replace("paths = 20_000", "paths = 200")
    if how == "sweep":
        text = text.replace('name = "small"', 'name = "small"\n[sweep]\n"material.albedo" = [0.5]')
    config = tmp_path / ("albedo0.5.h5" if how == "sweep" else "c.toml")  # a sweep point's table name
    config.write_text(text)
    out = {"same path": config, "symlink": tmp_path / "link.h5", "sweep": tmp_path}[how]
    if how == "symlink":
        out.symlink_to(config)
    for force in ([], ["--force"]):
        assert main(["run", str(config), "--out", str(out), *force]) == 2
        err = capsys.readouterr().err.splitlines()
        assert len(err) == 1 and "is the config file" in err[0], err
        assert config.read_text() == text


@pytest.mark.parametrize("sweep", [False, True])
def test_a_table_into_a_folder_nothing_can_write_in_is_refused_in_one_line(tmp_path, capsys, sweep):
    """/sys takes no new file, even from root, whose permission bits say it may: the table (or a
    sweep's folder) is refused in one line before anything is traced, not with the traceback of
    the unit store's mkdir."""
    text = SPHERES.replace("paths = 20_000", "paths = 200")
    if sweep:
        text += '[sweep]\n"material.albedo" = [0.5, 0.6]\n'
    config = tmp_path / "c.toml"
    config.write_text(text)
    out = "/sys/points" if sweep else "/sys/table.h5"
    assert main(["run", str(config), "--out", out]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "--out" in lines[0] and "/sys" in lines[0] and "not writable" in lines[0], lines
    assert list(tmp_path.iterdir()) == [config]


def test_existing_table_is_not_overwritten_without_force(tmp_path, capsys):
    config = tmp_path / "small.toml"
    config.write_text(SPHERES.replace("paths = 20_000", "paths = 200"))
    out = tmp_path / "t.h5"
    out.write_bytes(b"precious")
    assert main(["run", str(config), "--out", str(out)]) == 2
    assert out.read_bytes() == b"precious"
    assert "--force" in capsys.readouterr().err
    assert main(["run", str(config), "--out", str(out), "--force"]) == 0
    assert h5py.is_hdf5(out)


def edit(old, new):
    return lambda text: text.replace(old, new)


BAD_CONFIGS = {
    "volume fraction out of range": (edit("volume_fraction = 0.3", "volume_fraction = 1.5"), "scene.volume_fraction"),
    # an unknown [scene] key: tests/test_scene_kinds.py, for every scene kind
    "unknown scene kind": (edit('kind = "poisson_spheres"', 'kind = "cubes"'), "scene.kind"),
    "unknown material kind": (edit('kind = "lambert"', 'kind = "velvet"'), "material.kind"),
    "wrong type": (edit("volume_fraction = 0.3", 'volume_fraction = "dense"'), "scene.volume_fraction"),
    "boolean for a number": (edit("albedo = 0.8", "albedo = true"), "material.albedo"),
    "broken TOML": (edit("[material]", "[material"), "TOML"),
    "missing material parameter": (edit("albedo = 0.8\n", ""), "material.albedo"),
    "missing conductor k": (edit('kind = "lambert"\nalbedo = 0.8', 'kind = "conductor"\neta = 1.2'), "material.k"),
    "incidence out of range": (edit("[0.0, 60.0]", "[0.0, 95.0]"), "illumination.theta_i_deg"),
    "negative paths": (edit("paths = 20_000", "paths = -5"), "run.paths"),
    "fractional paths": (edit("paths = 20_000", "paths = 2.5"), "run.paths"),
    "unknown section": (lambda text: text + "\n[extra]\nfoo = 1\n", "extra"),
    "missing run section": (edit("[run]\npaths = 20_000\nrealizations = 4\nseed = 5\n", ""), "run"),
    "one realization": (edit("realizations = 4", "realizations = 1"), "run.realizations"),
    "unknown backend": (edit("seed = 5", 'seed = 5\nbackend = "gpu"'), "run.backend"),
    "name with a control character": (edit('name = "small"', 'name = "sm\\u0000all"'), "name"),
    "base under a plane": (lambda text: text.replace('kind = "poisson_spheres"\nvolume_fraction = 0.3\ntile = 16.0\ndepth = 8.0',
                                                     'kind = "plane"') + '\n[base]\nkind = "absorber"\n', "base"),
    # configs that can only give meaningless tables
    "fewer paths than realizations": (edit("paths = 20_000", "paths = 3"), "run.paths = 3: fewer than run.realizations"),
    "realizations of no path": (edit("realizations = 4", "realizations = 100000"), "run.paths = 20,000: fewer than"),
    "a slab of 4 spheres": (edit("tile = 16.0\ndepth = 8.0", "tile = 4.0\ndepth = 3.0"),
                            "scene.tile = 4, scene.depth = 3: 4.09 spheres expected a realization"),
    "a tile of 0.22 grains": (edit('kind = "poisson_spheres"\nvolume_fraction = 0.3\ntile = 16.0\ndepth = 8.0',
                                   'kind = "micrograins"\ntau0 = 0.5\nbeta = 1.0\ntile = 1.0'),
                              "scene.tile = 1: 0.221 grains expected a tile (tau0 0.5); accepted: at least 10"),
}


@pytest.mark.parametrize("case", sorted(BAD_CONFIGS))
def test_bad_config_gives_one_line_naming_the_key_and_exit_2(case, tmp_path, capsys):
    change, key = BAD_CONFIGS[case]
    assert_run_refused(change(SPHERES), key, tmp_path, capsys)


def test_a_config_that_is_not_utf8_gives_one_line(tmp_path, capsys):
    config = tmp_path / "latin1.toml"
    config.write_bytes(SPHERES.replace('name = "small"', 'name = "caf\xe9"').encode("latin-1"))
    assert main(["run", str(config), "--out", str(tmp_path / "t.h5")]) == 2
    err = capsys.readouterr().err
    assert err.splitlines() == [f"microsim: error: config file {str(config)!r} is not UTF-8 text (byte 0xe9 at "
                                f"offset 12); TOML files are UTF-8"]  # after a newline and name = "caf
    assert list(tmp_path.iterdir()) == [config]


@pytest.mark.parametrize("name", ["../escaped", "/tmp/absolute", "sub/dir"])
def test_the_default_table_is_named_from_the_config_file_in_the_current_directory(name, tmp_path, monkeypatch):
    """``name`` is a label stored in the table, never a path."""
    here = tmp_path / "here"
    here.mkdir()
    config = tmp_path / "small.toml"
    config.write_text(SPHERES.replace('name = "small"', f'name = "{name}"').replace("paths = 20_000", "paths = 400"))
    monkeypatch.chdir(here)
    escaped = [Path(here, name + ".h5").resolve(), Path(here, name).resolve().parent / "small.h5"]
    existed = [path.exists() for path in escaped]
    assert main(["run", str(config)]) == 0
    assert [p.name for p in here.iterdir()] == ["small.h5"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["here", "small.toml"]
    assert [path.exists() for path in escaped] == existed  # nothing written where the name points
    with h5py.File(here / "small.h5") as h5:
        assert tomllib.loads(h5.attrs["config_toml"])["name"] == name


@pytest.mark.parametrize("argv, key", [
    (["run", "missing.toml"], "missing.toml"),
    (["run", "{config}", "--workers", "0"], "--workers"),
    (["run", "{config}", "--threads", "0"], "--threads"),
    (["run", "{config}", "--threads", "100000"], "--threads"),
    (["run", "{config}", "--backend", "gpu"], "--backend"),
    (["run", "{config}", "--paths", "many"], "--paths"),
    (["run", "{config}", "--seed", "-1"], "--seed"),
    (["run", "{config}", "--out", "/no/such/dir/t.h5"], "--out"),
    (["frobnicate"], "frobnicate"),
])
def test_bad_command_line_gives_one_line_and_exit_2(argv, key, tmp_path, capsys):
    config = tmp_path / "ok.toml"
    config.write_text(SPHERES)
    assert main([a.format(config=config) for a in argv]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and key in lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ok.toml"]


def test_console_script_exit_status(tmp_path):
    script = Path(sys.executable).parent / "microsim"  # installed next to the interpreter running the tests
    done = subprocess.run([str(script), "run", str(tmp_path / "nope.toml")], capture_output=True, text=True)
    assert done.returncode == 2 and done.stderr.count("\n") == 1 and "Traceback" not in done.stderr


def test_shipped_configs_validate():
    from microsim import config

    runs = Path(__file__).parent.parent / "runs"
    shipped = sorted(runs.glob("*.toml"))
    assert {"plane.toml", "spheres_phi010.toml", "spheres_phi030.toml", "spheres_phi060.toml"} <= {p.name for p in shipped}
    for path in shipped:
        config.load(path)


def test_a_table_that_appears_while_the_run_traces_is_not_replaced(tmp_path, capsys, monkeypatch):
    """The overwrite check holds at the final rename, atomically, not only at start-up: the file
    that appeared is kept, and so is the run's table, under another name."""
    from microsim.run import runner

    config = tmp_path / "small.toml"
    config.write_text(SPHERES.replace("paths = 20_000", "paths = 400"))
    out = tmp_path / "t.h5"
    real_run = runner.Run.trace

    def run_while_someone_writes_out(*args, **kwargs):
        results = real_run(*args, **kwargs)
        out.write_bytes(b"written meanwhile")
        return results

    monkeypatch.setattr(runner.Run, "trace", run_while_someone_writes_out)
    assert main(["run", str(config), "--out", str(out)]) == 2
    err = capsys.readouterr().err.splitlines()
    kept = tmp_path / f"t.{os.getpid()}.h5"
    assert err == [f"microsim: error: --out: {out} appeared while the run traced; this run's table was kept as "
                   f"{kept} (pass --force to overwrite)"]
    assert out.read_bytes() == b"written meanwhile" and h5py.is_hdf5(kept)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["small.toml", "t.h5", kept.name])
    out.unlink()
    assert main(["run", str(config), "--out", str(out), "--force"]) == 0 and h5py.is_hdf5(out)


def test_two_runs_to_the_same_new_path_do_not_both_succeed(tmp_path):
    from microsim import config as config_module
    from microsim import tables

    path = tmp_path / "c.toml"
    path.write_text(SPHERES.replace("paths = 20_000", "paths = 400"))
    cfg = config_module.load(path)
    result = trace(cfg)
    out = tmp_path / "t.h5"
    tables.write(out, result, cfg)
    first = out.read_bytes()
    with pytest.raises(tables.TableExists):
        tables.write(out, result, cfg)
    assert out.read_bytes() == first


def _raise_unpicklable(*args):
    import threading

    raise RuntimeError("no pickle for this", threading.Lock())


def _exit_quietly(*args):
    os._exit(0)


@pytest.mark.parametrize("failure, line", [
    (_raise_unpicklable, "microsim: error: a worker failed: RuntimeError: ('no pickle for this', <unlocked "),
    (_exit_quietly, "microsim: error: a worker process died (exit code 0)"),
])
def test_a_failing_worker_ends_the_run_in_one_line(failure, line, tmp_path, capsys, monkeypatch):
    """A worker whose exception does not pickle, or that exits without its units, must not leave
    the main process waiting (it did, for ever)."""
    from microsim.run import executors

    config = tmp_path / "small.toml"
    config.write_text(SPHERES.replace("paths = 20_000", "paths = 400"))
    monkeypatch.setattr(executors, "trace_units", failure)  # the workers are forked from this process
    assert main(["run", str(config), "--out", str(tmp_path / "t.h5"), "--workers", "2"]) == 1
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(line)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["small.toml"]


@pytest.mark.parametrize("count", [0, 257, 1_000_000])
def test_a_list_of_the_wrong_length_names_the_limit_and_quotes_an_excerpt(count, tmp_path, capsys):
    """A list of the wrong length (none, 257, a million incidences) is refused in one short line
    that names the limit, 256, and the count, not with the list echoed."""
    config = tmp_path / "bad.toml"
    config.write_text(SPHERES.replace("theta_i_deg = [0.0, 60.0]", f"theta_i_deg = {[10.0] * count}"))
    assert main(["run", str(config), "--out", str(tmp_path / "bad.h5")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "illumination.theta_i_deg" in lines[0], lines
    assert "1 to 256" in lines[0] and f"{count:,} items" in lines[0] and len(lines[0]) < 250, lines[0]


@pytest.mark.parametrize("argv", [["--help"], ["run", "--help"], ["compare", "--help"], ["run"], ["fit", "x.h5"],
                                  ["run", "c.toml", "--workers", "0"], ["export", "--help"], ["render", "--help"],
                                  ["export", "x.h5", "--format", "obj"]],
                         ids=["--help", "run --help", "compare --help", "no config", "no --model", "--workers 0",
                              "export --help", "render --help", "export --format obj"])
def test_help_and_argument_errors_load_none_of_the_work(argv):
    """Help and usage errors load none of the work's modules (numba, h5py, pydantic, scipy, the
    generators, trimesh): importing numba alone costs seconds of start-up. compare's and fit's
    take their flags (--points, --retro) from the estimators' declarations, whose config keys
    are pydantic's (20 ms): they load pydantic, and none of the others."""
    code = ("import sys\nfrom microsim.cli import main\nstatus = main(sys.argv[1:])\n"
            "print(status, sorted(m for m in ('numba', 'h5py', 'pydantic', 'scipy', 'geometry', 'trimesh') "
            "if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True)
    status, loaded = done.stdout.splitlines()[-1].split(" ", 1)
    declarations = "['pydantic']" if argv[0] in ("compare", "fit") else "[]"
    assert (status, loaded) == ("0" if "--help" in argv else "2", declarations), done.stderr
