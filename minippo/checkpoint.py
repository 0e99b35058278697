"""A run's checkpoint: the state of a ``Trainer`` between two updates, written so that an interruption (a kill, a
full disk, Ctrl-C) never leaves half of it, and read back so that a resumed run is the uninterrupted one."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from minippo.agent_files import save_policy
from minippo.records import write_atomically


def trainer_state(trainer) -> dict:
    """Everything the next update depends on, so that a resumed run is the uninterrupted run."""
    return {
        "params": trainer.agent.params.copy(),
        "update": np.array(trainer.update),
        "wall_s": np.array(trainer.wall_s),
        "kl_beta": np.array(trainer.kl_beta),
        "rng": np.array(json.dumps(trainer.rng.bit_generator.state)),
        "reward_discounted": trainer.reward_scaler.discounted,
        **trainer.rollout.state(),
        **{f"adam_{k}": v for k, v in trainer.optimizer.state_dict().items()},
        **trainer.obs_normalizer.stats.state("obs"),
        **trainer.reward_scaler.stats.state("ret"),
    }


def load_trainer_state(trainer, state: dict) -> str | None:
    """Carry on from ``state``; returns a one-line notice when the run cannot go on exactly as it would have."""
    trainer.agent.params[...] = state["params"]
    trainer.update = int(state["update"])
    trainer.wall_s = float(state["wall_s"])
    trainer.kl_beta = float(state["kl_beta"])
    trainer.rng.bit_generator.state = json.loads(str(state["rng"]))
    trainer.reward_scaler.discounted = np.array(state["reward_discounted"], dtype=np.float64)
    trainer.optimizer.load_state_dict({k[5:]: v for k, v in state.items() if k.startswith("adam_")})
    trainer.obs_normalizer.stats.load(state, "obs")
    trainer.obs_normalizer.refresh()
    trainer.reward_scaler.stats.load(state, "ret")
    if trainer.rollout.load_state(state, trainer.config.seed + 10_000 * trainer.update):
        return None
    return (
        f"the checkpoint holds no state of the {trainer.config.env_id} environments (minippo cannot save them, or "
        "an older minippo wrote it): they start fresh episodes, so the run goes on differently from one never "
        "interrupted"
    )


def save_checkpoint(out: Path, trainer) -> None:
    """Write checkpoint.npz, then policy.npz, each whole or not at all."""
    state = trainer_state(trainer)
    write_atomically(out / "checkpoint.npz", lambda handle: np.savez(handle, **state))
    save_policy(
        out / "policy.npz",
        trainer.agent,
        trainer.obs_normalizer,
        {"env_id": trainer.config.env_id, "update": trainer.update},
    )


def checkpoint_update(out) -> int | None:
    """The update of the checkpoint in the run folder ``out``, or None when it has none (or none that can be read)."""
    try:
        with np.load(Path(out) / "checkpoint.npz", allow_pickle=False) as data:
            return int(data["update"])
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        return None
