"""What the benchmark scripts share: CSV records appended under a file lock, run claims, and launching
``minippo train`` so that every record carries the exact command that made it.

Parallel safety: a run is claimed by holding an exclusive ``flock`` on ``<runs>/.claims/<name>.lock`` for as long
as its training runs. A second runner started on the same list skips a claimed run and takes the next one, so
starting the same script twice runs two trainings at once, never the same one twice. The lock dies with the
process, so a killed runner leaves no stale claim: the next runner resumes the run from its checkpoint.
"""

from __future__ import annotations

import csv
import fcntl
import json
import os
import shlex
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent  # the repository
RESULTS = ROOT / "benchmarks" / "results"
RUNS = ROOT / "benchmarks" / "runs"

# one BLAS thread per training: two trainings share two cores, and a busy-waiting second BLAS thread
# only steals time from the other run (and Stable-Baselines3 is raced with one torch thread)
THREAD_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
THREAD_PREFIX = "OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1"


class BenchmarkError(Exception):
    """A problem to report on one line (bad arguments, a failed training)."""


def relative(path) -> str:
    """A path as written in commands and records: relative to the repository when inside it."""
    path = Path(path).resolve()
    try:
        return str(path.relative_to(ROOT))
    except ValueError:
        return str(path)


def git_commit() -> str:
    """The short commit of the code that runs, with "+dirty" when tracked files in minippo/ (the code that trains)
    have uncommitted edits."""
    try:
        head = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True, check=True
        ).stdout.strip()
        status = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no", "--", "minippo"],
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


@contextmanager
def locked(path):
    """Hold an exclusive lock on ``path`` (created if missing) for the duration of the block."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a+") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield handle
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def append_row(path, fields: list[str], row: dict, unique: tuple[str, ...] | None = None) -> bool:
    """Append ``row`` to the CSV at ``path`` under a lock, writing the header if the file is new.

    With ``unique`` (key columns), a row whose key is already recorded is not written again; returns whether the
    row was written. Rows are read back as strings, so keys are compared as strings.
    """
    path = Path(path)
    with locked(path.with_name(path.name + ".lock")):
        existing = read_rows(path)
        if existing and list(existing[0].keys()) != fields:
            raise BenchmarkError(f"{relative(path)} has columns {list(existing[0].keys())}, expected {fields}")
        if unique is not None:
            key = tuple(str(row[k]) for k in unique)
            if any(tuple(old[k] for k in unique) == key for old in existing):
                return False
        new = not path.exists() or path.stat().st_size == 0
        with open(path, "a", newline="") as handle:
            writer = csv.DictWriter(handle, fieldnames=fields, lineterminator="\n")
            if new:
                writer.writeheader()
            writer.writerow({k: row[k] for k in fields})
            handle.flush()
            os.fsync(handle.fileno())
    return True


def is_recorded(path, key: dict) -> bool:
    return any(all(row.get(k) == str(v) for k, v in key.items()) for row in read_rows(path))


@contextmanager
def claim(name: str, claims_dir):
    """Try to claim a run. Yields True if this process holds the claim, False if another process does."""
    claims_dir = Path(claims_dir)
    claims_dir.mkdir(parents=True, exist_ok=True)
    handle = open(claims_dir / f"{name}.lock", "a+")
    try:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            yield False
            return
        try:
            yield True
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)
    finally:
        handle.close()


def last_progress(run_dir) -> dict | None:
    rows = read_rows(Path(run_dir) / "progress.csv")
    return rows[-1] if rows else None


def checkpoint_update(run_dir) -> int:
    """The update number saved in the run's checkpoint, 0 when there is none."""
    path = Path(run_dir) / "checkpoint.npz"
    if not path.exists():
        return 0
    import numpy as np

    try:
        with np.load(path, allow_pickle=False) as data:
            return int(data["update"])
    except (OSError, KeyError, ValueError):
        return 0


def finished(run_dir, total_steps: int, horizon: int = 2048) -> bool:
    """True when the run folder holds a complete training of ``total_steps`` (its last update is checkpointed)."""
    num_updates = max(1, total_steps // horizon)
    last = last_progress(run_dir)
    return last is not None and int(last["update"]) == num_updates and checkpoint_update(run_dir) == num_updates


def train_command(env_id: str, steps: int, seed: int, out, extra: list[str] | None = None) -> list[str]:
    argv = ["minippo", "train", env_id, "--steps", str(steps), "--seed", str(seed), "--out", relative(out), "--quiet"]
    return argv + list(extra or [])


def shell_text(argv: list[str]) -> str:
    return " ".join(shlex.quote(part) for part in argv)


def pid_alive(pid, run_dir) -> bool:
    """True when process ``pid`` is alive and is a training writing to ``run_dir``."""
    try:
        cmdline = Path(f"/proc/{int(pid)}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except (OSError, ValueError, TypeError):
        return False
    cmdline = f" {cmdline} "
    return f" {relative(run_dir)} " in cmdline or f" {Path(run_dir).resolve()} " in cmdline


def run_training(argv: list[str], log, on_start=None) -> None:
    """Run one ``minippo train`` from the repository root with one BLAS thread; raise BenchmarkError on failure.
    ``on_start(pid)`` is called once the process runs."""
    env = {**os.environ, **THREAD_ENV}
    with open(log, "a") as handle:
        handle.write(f"[{time.strftime('%Y-%m-%d %H:%M:%S')}] {shell_text(argv)}\n")
        handle.flush()
        process = subprocess.Popen(argv, cwd=ROOT, env=env, stdout=handle, stderr=subprocess.STDOUT)
        if on_start is not None:
            on_start(process.pid)
        try:
            returncode = process.wait()
        except KeyboardInterrupt:
            process.wait()
            raise
    if returncode != 0:
        raise BenchmarkError(f"'{shell_text(argv)}' exited with code {returncode}; see {relative(log)}")


def launch_or_resume(env_id: str, steps: int, seed: int, run_dir, extra: list[str], claims_dir) -> list[str] | None:
    """Bring ``run_dir`` to a finished training of ``steps`` steps and return the commands that made it.

    The caller holds the run's claim. A finished folder is not retrained; a folder with a checkpoint is resumed;
    anything else starts over (--force). The commands used are kept in ``<claims>/<name>.json``, so a run that
    was started by one runner and resumed by another still records both commands.
    """
    run_dir = Path(run_dir)
    meta_path = Path(claims_dir) / f"{run_dir.name}.json"
    meta = json.loads(meta_path.read_text()) if meta_path.exists() else {"commands": [], "commit": git_commit()}
    if meta.get("pid") and pid_alive(meta["pid"], run_dir):  # started outside any runner, and still going
        return None
    if finished(run_dir, steps):
        return meta["commands"] or None
    if checkpoint_update(run_dir) > 0 and meta["commands"]:
        argv = ["minippo", "train", env_id, "--out", relative(run_dir), "--resume", "--quiet"]
    else:
        meta = {"commands": [], "commit": git_commit()}
        argv = train_command(env_id, steps, seed, run_dir, extra) + (["--force"] if run_dir.exists() else [])
    meta["commands"].append(f"{THREAD_PREFIX} {shell_text(argv)}")

    def remember(pid):
        meta["pid"] = pid
        meta_path.write_text(json.dumps(meta, indent=1) + "\n")

    run_training(argv, Path(claims_dir) / f"{run_dir.name}.log", remember)
    return meta["commands"]


def launch_commit(run_dir, claims_dir) -> str:
    meta_path = Path(claims_dir) / f"{Path(run_dir).name}.json"
    if meta_path.exists():
        return json.loads(meta_path.read_text()).get("commit", "unknown")
    return git_commit()


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
