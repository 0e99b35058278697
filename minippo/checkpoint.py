"""A run's checkpoint: one dict, the ``Trainer``'s ``state_dict``, written to an .npz so that an interruption (a kill,
a full disk, Ctrl-C) never leaves half of it, and read back whole so that a resumed run is the uninterrupted one.

The dict's parts are dicts of their own (``{"optimizer": {"m": …, "v": …, "t": …}, …}``, as nanoGPT's checkpoint
holds the model's and the optimiser's); the .npz holds each array under its keys joined by ``/`` (``optimizer/m``),
with ``format``, the layout's number. A checkpoint of format 1 (minippo 0.1.0, every part's keys side by side:
``adam_m``, ``obs_mean``, ``steps``) is read into today's layout, so that a run it began resumes as it would have.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from minippo.errors import MinippoError
from minippo.records import write_atomically

FORMAT = 2
FIRST_FORMAT = {"adam_": "optimizer/", "obs_": "obs_normalizer/", "ret_": "reward_scaler/", "reward_": "reward_scaler/"}
FIRST_FORMAT_TOP = ("update", "wall_s", "kl_beta", "rng", "params")  # format 1's other keys were the rollout's


def save_checkpoint(path, state: dict) -> None:
    """Write ``state`` (dicts of arrays, numbers and texts, nested) to the .npz ``path``, whole or not at all."""
    flat = {"format": np.array(FORMAT), **flatten(state)}
    write_atomically(Path(path), lambda handle: np.savez(handle, **flat))


def load_checkpoint(path) -> dict:
    """The dict ``save_checkpoint`` wrote to ``path`` (its numbers and texts as 0-d arrays), or a one-line
    MinippoError when it cannot be read."""
    try:
        with np.load(path, allow_pickle=False) as data:
            flat = {key: data[key] for key in data.files}
    except FileNotFoundError:
        raise MinippoError(f"no checkpoint at {path}") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile):
        raise MinippoError(f"cannot read the checkpoint {path}: it is corrupted or not a minippo checkpoint") from None
    written = int(flat.pop("format", 1))
    if written == 1:
        flat = {first_format_key(key): value for key, value in flat.items()}
    elif written != FORMAT:
        raise MinippoError(
            f"the checkpoint {path} has format {written}, which this minippo (format {FORMAT}) cannot read: resume "
            "it with the minippo that wrote it"
        )
    return unflatten(flat)


def checkpoint_update(path) -> int | None:
    """The update of the checkpoint at ``path``, or None when there is none (or none that can be read)."""
    try:
        with np.load(path, allow_pickle=False) as data:
            return int(data["update"])
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):
        return None


def flatten(state: dict, prefix: str = "") -> dict:
    """{"optimizer": {"m": m}} -> {"optimizer/m": m}, each leaf an array."""
    flat = {}
    for key, value in state.items():
        if isinstance(value, dict):
            flat |= flatten(value, f"{prefix}{key}/")
        else:
            flat[prefix + key] = np.asarray(value)
    return flat


def unflatten(flat: dict) -> dict:
    """{"optimizer/m": m} -> {"optimizer": {"m": m}}."""
    state: dict = {}
    for key, value in flat.items():
        *parts, name = key.split("/")
        node = state
        for part in parts:
            node = node.setdefault(part, {})
        node[name] = value
    return state


def first_format_key(key: str) -> str:
    """A key of format 1 as format 2 names it: adam_m -> optimizer/m, ret_mean -> reward_scaler/mean, steps ->
    rollout/steps."""
    if key in FIRST_FORMAT_TOP:
        return key
    for old, new in FIRST_FORMAT.items():
        if key.startswith(old):
            return new + key[len(old) :]
    return "rollout/" + key
