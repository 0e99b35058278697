"""CSV records (progress.csv, a sweep's CSV) and the commit of the code that wrote them."""

from __future__ import annotations

import csv
import os
import subprocess
from pathlib import Path

from minippo.errors import MinippoError


def read_rows(path) -> list[dict]:
    """The rows of a CSV file as dicts of strings; [] when it does not exist or is empty."""
    path = Path(path)
    if not path.exists() or path.stat().st_size == 0:
        return []
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def append_row(path, fields: list[str], row: dict) -> None:
    """Append one row (the header first if the file is new), flushed to disk before returning."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    new = not path.exists() or path.stat().st_size == 0
    with open(path, "a", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=fields, lineterminator="\n")
        if new:
            writer.writeheader()
        writer.writerow({key: row.get(key, "") for key in fields})
        handle.flush()
        os.fsync(handle.fileno())


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
