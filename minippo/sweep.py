"""Sweeps: a grid of trainings run at once on Ray, on this machine or on a cluster (``minippo sweep``).

    minippo sweep CartPole-v1 Acrobot-v1 --seeds 1-3 --steps 100000 --grid clip_epsilon=0.1,0.2,0.3 --out runs/eps
    minippo sweep @runs/eps.sweep           # the same arguments read from a file (one or more per line, # comments)

Each run of the grid (every task × every seed × every combination of ``--grid`` values) is exactly the training
``minippo train`` would run alone: the same ``Config``, the same ``train``, one CPU and one math thread, so its
progress.csv is the same bitwise except the two clock columns (steps_per_s, wall_s). It runs as a Ray task, which
trains in a scratch folder on whatever machine Ray puts it and returns the files; the driver (the process where
``minippo sweep`` was typed) writes them into ``--out/<run>/`` (config.json, progress.csv, checkpoint.npz,
policy.npz, and curve.png drawn as ``minippo train`` draws it) and appends one row to the sweep's CSV
(``--out/sweep.csv`` unless ``--csv``): the run's task, seed and grid values, its steps and final return (mean of the
last 100 episodes), its clock, its status and one-line error, the attempts it took, the Ray node and host it ran on,
the commit of the driver's code and the ``minippo train`` command that makes the same run alone. No file is shared
between machines: only the driver reads and writes the folder. A progress bar counts the runs and shows the running
ones' progress and current return.

Where it runs: without ``--address`` (or ``RAY_ADDRESS``), a Ray instance on this machine, started for the sweep and
stopped after it, with one worker per core (``--workers N`` for fewer), listening on the loopback address only. With
``--address HOST:PORT``, a Ray cluster already running there (``ray start --head`` on one machine, ``ray start
--address HOST:PORT`` on the others, minippo installed on each); ``--workers N`` then caps the runs in flight.

Safe to stop and start again: a run with an ``ok`` row in the CSV is skipped, so the same command resumes a sweep (a
row of the same run made by another command, with other steps or settings, is refused: another sweep's CSV).
A run that fails (an exception, NaN/inf in the loss: ``NonFiniteError``, or a worker that dies) is tried again up to
``--retries`` more times, from its last checkpoint (whose files the driver holds), then recorded with status
``failed`` and its reason, and the sweep goes on; a later invocation tries it again.
Ctrl-C records the runs already finished, stops the workers, and exits with 130.

Ray is an optional dependency (``pip install -e ".[sweep]"``); nothing else in minippo imports it. ``plan`` makes the
runs, ``Sweep`` records them, and ``execute`` is the engine under both: it runs any function called as ``train_run``
is (a Config's dict in, a dict with the run's files and last progress row out) on Ray, with retries and Ctrl-C.
"""

from __future__ import annotations

import itertools
import math
import os
import shlex
import signal
import socket
import sys
import tempfile
import threading
import typing
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from minippo.config import Config, field_types
from minippo.errors import MinippoError
from minippo.flags import train_argv
from minippo.records import append_row, check_columns, commit_of_code, read_rows
from minippo.run_folder import RunFolder

RESULT_FIELDS = [
    "steps",
    "return_mean",
    "wall_s",
    "steps_per_s",
    "status",
    "error",
    "attempts",
    "node",
    "host",
    "commit",
    "command",
]
LOOPBACK = ("127.0.0.1", "localhost", "::1")


@dataclass
class Run:
    """One training of a sweep: its folder name, its Config and the CSV columns that name it (``labels``)."""

    name: str
    config: Config
    labels: dict

    def key(self) -> tuple:
        return tuple(str(value) for value in self.labels.values())

    def command(self, out_dir) -> str:
        """The ``minippo train`` command that makes the same training alone, into ``out_dir``/``name``."""
        argv = ["minippo", "train", *train_argv(self.config, Path(out_dir) / self.name), "--quiet"]
        return shlex.join(argv)


# planning a sweep from the command line's words


def parse_seeds(text: str) -> list[int]:
    """'1-3' -> [1, 2, 3]; '1,4,7' and '1-3,7' too."""
    seeds: list[int] = []
    try:
        for part in filter(None, (part.strip() for part in text.split(","))):
            first, _, last = part.partition("-")
            low, high = int(first), int(last or first)
            if low < 0 or high < low:
                raise ValueError
            seeds += range(low, high + 1)
    except ValueError:
        raise MinippoError(f"--seeds takes numbers and ranges such as 1-3 or 1,4,7, not '{text}'") from None
    if not seeds:
        raise MinippoError("--seeds names no seed")
    if len(set(seeds)) != len(seeds):
        raise MinippoError(f"--seeds names a seed twice: '{text}'")
    return seeds


def parse_grid(texts: list[str]) -> list[tuple[str, list]]:
    """['clip_epsilon=0.1,0.2', 'lr=3e-4,1e-3'] -> [('clip_epsilon', [0.1, 0.2]), ('lr', [0.0003, 0.001])], each
    value typed like its Config field. A tuple field's values put x between their numbers (hidden_sizes=32x32,64)."""
    grid = []
    for text in texts:
        if "=" not in text:
            raise MinippoError(f"--grid takes key=value1,value2,..., not '{text}'")
        key, raw = text.split("=", 1)
        key = key.strip().replace("-", "_")
        if any(key == other for other, _ in grid):
            raise MinippoError(f"--grid {key} is given twice")
        words = [word.strip() for word in raw.split(",") if word.strip()]
        if not words:
            raise MinippoError(f"--grid {key}: no values")
        tuple_field = typing.get_origin(field_types().get(key)) is tuple
        values = [Config.parse_value(key, word.replace("x", ",") if tuple_field else word) for word in words]
        if len(set(map(repr, values))) != len(values):
            raise MinippoError(f"--grid {key} names a value twice")
        grid.append((key, values))
    return grid


def plan(envs, seeds, steps, grid=(), settings=None) -> list[Run]:
    """The runs of a sweep in the order they start: task by task, then grid point, then seed.

    ``grid``: [(Config field, [values])] from ``parse_grid``, every combination; ``settings``: {Config field: value}
    for every run (as ``minippo train``'s options set them)."""
    settings = dict(settings or {})
    for key, _ in grid:
        if key in settings:
            raise MinippoError(f"{key} is both swept (--grid) and fixed (--config, --preset or its own option)")
    runs = []
    for env_id in envs:
        for point in itertools.product(*[[(key, value) for value in values] for key, values in grid]):
            fields = {**settings, **dict(point)}
            shown = {key: text(value) for key, value in point}
            for seed in seeds:
                config = Config(env_id=env_id, total_steps=steps, seed=seed, **fields)
                config.validate()
                name = "-".join([env_id, *(f"{key}={value}" for key, value in shown.items()), f"seed{seed}"])
                runs.append(Run(name, config, {"env": env_id, "seed": seed, **shown}))
    return runs


def text(value) -> str:
    """A grid value as a run's name and the CSV write it (a tuple's numbers joined by x: 32x32)."""
    if isinstance(value, tuple):
        return "x".join(str(v) for v in value)
    return str(value)


# one training, as a Ray task runs it


def train_run(config_dict: dict, name: str = "", board=None, resume: dict | None = None) -> dict:
    """Train one run in a scratch folder with one math thread and return what it wrote: {"files": {name: bytes},
    "last": the last progress row, "resumed_from": the update it started from, "node", "host", "pid"}. ``board`` (a
    Ray actor) hears each update's return and keeps each checkpoint's files; ``resume``: such files, from which the
    run carries on as it would have (a retry after its worker died)."""
    from threadpoolctl import threadpool_limits

    from minippo.ppo import train

    config = Config.from_dict(config_dict)
    total = config.num_updates * config.batch_size

    def on_update(row):
        if board is not None:
            board.report.remote(name, row["step"], total, row["return_mean"])

    def on_checkpoint(out):
        if board is not None:
            folder = RunFolder(out)
            board.keep.remote(name, folder.checkpoint_update(), folder.files(RunFolder.RESUMABLE))

    with threadpool_limits(1), tempfile.TemporaryDirectory(prefix="minippo-run-") as scratch:
        folder = RunFolder(scratch)
        folder.write_files(resume or {})
        resumed_from = folder.checkpoint_update() or 0
        rows = train(config, scratch, resume=bool(resume), on_update=on_update, on_checkpoint=on_checkpoint)
        files = folder.files()
    node = ""
    if "ray" in sys.modules:
        import ray

        if ray.is_initialized():
            node = ray.get_runtime_context().get_node_id()[:12]
    return {
        "files": files,
        "last": rows[-1],
        "resumed_from": resumed_from,
        "node": node,
        "host": socket.gethostname(),
        "pid": os.getpid(),
    }


# the driver: CSV, run folders, progress


def write_run(path: Path, result: dict, title: str) -> None:
    """The run's files as the task returned them (an earlier attempt's others removed), then its curve.png as
    ``minippo train`` draws it."""
    from minippo.plotting import plot_runs

    folder = RunFolder(path)
    folder.write_files(result["files"])
    plot_runs([folder.path], folder.curve_png, title=title)


def one_line(error: BaseException) -> str:
    cause = getattr(error, "cause", None)  # a RayTaskError carries the task's own exception
    error = cause if isinstance(cause, BaseException) else error
    message = str(error).strip().splitlines()
    text = f"{type(error).__name__}: {message[-1] if message else ''}".strip()
    return text[:300]


class Sweep:
    """Runs ``runs`` on Ray and records them; ``run()`` returns the number of runs that failed. The commands in the
    CSV name ``out`` as it is given (a relative folder stays relative). ``task``: the function each run trains with,
    called as ``train_run`` is and returning the same kind of result."""

    def __init__(self, runs, out, csv_path=None, workers=None, address=None, retries=0, quiet=False, task=train_run):
        self.runs, self.out, self.task = list(runs), Path(out), task
        self.csv_path = Path(csv_path) if csv_path else self.out / "sweep.csv"
        self.label_fields = list(self.runs[0].labels) if self.runs else ["env", "seed"]
        self.fields = self.label_fields + RESULT_FIELDS
        self.workers, self.retries, self.quiet = workers, retries, quiet
        self.address = address or os.environ.get("RAY_ADDRESS") or None
        self.commit = commit_of_code()
        self.failed: list[str] = []
        self.recorded = 0

    def todo(self) -> list[Run]:
        """The runs without an ok row. A row for the same labels but another command (other steps, other fixed
        settings) means the CSV holds another sweep: refused, rather than skipped or mixed in."""
        done = {}
        for row in read_rows(self.csv_path):
            if row["status"] == "ok":
                done[tuple(row[k] for k in self.label_fields)] = row["command"]
        for run in self.runs:
            made_by = done.get(run.key())
            if made_by is not None and made_by != run.command(self.out):
                raise MinippoError(
                    f"{self.csv_path} holds {run.name} made by '{made_by}', not by '{run.command(self.out)}';"
                    " give this sweep another --out or --csv"
                )
        return [run for run in self.runs if run.key() not in done]

    def finish(self, run: Run, result: dict | None, error: str, attempts: int) -> dict:
        """Write a finished run's folder and its CSV row (rows of failures too); returns the row."""
        row = {**run.labels, "status": "failed", "error": error, "attempts": attempts, "commit": self.commit}
        row["command"] = run.command(self.out)
        if result is not None:
            folder = self.out / run.name
            write_run(folder, result, f"{run.config.env_id}, seed {run.config.seed}")
            last = result["last"]
            row.update(
                steps=last["step"],
                return_mean=repr(float(last["return_mean"])),
                wall_s=round(last["wall_s"], 1),
                steps_per_s=round(last["steps_per_s"], 1),
                status="ok",
                error="",
                node=result["node"],
                host=result["host"],
            )
        else:
            self.failed.append(run.name)
        append_row(self.csv_path, self.fields, row)
        self.recorded += 1
        return row

    def run(self) -> int:
        check_columns(self.csv_path, self.fields)
        todo = self.todo()
        skipped = len(self.runs) - len(todo)
        if not todo:
            self.say(f"all {len(self.runs)} runs are recorded in {self.csv_path}")
            return 0
        execute(todo, self.finish, self.workers, self.address, self.retries, self.progress, self.task)
        self.say(
            f"{len(todo)} runs: {len(todo) - len(self.failed)} ok, {len(self.failed)} failed"
            + (f", {skipped} already recorded" if skipped else "")
            + f" -> {self.csv_path}"
        )
        return len(self.failed)

    def progress(self, total: int):
        if self.quiet:
            return None
        from tqdm import tqdm

        return tqdm(total=total, unit="run", dynamic_ncols=True, file=sys.stderr, desc="sweep")

    def say(self, message: str) -> None:
        print(message, file=sys.stderr if self.quiet else sys.stdout)


# the engine: Ray tasks, retries, Ctrl-C


def reachable(address: str) -> None:
    """Refuse at once an address where nothing listens (Ray itself would retry for minutes)."""
    host, _, port = address.rpartition(":")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=5).close()
    except ValueError:
        raise MinippoError(f"--address takes HOST:PORT, not '{address}'") from None
    except OSError as error:
        raise MinippoError(f"no Ray cluster answers at {address} ({error.strerror or error})") from None


def start_ray(workers: int | None, address: str | None):
    """Import Ray and connect: to ``address``, or to a new Ray instance on this machine. Returns (ray, whether we
    started it)."""
    host = address.rsplit(":", 1)[0].strip("[]") if address else None
    if address is not None and "://" not in address and address != "auto":
        reachable(address)
    if address is None or host in LOOPBACK:
        # a Ray on this machine listens on the loopback address only (Ray's switch for single-machine use)
        os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    try:
        import ray
    except ImportError:
        raise MinippoError('minippo sweep runs on Ray, which is not installed: pip install "minippo[sweep]"') from None
    import logging

    if ray.is_initialized():
        return ray, False
    options = dict(include_dashboard=False, log_to_driver=False, logging_level=logging.ERROR)
    try:
        if address is None:
            ray.init(num_cpus=workers or os.cpu_count() or 1, **options)
        else:
            ray.init(address=address, **options)
    except (ConnectionError, RuntimeError, ValueError) as error:
        where = f"at {address}" if address else "on this machine"
        raise MinippoError(f"cannot start or reach Ray {where}: {str(error).strip().splitlines()[0]}") from None
    return ray, True


@contextmanager
def interrupt_after():
    """Hold Ctrl-C back until the block is done (a run's folder and row are written whole), then raise it."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    hit = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: hit.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if hit:
            raise KeyboardInterrupt


def execute(runs: list[Run], on_result, workers=None, address=None, retries=0, progress=None, task=None) -> None:
    """Train ``runs`` as Ray tasks of one CPU each (``task``, by default ``train_run``) and call
    ``on_result(run, result, error, attempts)`` as each one ends: the task's result and "" when it trained, None and
    a one-line reason when its last attempt failed.

    Ctrl-C: the runs that have finished are handed to ``on_result``, the others are cancelled (their workers
    killed), and KeyboardInterrupt goes on up."""
    ray, started = start_ray(workers, address)
    pending: dict = {}  # ObjectRef -> (run, attempt)
    bar = progress(len(runs)) if progress else None
    remote = ray.remote(task or train_run).options(num_cpus=1, max_retries=0)
    try:
        board = ray.remote(num_cpus=0)(Board).remote()
        window = workers or max(1, int(ray.cluster_resources().get("CPU", 1)))
        queue = [(run, 1) for run in runs]
        last = ""
        while queue or pending:
            while queue and len(pending) < window:
                run, attempt = queue.pop(0)
                kept = ray.get(board.kept.remote(run.name)) if attempt > 1 else None
                resume = {"resume": kept} if kept else {}
                pending[remote.remote(run.config.to_dict(), run.name, board, **resume)] = (run, attempt)
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=1.0)
            for ref in ready:
                run, attempt = pending.pop(ref)
                try:
                    result, error = ray.get(ref), ""
                except ray.exceptions.RayError as failure:
                    result, error = None, one_line(failure)
                    if attempt <= retries:  # again, from the run's last checkpoint (the board holds its files)
                        queue.insert(0, (run, attempt + 1))
                        continue
                board.forget.remote(run.name)
                with interrupt_after():
                    on_result(run, result, error, attempt)
                last = f"{run.name} failed" if result is None else f"{run.name} {result['last']['return_mean']:.1f}"
                if bar is not None:
                    bar.update(1)
            if bar is not None:
                bar.set_postfix_str(status_line(ray, board, pending, last), refresh=True)
    except KeyboardInterrupt:
        if pending:
            ready, _ = ray.wait(list(pending), num_returns=len(pending), timeout=0)
            for ref in ready:
                run, attempt = pending.pop(ref)
                try:
                    result = ray.get(ref, timeout=10)
                except ray.exceptions.RayError:
                    continue
                with interrupt_after():
                    on_result(run, result, "", attempt)
            for ref in pending:
                ray.cancel(ref, force=True)
        raise
    finally:
        if bar is not None:
            bar.close()
        if started:
            ray.shutdown()


class Board:
    """A Ray actor that holds each running run's latest step and return, for the progress bar, and the files of its
    latest checkpoint, from which a run whose worker died is tried again (no file is shared between machines)."""

    def __init__(self):
        self.latest = {}
        self.checkpoints = {}  # run name -> (update, {file name: bytes})

    def report(self, name, step, total, return_mean):
        self.latest[name] = (step, total, return_mean)

    def keep(self, name, update, files):
        if update is not None and update > self.checkpoints.get(name, (0, None))[0]:
            self.checkpoints[name] = (update, files)

    def kept(self, name):
        return self.checkpoints.get(name, (0, None))[1]

    def forget(self, name):
        self.checkpoints.pop(name, None)
        self.latest.pop(name, None)

    def snapshot(self):
        return dict(self.latest)


def status_line(ray, board, pending: dict, last: str) -> str:
    try:
        latest = ray.get(board.snapshot.remote(), timeout=2)
    except Exception:  # the bar is a convenience: a slow actor must not stop the sweep
        latest = {}
    parts = []
    for run, _ in pending.values():
        if run.name in latest:
            step, total, value = latest[run.name]
            shown = "—" if value is None or math.isnan(value) else f"{value:.1f}"
            parts.append(f"{run.name} {100 * step // total}% {shown}")
    return "; ".join(([f"last {last}"] if last else []) + parts)[:400]
