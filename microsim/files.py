"""Files written whole or not at all: under a temporary name beside the target, renamed when
complete (what the exporters and the renders write; the tables have their own rule,
:func:`microsim.tables.write`, which never replaces a file that appeared meanwhile)."""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path


@contextlib.contextmanager
def atomic(path: Path, suffix: str = ".tmp"):
    """Yield a temporary path beside ``path`` to write; when the block ends without an error, it
    becomes ``path`` (replacing it), as readable as a new file; otherwise it is removed."""
    handle, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent)
    os.close(handle)
    tmp = Path(name)
    try:
        yield tmp
        umask = os.umask(0)
        os.umask(umask)
        tmp.chmod(0o666 & ~umask)  # mkstemp makes it private
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
