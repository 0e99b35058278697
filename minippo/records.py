"""Files written whole or not at all, CSV records (progress.csv, a sweep's CSV, the benchmarks') and the commit of
the code that wrote them."""

from __future__ import annotations

import csv
import io
import os
import subprocess
from pathlib import Path

from minippo.errors import MinippoError


def write_atomically(path, write) -> None:
    """Write ``path`` with ``write(handle)`` (a binary file) into a temporary file beside it, flushed to disk, then
    rename it over ``path``: a reader finds the old file or the new one, never part of one. On any failure (a full
    disk, a second Ctrl-C) the temporary file is removed, the old file is left as it was, and the error goes on up.
    The temporary file is always a new one and the rename replaces whatever stood at ``path``, so a link left at either
    name (by code the grader runs, say) is never written through."""
    path = Path(path)
    tmp = path.with_name(f"{path.stem}.tmp{path.suffix}")
    try:
        tmp.unlink(missing_ok=True)  # one a killed run left behind
        with open(tmp, "xb") as handle:
            write(handle)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def read_rows(path) -> list[dict]:
    """The rows of a CSV file as dicts of strings; [] when it does not exist or is empty."""
    path = Path(path)
    if not path.exists() or path.stat().st_size == 0:
        return []
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def append_row(path, fields: list[str], row: dict, durable: bool = True) -> None:
    """Append one row (the header first if the file is new), flushed to disk before returning unless ``durable`` is
    false (progress.csv: a resumed run keeps only the rows up to its checkpoint, which is written durably)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    new = not path.exists() or path.stat().st_size == 0
    with open(path, "a", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=fields, lineterminator="\n")
        if new:
            writer.writeheader()
        writer.writerow({key: row.get(key, "") for key in fields})
        if durable:
            handle.flush()
            os.fsync(handle.fileno())


def write_rows(path, fields: list[str], rows) -> None:
    """``rows`` (dicts) as the CSV file ``path`` with the columns ``fields``, written whole or not at all."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    table = io.StringIO(newline="")
    writer = csv.DictWriter(table, fieldnames=fields, lineterminator="\n")
    writer.writeheader()
    writer.writerows({key: row.get(key, "") for key in fields} for row in rows)
    write_atomically(path, lambda handle: handle.write(table.getvalue().encode()))


def check_columns(path, fields: list[str]) -> None:
    """Refuse to append rows of ``fields`` to a CSV that has other columns (another record's file)."""
    path = Path(path)
    if path.exists() and path.stat().st_size:
        with open(path, newline="") as handle:
            header = next(csv.reader(handle), [])
        if header != fields:
            raise MinippoError(f"{path} has columns {','.join(header)}; this writes {','.join(fields)}")


def commit_of_code(paths: tuple[str, ...] = ("minippo",), root=None) -> str:
    """The short commit of the checkout at ``root`` (the one minippo is imported from), with +dirty when tracked
    files under ``paths`` have uncommitted edits; 'unknown' outside a git checkout."""
    root = Path(root) if root is not None else Path(__file__).resolve().parent.parent

    def git(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(["git", *args], cwd=root, capture_output=True, text=True)

    try:
        head = git("rev-parse", "--short", "HEAD")
        status = git("status", "--porcelain", "--untracked-files=no", "--", *paths)
    except OSError:
        return "unknown"
    if head.returncode != 0:
        return "unknown"
    return head.stdout.strip() + ("+dirty" if status.stdout.strip() else "")
