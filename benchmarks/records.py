"""What the benchmark scripts share: the repository's paths, CSV records, the commit of the code, and the
``minippo train`` command line. The training runners (``seven_tasks.py``, ``table1.py``) describe their runs and hand
them to ``minippo sweep``'s engine (``minippo.sweep``), which runs them on Ray and records them.
"""

from __future__ import annotations

import csv
import os
import shlex
import subprocess
import sys
from pathlib import Path

from minippo.sweep import append_row as write_row  # one CSV writer: the header once, each row flushed to disk

ROOT = Path(__file__).resolve().parent.parent  # the repository
RESULTS = ROOT / "benchmarks" / "results"
RUNS = ROOT / "benchmarks" / "runs"

# one BLAS thread per training: two trainings share two cores, and a busy-waiting second BLAS thread
# only steals time from the other run (and Stable-Baselines3 is raced with one torch thread)
THREAD_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


class BenchmarkError(Exception):
    """A problem to report on one line (bad arguments, a failed training)."""


def relative(path) -> str:
    """A path as written in commands and records: relative to the repository when inside it."""
    path = Path(path).resolve()
    try:
        return str(path.relative_to(ROOT))
    except ValueError:
        return str(path)


def git_commit(paths: tuple[str, ...] = ("minippo",)) -> str:
    """The short commit of the code that runs, with "+dirty" when tracked files under ``paths`` (by default minippo/,
    the code that trains) have uncommitted edits."""
    try:
        head = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True, check=True
        ).stdout.strip()
        status = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no", "--", *paths],
            cwd=ROOT,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + ("+dirty" if status else "")


def read_rows(path) -> list[dict]:
    path = Path(path)
    if not path.exists():
        return []
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def append_row(path, fields: list[str], row: dict, unique: tuple[str, ...] | None = None) -> bool:
    """Append ``row`` to the CSV at ``path``, writing the header if the file is new.

    With ``unique`` (key columns), a row whose key is already recorded is not written again; returns whether the
    row was written. Rows are read back as strings, so keys are compared as strings.
    """
    path = Path(path)
    existing = read_rows(path)
    if existing and list(existing[0].keys()) != fields:
        raise BenchmarkError(f"{relative(path)} has columns {list(existing[0].keys())}, expected {fields}")
    if unique is not None:
        key = tuple(str(row[k]) for k in unique)
        if any(tuple(old[k] for k in unique) == key for old in existing):
            return False
    write_row(path, fields, {k: row[k] for k in fields})
    return True


def record_row(run, row: dict) -> dict:
    """A runs record's row for a finished run: its labels (setting, task, seed), then what the sweep measured."""
    return {
        **run.labels,
        "steps": int(row["steps"]),
        "return_mean": round(float(row["return_mean"]), 2),
        "wall_s": round(float(row["wall_s"]), 1),
        "steps_per_s": round(float(row["steps_per_s"]), 1),
        "commit": row["commit"],
        "command": row["command"],
    }


def is_recorded(path, key: dict) -> bool:
    return any(all(row.get(k) == str(v) for k, v in key.items()) for row in read_rows(path))


def last_progress(run_dir) -> dict | None:
    rows = read_rows(Path(run_dir) / "progress.csv")
    return rows[-1] if rows else None


def train_command(env_id: str, steps: int, seed: int, out, extra: list[str] | None = None) -> list[str]:
    argv = ["minippo", "train", env_id, "--steps", str(steps), "--seed", str(seed), "--out", relative(out), "--quiet"]
    return argv + list(extra or [])


def shell_text(argv: list[str]) -> str:
    return " ".join(shlex.quote(part) for part in argv)


def compact_progress(run_dir, digits: int = 6) -> None:
    """Round progress.csv's numbers to ``digits`` significant digits (it is committed; full floats triple its size)."""
    path = Path(run_dir) / "progress.csv"
    rows = read_rows(path)
    if not rows:
        return

    def short(text: str) -> str:
        try:
            value = float(text)
        except ValueError:
            return text
        if value.is_integer() and abs(value) < 1e15 and "." not in text and "e" not in text.lower():
            return text
        return f"{value:.{digits}g}"

    tmp = path.with_name("progress.tmp.csv")
    with open(tmp, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0].keys()), lineterminator="\n")
        writer.writeheader()
        writer.writerows({k: short(v) for k, v in row.items()} for row in rows)
    os.replace(tmp, path)


def fail(message: str) -> None:
    print(f"{Path(sys.argv[0]).name}: error: {message}", file=sys.stderr)
    raise SystemExit(2)


def add_sweep_options(parser) -> None:
    """The engine's options, as ``minippo sweep`` has them."""
    parser.add_argument("--workers", type=int, help="trainings at once (default: every core, or the cluster's CPUs)")
    parser.add_argument("--address", help="a running Ray cluster, HOST:PORT (default: $RAY_ADDRESS, else this machine)")
    parser.add_argument("--retries", type=int, default=0, help="tries again a failed training this many times")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def run_sweep(runs, root, record_csv, fields: list[str], key: tuple, make_row, args) -> int:
    """Run ``runs`` (minippo.sweep.Run) on minippo sweep's engine into the folder ``root``: each finished run's
    progress.csv is rounded (``compact_progress``) and ``make_row(run, sweep_row)`` is appended to ``record_csv``;
    every run, failed ones too, is logged in ``root/sweep.csv`` with the node it ran on. Runs already in
    ``record_csv`` are skipped. Returns the exit code."""
    from minippo.errors import MinippoError
    from minippo.sweep import Record, Sweep

    if args.workers is not None and args.workers < 1:
        fail(f"--workers must be at least 1, not {args.workers}")
    job = Sweep(
        runs,
        root,
        workers=args.workers,
        address=args.address,
        retries=args.retries,
        quiet=args.quiet,
        record=Record(Path(record_csv), fields, key, make_row),
        after_write=compact_progress,
        command_out=relative(root),
    )
    try:
        return 1 if job.run() else 0
    except MinippoError as error:
        fail(str(error))
    except KeyboardInterrupt:
        print(f"interrupted; {job.recorded} runs recorded; the same command continues", file=sys.stderr)
        return 130
