"""Bad input (docs/conventions.md §9): a config that `microsim run` must refuse in one line, exit 2, writing nothing."""

from microsim.cli import main

#: what follows a scene table in the small configs of the bad-input tests
SMALL_RUN = """[material]
kind = "lambert"
albedo = 0.8
[illumination]
theta_i_deg = [30.0]
[sensor]
cells = 100
[run]
paths = 1000
realizations = 2
"""


def small_config(scene: str) -> str:
    """A config of the ``[scene]`` table ``scene`` (TOML lines) and SMALL_RUN."""
    return "[scene]\n" + scene.strip() + "\n" + SMALL_RUN


def assert_run_refused(text: str, key: str, tmp_path, capsys, *also: str) -> None:
    """`microsim run` on the config ``text`` exits with 2, prints one line naming ``key`` (and
    holding every string of ``also``) on stderr and nothing on stdout, and leaves nothing but the
    config in ``tmp_path``."""
    path = tmp_path / "bad.toml"
    path.write_text(text)
    assert main(["run", str(path), "--out", str(tmp_path / "bad.h5")]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and all(part in lines[0] for part in (key, *also)) and "Traceback" not in captured.err, \
        captured.err
    assert captured.out == "" and list(tmp_path.iterdir()) == [path]
