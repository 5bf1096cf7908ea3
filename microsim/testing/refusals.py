"""Bad input refused in one line (docs/conventions.md §9).

Contract: :func:`assert_refused` runs the command line (``microsim.cli.main``, what ``python -m
microsim`` runs) with ``argv`` and asserts exit status 2, exactly one line on stderr holding
every given word, no traceback and nothing on stdout; it returns the line.
:func:`assert_run_refused` is that for ``microsim run`` of a config's text, and also asserts that
nothing was written: the folder holds the config alone. ``capsys`` is pytest's fixture of that
name (what captured the streams).
"""

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


def assert_refused(argv, capsys, *words: str) -> str:
    """``microsim`` with ``argv`` exits with 2 and prints one line, holding every string of
    ``words``, on stderr, no traceback, and nothing on stdout; the line."""
    assert main([str(arg) for arg in argv]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and all(word in lines[0] for word in words) and "Traceback" not in captured.err, \
        captured.err
    assert captured.out == "", captured.out
    return lines[0]


def assert_run_refused(text: str, key: str, tmp_path, capsys, *also: str, out: str = "bad.h5") -> str:
    """`microsim run` on the config ``text`` (written to ``tmp_path``/bad.toml, the table asked at
    ``tmp_path``/``out``) exits with 2, prints one line naming ``key`` (and holding every string
    of ``also``) on stderr and nothing on stdout, and leaves nothing but the config in
    ``tmp_path``; the line."""
    path = tmp_path / "bad.toml"
    path.write_text(text)
    line = assert_refused(["run", path, "--out", tmp_path / out], capsys, key, *also)
    assert list(tmp_path.iterdir()) == [path]
    return line
