"""File helpers for outputs: the user's file mode, text written atomically."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def user_file_mode() -> int:
    """The mode a new regular file gets under the user's umask (0o644 for umask 022).

    ``tempfile.mkstemp`` creates 0600 files; whatever we write through one is chmod-ed to this
    before the rename, so outputs look like any other file the user writes.
    """
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


def write_atomic_text(path: Path, text: str) -> None:
    """Write a text file through a temporary sibling and rename (never half-written); the file
    gets the user's umask (:func:`user_file_mode`)."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.partial-", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.chmod(tmp, user_file_mode())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
