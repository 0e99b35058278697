"""An agent's file, policy.npz: its weights, its observation statistics, and what it is (``asdict(spec)``) with what the
run adds (the environment's id, the update), written whole or not at all and read back with a one-line error."""

from __future__ import annotations

import json
import zipfile
from dataclasses import MISSING, asdict, fields

import numpy as np

from minippo.agent import ActorCritic, AgentSpec
from minippo.errors import MinippoError
from minippo.normalization import ObservationNormalizer
from minippo.records import write_atomically


def save_policy(path, agent: ActorCritic, obs_normalizer, extra: dict | None = None) -> None:
    """Write the weights and the observation statistics to ``path`` (.npz), atomically."""
    meta = {
        **asdict(agent.spec),
        **(extra or {}),
        "normalize_observations": obs_normalizer.enabled,
        "obs_clip": obs_normalizer.clip,
    }
    stats = {f"obs_{key}": value for key, value in obs_normalizer.state_dict().items()}  # obs_mean, obs_var, obs_count
    write_atomically(
        path,
        lambda handle: np.savez(handle, params=agent.params, meta=np.array(json.dumps(meta)), **stats),
    )


def spec_of(meta: dict) -> AgentSpec:
    """The AgentSpec a policy file's description records (JSON's lists made tuples again; a field that an older file
    lacks takes its default; a file without obs_dim, kind or act_dim raises KeyError)."""
    given = {f.name: meta[f.name] for f in fields(AgentSpec) if f.name in meta or f.default is MISSING}
    for name in ("hidden_sizes", "image_shape"):
        if given.get(name) is not None:
            given[name] = tuple(given[name])
    return AgentSpec(**given)


def load_policy(path):
    """Return (agent, obs_normalizer, meta) from a policy.npz, or raise a one-line MinippoError."""
    try:
        with np.load(path, allow_pickle=False) as data:
            stored = {key: data[key] for key in data.files}
        meta = json.loads(str(stored["meta"]))
        agent = ActorCritic(spec_of(meta))
        if stored["params"].shape != agent.params.shape:
            raise ValueError("weights of the wrong size")
        agent.params[...] = stored["params"]
        normalizer = ObservationNormalizer((meta["obs_dim"],), meta["obs_clip"], meta["normalize_observations"])
        normalizer.load_state_dict({key: stored[f"obs_{key}"] for key in ("mean", "var", "count")})
    except FileNotFoundError:
        raise MinippoError(f"no policy at {path}")
    except (OSError, ValueError, KeyError, TypeError, zipfile.BadZipFile, json.JSONDecodeError, EOFError) as error:
        # NumPy's own message may advise allow_pickle, which would run code from the file: say it in our words
        reason = {
            zipfile.BadZipFile: "not an .npz archive",
            KeyError: f"no entry {error}",
            TypeError: "its description is not an agent's",
            json.JSONDecodeError: "its description is not JSON",
            EOFError: "the file ends early",
        }.get(type(error), "its weights do not fit" if "wrong size" in str(error) else "not an .npz archive")
        raise MinippoError(f"cannot read the policy {path}: it is corrupted or not a minippo policy ({reason})")
    if not np.all(np.isfinite(agent.params)):
        raise MinippoError(f"the policy {path} holds NaN or infinite weights")
    return agent, normalizer, meta
