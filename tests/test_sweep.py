"""Sweeps (docs/conventions.md §4, microsim/app/sweep.py): one table per point, each the same as the
point run alone, bit for bit; an index; bad sweeps refused in one line before anything is written."""

import csv

import pytest

from microsim import config, tables
from microsim.app.sweep import INDEX
from microsim.cli import main
from microsim.testing.configs import GRID
from microsim.testing.configs import SWEEP_BASE as BASE
from microsim.testing.refusals import assert_run_refused
from microsim.testing.tables import same_table


def test_grid_sweep_writes_every_point_as_if_run_alone_and_an_index(tmp_path, capsys):
    path = tmp_path / "grid.toml"
    path.write_text(GRID)
    assert main(["run", str(path), "--out", str(tmp_path / "grid")]) == 0
    with open(tmp_path / "grid" / INDEX) as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 6 and {r["status"] for r in rows} == {"done"}
    assert sorted(p.name for p in (tmp_path / "grid").iterdir()) == sorted([INDEX] + [r["table"] for r in rows])
    for row in rows:
        alone = tmp_path / f"{row['point']}.toml"
        alone.write_text(BASE.replace("volume_fraction = 0.2", f"volume_fraction = {row['scene.volume_fraction']}")
                         .replace("albedo = 0.8", f"albedo = {row['material.albedo']}"))
        assert main(["run", str(alone), "--out", str(tmp_path / f"{row['point']}.h5")]) == 0
        assert same_table(tmp_path / "grid" / row["table"], tmp_path / f"{row['point']}.h5"), row["point"]
        table = tables.load(tmp_path / "grid" / row["table"])
        assert float(row["albedo_theta0"]) == pytest.approx(table.albedo[0], rel=1e-5)


def test_zip_sweep_pairs_the_values(tmp_path, capsys):
    path = tmp_path / "zip.toml"
    path.write_text(BASE + '[sweep]\nmode = "zip"\n"scene.volume_fraction" = [0.1, 0.3]\n"run.seed" = [5, 6]\n')
    assert main(["run", str(path), "--out", str(tmp_path / "zip")]) == 0
    with open(tmp_path / "zip" / INDEX) as handle:
        rows = list(csv.DictReader(handle))
    assert [(r["scene.volume_fraction"], r["run.seed"]) for r in rows] == [("0.1", "5"), ("0.3", "6")]
    assert tables.load(tmp_path / "zip" / rows[1]["table"]).attrs["seed"] == 6


@pytest.mark.parametrize("sweep, key", [
    ('"scene.volume_fractio" = [0.1]', "scene.volume_fractio"),
    ('"scene.volume_fraction" = [0.1, 0.95]', "scene.volume_fraction"),
    ('"scene.volume_fraction" = []', "sweep.scene.volume_fraction"),
    ('"scene.volume_fraction" = 0.1', "sweep.scene.volume_fraction"),
    ('mode = "cross"\n"scene.volume_fraction" = [0.1]', "sweep.mode"),
    ('mode = "zip"\n"scene.volume_fraction" = [0.1, 0.2]\n"material.albedo" = [0.5]', "mode zip"),
    ('"scene.volume_fraction" = [0.1, 0.1]', "same values"),
    ('"material.albedo.x" = [0.5]', "material.albedo"),
])
def test_bad_sweeps_are_refused_in_one_line_writing_nothing(sweep, key, tmp_path, capsys):
    assert_run_refused(BASE + "[sweep]\n" + sweep + "\n", key, tmp_path, capsys, out="out")


def test_a_sweep_does_not_write_into_a_directory_that_holds_files(tmp_path, capsys):
    path = tmp_path / "grid.toml"
    path.write_text(GRID)
    (tmp_path / "grid").mkdir()
    (tmp_path / "grid" / "keep.h5").write_text("not ours")
    assert main(["run", str(path), "--out", str(tmp_path / "grid")]) == 2
    assert "--force" in capsys.readouterr().err
    assert [p.name for p in (tmp_path / "grid").iterdir()] == ["keep.h5"]


def test_overrides_of_any_depth():
    data = {"scene": {"kind": "plane"}}
    config.set_dotted(data, "name", "top")
    config.set_dotted(data, "a.b.c", 1)
    config.set_dotted(data, "scene.kind", "plane")
    assert data == {"scene": {"kind": "plane"}, "name": "top", "a": {"b": {"c": 1}}}
    with pytest.raises(config.ConfigError, match="scene.kind is a value"):
        config.set_dotted(data, "scene.kind.x", 1)


def test_a_resumed_sweep_keeps_its_finished_tables_and_traces_the_rest(tmp_path, capsys):
    """As after a crash in the fourth point: three tables are there, the others are not."""
    path = tmp_path / "grid.toml"
    path.write_text(GRID)
    out, first = tmp_path / "grid", tmp_path / "first"
    assert main(["run", str(path), "--out", str(first)]) == 0
    with open(first / INDEX) as handle:
        rows = list(csv.DictReader(handle))
    out.mkdir()
    for row in rows[:3]:
        (out / row["table"]).write_bytes((first / row["table"]).read_bytes())
    capsys.readouterr()
    assert main(["run", str(path), "--out", str(out), "--resume"]) == 0
    lines = capsys.readouterr().out.splitlines()
    kept = [line.split(":")[0] for line in lines if line.endswith("kept (its table was finished)")]
    assert kept == [row["point"] for row in rows[:3]]
    for row in rows:
        same_bytes = (out / row["table"]).read_bytes() == (first / row["table"]).read_bytes()
        assert same_bytes == (row in rows[:3])  # kept as they were, or traced again (a new date)
        assert same_table(out / row["table"], first / row["table"])
    with open(out / INDEX) as handle:
        assert [r["status"] for r in csv.DictReader(handle)] == ["done"] * 6


def test_a_resumed_sweep_refuses_a_table_of_another_config(tmp_path, capsys):
    path = tmp_path / "grid.toml"
    path.write_text(GRID)
    out = tmp_path / "grid"
    assert main(["run", str(path), "--out", str(out)]) == 0
    path.write_text(GRID.replace("seed = 3", "seed = 4"))
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    capsys.readouterr()
    assert main(["run", str(path), "--out", str(out), "--resume"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "is not the table of sweep point" in err[0] and "--force" in err[0]
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
