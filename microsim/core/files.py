"""Files written whole or not at all, where they may be written.

:func:`atomic` writes under a temporary name beside the target and renames it when complete
(what the exporters and the renders write; the tables have their own rule,
:func:`microsim.tables.write`, which never replaces a file that appeared meanwhile); a stop signal
that ends the process at once removes the temporary first (:func:`microsim.core.interrupts.remove_on_stop`).
:func:`refusal` is the one check of an output before the work: it does not exist (or ``force``),
it is none of the command's inputs (with or without ``force``), and its folder exists and takes a
new file (tried, not inferred from permission bits: root passes those on a folder nothing can
write in, as /sys).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

from microsim.core.interrupts import remove_on_stop


@contextlib.contextmanager
def atomic(path: Path, suffix: str = ".tmp"):
    """Yield a temporary path beside ``path`` to write; when the block ends without an error, it
    becomes ``path`` (replacing it), as readable as a new file; otherwise it is removed, and so it
    is by a stop signal that ends the process meanwhile."""
    def create() -> Path:
        handle, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent)
        os.close(handle)
        return Path(name)

    with remove_on_stop() as made:
        tmp = made(create)
        try:
            yield tmp
            umask = os.umask(0)
            os.umask(umask)
            tmp.chmod(0o666 & ~umask)  # mkstemp makes it private
            os.replace(tmp, path)
        finally:
            if tmp.exists():
                tmp.unlink()


def not_a_file(path: Path) -> str | None:
    """Why ``path`` cannot be read as a file ("no such file", "is a directory, not a file"), or None."""
    path = Path(path)
    if path.is_dir():
        return "is a directory, not a file"
    return None if path.is_file() else "no such file"


def same_file(a: Path, b: Path) -> bool:
    """Whether ``a`` and ``b`` name one file (the same path once resolved, or one inode: a hard
    link)."""
    a, b = Path(a), Path(b)
    if a.resolve() == b.resolve():
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:  # either does not exist
        return False


def refusal(out: Path, key: str = "--out", *, force: bool = False, inputs: dict | None = None,
            directory: bool = False) -> str | None:
    """Why ``out`` cannot be written (one line starting with ``key``), or None.

    ``inputs``: what the command reads, by the name it has in the message ({"the table": path});
    ``out`` may be none of them, with ``force`` or not. ``directory``: ``out`` is a folder to
    make or fill (its nearest existing ancestor is the one tried)."""
    out = Path(out)
    for name, path in (inputs or {}).items():
        if path is not None and same_file(out, path):
            return f"{key} {out}: is {name} the command reads; give the output another name"
    if directory:
        existing = out
        while not existing.exists() and existing != existing.parent:
            existing = existing.parent
        if not existing.is_dir():
            return f"{key} {out}: {existing} is a file; give a directory"
        return None if takes_files(existing) else f"{key} {out}: directory {existing} is not writable"
    if out.is_dir():
        return f"{key} {out}: is a directory; give a file name"
    if out.exists() and not force:
        return f"{key} {out}: exists (pass --force to overwrite)"
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        return f"{key} {out}: no directory {parent}"
    if not takes_files(parent):
        return f"{key} {out}: directory {parent} is not writable"
    return None


def takes_files(folder: Path) -> bool:
    """Whether a new file can be made in ``folder`` (one is made and removed)."""
    try:
        handle, name = tempfile.mkstemp(prefix=".microsim-write-test.", dir=folder)
    except OSError:
        return False
    os.close(handle)
    os.unlink(name)
    return True
