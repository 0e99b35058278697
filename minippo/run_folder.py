"""A run folder: config.json, progress.csv (one row per update), checkpoint.npz and policy.npz.

Every file is written whole or not at all; a file that cannot be written stops the run with one line, and the last
checkpoint is kept.
"""

from __future__ import annotations

import json
import sys
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from minippo.checkpoint import checkpoint_update, load_trainer_state, save_checkpoint, write_atomically
from minippo.errors import MinippoError
from minippo.records import append_row, read_rows, write_rows

PROGRESS_FIELDS = [
    "update",
    "step",
    "episodes",
    "return_mean",
    "length_mean",
    "approx_kl",
    "clip_fraction",
    "entropy",
    "policy_objective",
    "value_loss",
    "explained_variance",
    "kl_beta",
    "lr",
    "steps_per_s",
    "wall_s",
]
COUNTS = ("update", "step", "episodes")  # the integer columns of progress.csv


def start_folder(out: Path, trainer, resume: bool) -> list[dict]:
    """Write config.json and progress.csv's header; with ``resume``, first load the checkpoint of ``trainer``'s run,
    and keep the rows of its updates. Returns those rows."""
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    with run_files(out, trainer):
        if resume and (out / "checkpoint.npz").exists():
            with np.load(out / "checkpoint.npz", allow_pickle=False) as data:
                notice = load_trainer_state(trainer, {key: data[key] for key in data.files})
            if notice:
                print(f"minippo: {notice}", file=sys.stderr)
            rows = progress_until(out / "progress.csv", trainer.update)
        text = json.dumps(trainer.config.to_dict(), indent=2) + "\n"
        write_atomically(out / "config.json", lambda handle: handle.write(text.encode()))
        write_rows(out / "progress.csv", PROGRESS_FIELDS, [csv_row(row) for row in rows])
    return rows


def write_update(out: Path, trainer, row: dict, checkpoint: bool) -> None:
    """Append the update's row to progress.csv, then write the checkpoint when it is time for one."""
    with run_files(out, trainer):
        append_row(out / "progress.csv", PROGRESS_FIELDS, csv_row(row), durable=False)
        if checkpoint:
            save_checkpoint(out, trainer)


@contextmanager
def run_files(out: Path, trainer):
    """A run folder's file that cannot be written (a full disk, no permission) stops the run with one line."""
    try:
        yield
    except OSError as error:
        kept = checkpoint_update(out)
        kept = "no checkpoint yet" if kept is None else f"the checkpoint of update {kept} is kept"
        reason = error.strerror or str(error)
        raise MinippoError(f"cannot write the run's files in {out} ({reason}) at update {trainer.update}; {kept}")


def csv_row(row: dict) -> dict:
    """A progress row as progress.csv holds it: floats by repr, which reads back to the same float."""
    return {key: (repr(value) if isinstance(value, float) else value) for key, value in row.items()}


def progress_until(path: Path, update: int) -> list[dict]:
    """progress.csv's rows of updates 1 … ``update`` (the checkpoint's), read back to the numbers they were written
    from: the rows a killed run wrote after its last checkpoint, and a row cut short by the kill, are dropped."""
    try:
        rows = [
            {key: (int if key in COUNTS else float)(row[key]) for key in PROGRESS_FIELDS}
            for row in read_rows(path)[:update]
        ]
    except (KeyError, TypeError, ValueError):
        rows = None
    if rows is None or [row["update"] for row in rows] != list(range(1, update + 1)):
        raise MinippoError(f"{path} does not hold the rows of updates 1 to {update}, the checkpoint's; cannot resume")
    return rows
