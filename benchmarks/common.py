"""What the runners share: paths, one-line errors, a CSV writer, the rounding of committed progress.csv files, and
running ``minippo.sweep.Run``s on minippo sweep's engine into a record of the runner's columns (--list, resuming)."""

from __future__ import annotations

import functools
import shlex
import sys
from pathlib import Path

from minippo import records
from minippo.errors import MinippoError
from minippo.records import append_row, check_columns, commit_of_code, read_rows

ROOT = Path(__file__).resolve().parent.parent  # the repository
RESULTS = ROOT / "benchmarks" / "results"
RUNS = ROOT / "benchmarks" / "runs"
# one math thread per process: two trainings share two cores (and Stable-Baselines3 races with one torch thread)
THREAD_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


class BenchmarkError(ValueError):
    """A problem to report on one line (bad arguments or records, a failed training)."""


def fail(message: str) -> None:
    program = Path(sys.argv[0])  # a runner's file, or the folder of a package's __main__.py
    print(f"{program.parent.name if program.stem == '__main__' else program.name}: error: {message}", file=sys.stderr)
    raise SystemExit(2)


def one_line_errors(main):
    """A runner's ``main`` with its BenchmarkError or MinippoError reported on one line (``fail``)."""

    @functools.wraps(main)
    def guarded(*args, **kwargs):
        try:
            return main(*args, **kwargs)
        except (BenchmarkError, MinippoError) as error:
            fail(str(error))

    return guarded


def relative(path) -> str:
    """A path as commands and records write it: relative to the repository when inside it."""
    path = Path(path).resolve()
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def git_commit(paths: tuple[str, ...] = ("minippo",)) -> str:
    return commit_of_code(paths, ROOT)


def invocation(module: str, argv) -> str:
    """The command that ran ``python -m benchmarks.MODULE`` with ``argv`` (None: this process's), as records keep it."""
    return f"python -m benchmarks.{module} {shlex.join(sys.argv[1:] if argv is None else argv)}".strip()


def compact_progress(run_dir, digits: int = 6) -> None:
    """Round progress.csv's numbers to ``digits`` significant digits (it is committed; full floats triple its size)."""
    path = Path(run_dir) / "progress.csv"

    def short(text: str) -> str:
        try:
            return text if text.lstrip("-").isdigit() else f"{float(text):.{digits}g}"
        except ValueError:
            return text

    if rows := read_rows(path):
        write_rows(path, [{k: short(v) for k, v in row.items()} for row in rows])


def write_rows(path, rows: list[dict], fields=None) -> Path:
    """``rows`` as the CSV file ``path``, whole or not at all; ``fields``: its columns (by default the first row's)."""
    records.write_rows(path, fields or (list(rows[0]) if rows else ["empty"]), rows)
    return Path(path)


def add_sweep_options(parser) -> None:
    """The engine's options, as ``minippo sweep`` has them, and ``--list``."""
    parser.add_argument("--workers", type=int, help="trainings at once (default: every core, or the cluster's CPUs)")
    parser.add_argument("--address", help="a running Ray cluster, HOST:PORT (default: $RAY_ADDRESS, else this machine)")
    parser.add_argument("--retries", type=int, default=0, help="tries again a failed training this many times")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--list", action="store_true", help="show what is recorded and what is left, then stop")


def check_steps(steps: int, least: int = 2048) -> None:
    if steps < least:
        fail(f"--steps must be at least one horizon ({least}), not {steps}")


def keyed(runs, record_csv, fields) -> tuple[list, dict, dict]:
    """(key, {a run's key: run}, {a row's key: row of ``record_csv``}): a key is the values, as text, of the record's
    columns that name a run (its labels), in the record's order."""
    key = [field for field in fields if runs and field in runs[0].labels]
    named = {tuple(str(run.labels[k]) for k in key): run for run in runs}
    return key, named, {tuple(row[k] for k in key): row for row in read_rows(record_csv)}


def todo(runs, record_csv, fields) -> list:
    """The runs that ``record_csv`` does not hold yet."""
    _, named, recorded = keyed(runs, record_csv, fields)
    return [run for name, run in named.items() if name not in recorded]


def show_list(runs, record_csv, fields) -> int:
    """``--list``: every run, recorded (with its scores) or still to do."""
    key, named, recorded = keyed(runs, record_csv, fields)
    shown = [[f"seed {v}" if k == "seed" else v for k, v in zip(key, name)] for name in named]
    widths = [max(map(len, column)) for column in zip(*shown)]
    for name, texts in zip(named, shown):
        row = recorded.get(name, {})
        label = "  ".join(f"{text:<{width}}" for text, width in zip(texts, widths))
        scores = "".join(f"  {col[:-5]} {row[col]:>9}" for col in ("return_mean", "eval_mean") if col in row)
        print(f"{'recorded' if row else 'to do':<8}  {label}{scores}")
    return 0


def record_sweep(runs, root, record_csv, fields: list[str], more=None) -> int:
    """Copy the ok rows of ``root/sweep.csv`` that ``record_csv`` lacks into it, with ``more(folder)``'s columns,
    rounding each run's progress.csv; returns how many were added."""
    key, named, recorded = keyed(runs, record_csv, fields)
    left = {name: run for name, run in named.items() if name not in recorded}
    added = 0
    for row in read_rows(Path(root) / "sweep.csv"):
        if row["status"] != "ok" or (run := left.pop(tuple(row[k] for k in key), None)) is None:
            continue
        extra = more(Path(root) / run.name) if more else {}
        compact_progress(Path(root) / run.name)
        numbers = {"steps": int(row["steps"]), "return_mean": round(float(row["return_mean"]), 2)}
        numbers |= {"wall_s": round(float(row["wall_s"]), 1), "steps_per_s": round(float(row["steps_per_s"]), 1)}
        numbers |= {**extra, "commit": row["commit"], "command": row["command"]}
        append_row(record_csv, fields, {**run.labels, **numbers})
        added += 1
    return added


def run_sweep(runs, root, record_csv, fields: list[str], args, engine=None, more=None) -> int:
    """Run the ``runs`` that ``record_csv`` lacks on minippo sweep's engine into ``root`` (which logs every run in
    ``root/sweep.csv``), then record the finished ones (``more``: see ``record_sweep``), or with ``args.list`` show
    them. ``engine``: a ``Sweep`` maker whose ``finish`` writes the record itself. Returns the exit code."""
    from minippo.sweep import Sweep

    if args.list:
        return show_list(runs, record_csv, fields)
    if args.workers is not None and args.workers < 1:
        fail(f"--workers must be at least 1, not {args.workers}")
    check_columns(record_csv, fields)
    root = relative(root)  # the commands in the records name the folder from the repository's root
    if engine is None:
        record_sweep(runs, root, record_csv, fields, more)  # runs an interrupted invocation finished
    left = todo(runs, record_csv, fields)
    if not left:
        print(f"all {len(runs)} runs are recorded in {relative(record_csv)}")
        return 0
    options = dict(workers=args.workers, address=args.address, retries=args.retries, quiet=args.quiet)
    job = (engine or Sweep)(left, root, **options)
    try:
        code = 1 if job.run() else 0
    except KeyboardInterrupt:
        print(f"interrupted; {job.recorded} runs recorded; the same command continues", file=sys.stderr)
        code = 130
    if engine is None:
        record_sweep(runs, root, record_csv, fields, more)
    return code


def markdown_table(header: list, rows: list) -> str:
    """A Markdown table: a header row, then a row per list of cells."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join(lines + ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows])
