"""A run folder: config.json, progress.csv (one row per update), checkpoint.npz, policy.npz and curve.png.

``RunFolder`` is the one place that knows these names and a folder's rules: a new run goes into a folder that holds
files only with ``force``, and even then the old run's files are removed only once the new run's ``Trainer`` exists
(its settings valid, its environments made); ``resume`` goes on from the checkpoint, and ``steps`` extends the run.
Every file is written whole or not at all; a file that cannot be written stops the run with one line, and the last
checkpoint is kept.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from contextlib import contextmanager
from pathlib import Path

from minippo.agent_files import save_policy
from minippo.checkpoint import checkpoint_update, load_checkpoint, save_checkpoint
from minippo.config import Config
from minippo.errors import MinippoError
from minippo.records import append_row, read_rows, write_atomically, write_rows

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


class RunFolder:
    """The files of one run in ``path``, and what may be done with them."""

    CONFIG, PROGRESS, CHECKPOINT, POLICY = "config.json", "progress.csv", "checkpoint.npz", "policy.npz"
    CURVE = "curve.png"
    FILES = (CONFIG, PROGRESS, CHECKPOINT, POLICY, CURVE)  # a run's files: what a new run in the folder replaces
    RESUMABLE = (CONFIG, PROGRESS, CHECKPOINT, POLICY)  # what a run carries on from (curve.png is drawn from them)

    def __init__(self, path):
        self.path = Path(path)
        self.config_json = self.path / self.CONFIG
        self.progress_csv = self.path / self.PROGRESS
        self.checkpoint_npz = self.path / self.CHECKPOINT
        self.policy_npz = self.path / self.POLICY
        self.curve_png = self.path / self.CURVE

    def __repr__(self) -> str:
        return f"RunFolder({str(self.path)!r})"

    # the rules: a new run, a resumed one, an extended one

    def check_new(self, force: bool = False) -> None:
        """Refuse a new run into a folder that holds files, unless ``force``. Nothing is removed here: ``start``
        removes the old run's files, once the new run's Trainer exists."""
        if self.path.exists() and any(self.path.iterdir()) and not force:
            raise MinippoError(f"{self.path} exists and is not empty; pass --force to replace or --resume to continue")

    def resumed_config(self, steps: int | None = None) -> Config | None:
        """The Config with which the run goes on from its checkpoint (with ``steps``, extended to that many steps), or
        None when it has finished already (and said so on stderr)."""
        done = self.checkpoint_update()
        if done is None and self.checkpoint_npz.exists():
            raise MinippoError(f"--resume: cannot read {self.checkpoint_npz}")
        if done is None:
            raise MinippoError(f"--resume: no checkpoint in {self.path}")
        config = self.read_config()
        trained = done * config.batch_size
        if steps is not None and steps != config.total_steps:
            extended = dataclasses.replace(config, total_steps=steps).validate()
            if extended.num_updates < done:
                raise MinippoError(
                    f"--resume --steps {steps:,}: the run has already trained {trained:,} steps ({done} updates)"
                )
            if config.anneal_lr and extended.num_updates != config.num_updates:
                say(
                    f"the learning rate of updates 1-{done} was annealed over {config.num_updates} updates, not "
                    f"{extended.num_updates}: the extended run differs from one trained to {steps:,} steps from the "
                    "start (--no-anneal-lr makes runs that extend exactly)"
                )
            config = extended
        if done >= config.num_updates:
            say(
                f"{self.path} has finished ({trained:,} steps, {done} updates); to train it further: minippo train "
                f"{config.env_id} --out {self.path} --resume --steps N, N > {trained:,}"
            )
            return None
        return config

    def read_config(self) -> Config:
        try:
            return Config.from_dict(json.loads(self.config_json.read_text()))
        except (FileNotFoundError, json.JSONDecodeError) as error:
            raise MinippoError(f"--resume: cannot read {self.config_json} ({error})")

    def checkpoint_update(self) -> int | None:
        """The update of the folder's checkpoint, or None when it has none (or none that can be read)."""
        return checkpoint_update(self.checkpoint_npz)

    # a run's life: started (or resumed), an update's row, a checkpoint

    def start(self, trainer, resume: bool = False) -> list[dict]:
        """With ``resume`` and a checkpoint, load it into ``trainer`` and keep the rows of its updates; else remove an
        earlier run's files. Then write config.json and progress.csv. Returns the rows kept."""
        self.path.mkdir(parents=True, exist_ok=True)
        rows = []
        with self.writing(trainer):
            if resume and self.checkpoint_npz.exists():
                notice = trainer.load_state_dict(load_checkpoint(self.checkpoint_npz))
                if notice:
                    say(notice)
                rows = self.progress_until(trainer.update)
            else:
                self.remove(self.FILES)
            text = json.dumps(trainer.config.to_dict(), indent=2) + "\n"
            write_atomically(self.config_json, lambda handle: handle.write(text.encode()))
            write_rows(self.progress_csv, PROGRESS_FIELDS, [csv_row(row) for row in rows])
        return rows

    def write_update(self, trainer, row: dict, checkpoint: bool) -> None:
        """Append the update's row to progress.csv, then write the checkpoint when it is time for one."""
        with self.writing(trainer):
            append_row(self.progress_csv, PROGRESS_FIELDS, csv_row(row), durable=False)
            if checkpoint:
                self.save(trainer)

    def save(self, trainer) -> None:
        """Write checkpoint.npz (the trainer's ``state_dict``), then policy.npz, each whole or not at all."""
        save_checkpoint(self.checkpoint_npz, trainer.state_dict())
        meta = {"env_id": trainer.config.env_id, "update": trainer.update}
        save_policy(self.policy_npz, trainer.agent, trainer.obs_normalizer, meta)

    @contextmanager
    def writing(self, trainer):
        """A file that cannot be written (a full disk, no permission) stops the run with one line."""
        try:
            yield
        except OSError as error:
            kept = self.checkpoint_update()
            kept = "no checkpoint yet" if kept is None else f"the checkpoint of update {kept} is kept"
            reason = error.strerror or str(error)
            raise MinippoError(
                f"cannot write the run's files in {self.path} ({reason}) at update {trainer.update}; {kept}"
            )

    def progress_until(self, update: int) -> list[dict]:
        """progress.csv's rows of updates 1 … ``update`` (the checkpoint's), read back to the numbers they were
        written from: the rows a killed run wrote after its last checkpoint, and a row cut short by the kill, are
        dropped."""
        try:
            rows = [
                {key: (int if key in COUNTS else float)(row[key]) for key in PROGRESS_FIELDS}
                for row in read_rows(self.progress_csv)[:update]
            ]
        except (KeyError, TypeError, ValueError):
            rows = None
        if rows is None or [row["update"] for row in rows] != list(range(1, update + 1)):
            raise MinippoError(
                f"{self.progress_csv} does not hold the rows of updates 1 to {update}, the checkpoint's; cannot resume"
            )
        return rows

    # the files as bytes: a sweep's run trains in a scratch folder and hands them to the driver

    def files(self, names=FILES) -> dict[str, bytes]:
        """{name: contents} of the run's files ``names`` that the folder holds."""
        return {name: (self.path / name).read_bytes() for name in names if (self.path / name).is_file()}

    def write_files(self, files: dict[str, bytes]) -> None:
        """Write ``files`` ({name: contents}, as ``files`` gives them) into the folder, each whole, and remove the
        run's other files (an earlier attempt's must not outlive it)."""
        self.path.mkdir(parents=True, exist_ok=True)
        self.remove([name for name in self.FILES if name not in files])
        for name, data in files.items():
            write_atomically(self.path / name, lambda handle, data=data: handle.write(data))

    def remove(self, names) -> None:
        for name in names:
            (self.path / name).unlink(missing_ok=True)


def say(notice: str) -> None:
    """A one-line notice on stderr: the run goes on, but not quite as asked."""
    print(f"minippo: {notice}", file=sys.stderr)


def csv_row(row: dict) -> dict:
    """A progress row as progress.csv holds it: floats by repr, which reads back to the same float."""
    return {key: (repr(value) if isinstance(value, float) else value) for key, value in row.items()}
