"""Writing a run's files so that an interruption (a kill, a full disk, Ctrl-C) never leaves half of one."""

from __future__ import annotations

import os
from pathlib import Path


def write_atomically(path, write) -> None:
    """Write ``path`` with ``write(handle)`` (a binary file) into a temporary file beside it, flushed to disk, then
    rename it over ``path``: a reader finds the old file or the new one, never part of one. On any failure (a full
    disk, a second Ctrl-C) the temporary file is removed, the old file is left as it was, and the error goes on up."""
    path = Path(path)
    tmp = path.with_name(f"{path.stem}.tmp{path.suffix}")
    try:
        with open(tmp, "wb") as handle:
            write(handle)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
