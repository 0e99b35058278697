"""What the runners share: the repository's paths, a one-line error, the progress.csv rounding of committed runs, and
running a list of ``minippo.sweep.Run`` on minippo sweep's engine into a runs record of the runner's own columns."""

from __future__ import annotations

import csv
import os
import shlex
import sys
from pathlib import Path

from minippo.records import append_row, check_columns, commit_of_code, read_rows

ROOT = Path(__file__).resolve().parent.parent  # the repository
RESULTS = ROOT / "benchmarks" / "results"
RUNS = ROOT / "benchmarks" / "runs"
# one math thread per process: two trainings share two cores (and Stable-Baselines3 races with one torch thread)
THREAD_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


class BenchmarkError(Exception):
    """A problem to report on one line (bad arguments, a failed training)."""


def fail(message: str) -> None:
    print(f"{Path(sys.argv[0]).name}: error: {message}", file=sys.stderr)
    raise SystemExit(2)


def relative(path) -> str:
    """A path as commands and records write it: relative to the repository when inside it."""
    path = Path(path).resolve()
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def git_commit(paths: tuple[str, ...] = ("minippo",)) -> str:
    return commit_of_code(paths, ROOT)


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


def add_sweep_options(parser) -> None:
    """The engine's options, as ``minippo sweep`` has them."""
    parser.add_argument("--workers", type=int, help="trainings at once (default: every core, or the cluster's CPUs)")
    parser.add_argument("--address", help="a running Ray cluster, HOST:PORT (default: $RAY_ADDRESS, else this machine)")
    parser.add_argument("--retries", type=int, default=0, help="tries again a failed training this many times")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def record_sweep(runs, root, record_csv, fields: list[str]) -> int:
    """Copy the ok rows of ``root/sweep.csv`` that ``record_csv`` lacks into it (their labels, then steps, return,
    clock, commit and command), rounding each run's progress.csv; returns how many were added."""
    key = [field for field in fields if field in runs[0].labels] if runs else []
    by_key = {tuple(str(run.labels[k]) for k in key): run for run in runs}
    recorded = {tuple(row[k] for k in key) for row in read_rows(record_csv)}
    added = 0
    for row in read_rows(Path(root) / "sweep.csv"):
        run = by_key.get(tuple(row[k] for k in key))
        if row["status"] != "ok" or run is None or tuple(row[k] for k in key) in recorded:
            continue
        compact_progress(Path(root) / run.name)
        numbers = {"steps": int(row["steps"]), "return_mean": round(float(row["return_mean"]), 2)}
        numbers |= {"wall_s": round(float(row["wall_s"]), 1), "steps_per_s": round(float(row["steps_per_s"]), 1)}
        append_row(record_csv, fields, {**run.labels, **numbers, "commit": row["commit"], "command": row["command"]})
        recorded.add(tuple(row[k] for k in key))
        added += 1
    return added


def run_sweep(runs, root, record_csv, fields: list[str], args) -> int:
    """Run the ``runs`` that ``record_csv`` does not hold on minippo sweep's engine into the folder ``root`` (each
    run, failed ones too, is logged in ``root/sweep.csv`` with the node it ran on), then record the finished ones.
    Returns the exit code."""
    from minippo.errors import MinippoError
    from minippo.sweep import Sweep

    if args.workers is not None and args.workers < 1:
        fail(f"--workers must be at least 1, not {args.workers}")
    try:
        check_columns(record_csv, fields)
    except MinippoError as error:
        fail(str(error))
    root = relative(root)  # the commands in the records name the folder from the repository's root
    record_sweep(runs, root, record_csv, fields)  # runs an interrupted invocation finished
    key = [field for field in fields if runs and field in runs[0].labels]
    recorded = {tuple(row[k] for k in key) for row in read_rows(record_csv)}
    todo = [run for run in runs if tuple(str(run.labels[k]) for k in key) not in recorded]
    job = Sweep(todo, root, workers=args.workers, address=args.address, retries=args.retries, quiet=args.quiet)
    try:
        code = 1 if todo and job.run() else 0
    except MinippoError as error:
        fail(str(error))
    except KeyboardInterrupt:
        print(f"interrupted; {job.recorded} runs recorded; the same command continues", file=sys.stderr)
        code = 130
    record_sweep(runs, root, record_csv, fields)
    return code
