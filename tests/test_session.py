"""A run from Python (microsim.app.session) has every guarantee of the command line: a run, a run
killed by SIGKILL and resumed, and a sweep give tables bit-identical to ``microsim run``'s; bad
input is one line (RunRefused) with nothing written; progress and sweep points are told."""

import csv
import subprocess
import sys

import pytest

from microsim import tables
from microsim.app import session
from microsim.app.progress import Progress
from microsim.cli import main
from microsim.testing import trace_albedos
from microsim.testing.configs import GRID, SPHERES
from microsim.testing.interruptions import RUN, UNITS, kill_at_half, saved
from microsim.testing.tables import same_table


def test_a_run_from_python_is_the_command_line_s_table(tmp_path, capsys):
    """The command line runs the session too: both are also checked against the runner's
    tables written without it."""
    from microsim import config as config_module

    config = tmp_path / "small.toml"
    config.write_text(SPHERES)
    outcome = session.run(config, tmp_path / "python.h5", workers=2)
    assert main(["run", str(config), "--out", str(tmp_path / "cli.h5")]) == 0
    validated = config_module.load(config)
    tables.write(tmp_path / "runner.h5", trace_albedos(validated)[0], validated)
    assert outcome.tables == [tmp_path / "python.h5"]
    assert same_table(tmp_path / "python.h5", tmp_path / "cli.h5")
    assert same_table(tmp_path / "python.h5", tmp_path / "runner.h5")
    def lines(text):  # but for the time, where it ran, and compiling (the first run of a process compiles)
        return [line.split(" | ")[0] for line in text[:-1] if not line.startswith("compiled the tracer")]

    report = outcome.report()
    assert lines(report) == lines(capsys.readouterr().out.splitlines())
    assert report[-1] == f"table written to {tmp_path / 'python.h5'}"


def test_a_config_as_a_dictionary_is_its_file(tmp_path):
    import tomllib

    config = tmp_path / "small.toml"
    config.write_text(SPHERES)
    session.run(tomllib.loads(SPHERES), tmp_path / "data.h5", paths=4000)
    session.run(config, tmp_path / "file.h5", paths=4000)
    assert same_table(tmp_path / "data.h5", tmp_path / "file.h5")


class Heard(Progress):
    def __init__(self):
        self.events = []

    def start(self, plan, compile_seconds):
        self.events.append("start")

    def tracing(self, watch):
        self.events.append("tracing")

    def unit(self, unit, paths, from_store):
        self.events.append(unit)

    def stop(self):
        self.events.append("stop")


def test_a_sweep_from_python_is_the_command_line_s(tmp_path):
    config = tmp_path / "grid.toml"
    config.write_text(GRID)
    progress, points = Heard(), []
    outcome = session.run(config, tmp_path / "python", progress=progress, on_point=points.append)
    assert main(["run", str(config), "--out", str(tmp_path / "cli")]) == 0
    names = sorted(p.name for p in (tmp_path / "cli").glob("*.h5"))
    assert len(names) == 6 and names == sorted(p.table.name for p in outcome.points)
    for name in names:
        assert same_table(tmp_path / "python" / name, tmp_path / "cli" / name), name
    assert [p.table for p in points] == [p.table for p in outcome.points]
    with open(outcome.index) as a, open(tmp_path / "cli" / "index.csv") as b:
        rows = list(csv.DictReader(a))
        assert rows == list(csv.DictReader(b))
    for row in rows:  # each point done, with its table's albedos
        albedo = tables.load(tmp_path / "python" / row["table"]).albedo
        assert row["status"] == "done" and [row["albedo_theta0"], row["albedo_theta60"]] == [f"{a:.6g}" for a in albedo]
    units = [(r, i) for r in range(2) for i in range(2)]
    assert progress.events == 6 * ["start", "tracing", *units, "stop"]


@pytest.mark.slow
def test_a_python_run_killed_by_sigkill_resumes_bit_identical_to_the_command_line(tmp_path):
    """The run is killed in a process of its own, from Python as a script would run it, and
    resumed from Python in this one."""
    config = tmp_path / "run.toml"
    config.write_text(RUN)
    out = tmp_path / "killed.h5"
    script = f"from microsim.app import session; session.run({str(config)!r}, {str(out)!r}, workers=2)"
    kill_at_half(subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                  text=True), out)
    kept = saved(out)
    assert UNITS // 2 <= kept < UNITS
    with pytest.raises(session.RunRefused, match="resume"):  # kept units are not discarded unasked
        session.run(config, out)
    outcome = session.run(config, out, resume=True)
    assert (outcome.results[0].units_resumed, outcome.results[0].units_traced) == (kept, UNITS - kept)
    assert main(["run", str(config), "--out", str(tmp_path / "cli.h5"), "--workers", "2"]) == 0
    assert same_table(out, tmp_path / "cli.h5")


@pytest.mark.parametrize("options, message", [
    ({"workers": 0}, "--workers 0: expected an integer in [1, 256]"),
    ({"executor": "slurm"}, "--executor 'slurm': accepted: local, dask"),
    ({"scheduler": "tcp://h:1"}, "--scheduler: a Dask scheduler's address is taken with --executor dask only"),
    ({"paths": 0}, "run.paths"),
])
def test_bad_options_are_one_line_and_write_nothing(tmp_path, options, message):
    config = tmp_path / "small.toml"
    config.write_text(SPHERES)
    with pytest.raises(session.RunRefused) as refused:
        session.run(config, tmp_path / "t.h5", **options)
    assert message in str(refused.value) and "\n" not in str(refused.value)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["small.toml"]


def test_a_dictionary_needs_out_and_a_table_is_not_overwritten_unasked(tmp_path):
    import tomllib

    with pytest.raises(session.RunRefused, match="^out: "):
        session.run(tomllib.loads(SPHERES))
    table = tmp_path / "t.h5"
    table.write_bytes(b"kept")
    with pytest.raises(session.RunRefused, match=r"exists \(pass --force"):
        session.run(tomllib.loads(SPHERES), table)
    assert table.read_bytes() == b"kept"
