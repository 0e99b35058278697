"""The actor-critic: the policy π_θ and the value function V, as two MLPs (the paper's MuJoCo setup) or one shared
trunk with two heads (eq. 9), the trunk a tanh MLP or, for images, a small convolutional network (the paper's Atari
setup, in MinAtar's size); all parameters in one flat vector. Saving and loading the policy live here too."""

from __future__ import annotations

import json
import zipfile

import numpy as np

from minippo.conv import ConvTrunk
from minippo.distributions import Categorical, DiagGaussian
from minippo.errors import MinippoError
from minippo.network import MLP
from minippo.normalization import ObservationNormalizer
from minippo.records import write_atomically

SQRT2 = float(np.sqrt(2.0))
NETWORKS = ("mlp", "minatar_cnn")


class ActorCritic:
    def __init__(
        self,
        obs_dim: int,
        kind: str,
        act_dim: int,
        hidden_sizes=(64, 64),
        shared: bool = False,
        log_std_init: float = 0.0,
        orthogonal_init: bool = True,
        rng: np.random.Generator | None = None,
        dtype="float64",
        network: str = "mlp",
        image_shape: tuple[int, int, int] | None = None,
    ):
        if kind not in ("discrete", "continuous"):
            raise ValueError(f"kind must be 'discrete' or 'continuous', not {kind!r}")
        if network not in NETWORKS:
            raise ValueError(f"network must be one of {', '.join(NETWORKS)}, not {network!r}")
        self.obs_dim, self.kind, self.act_dim = int(obs_dim), kind, int(act_dim)
        self.hidden_sizes, self.shared = tuple(int(h) for h in hidden_sizes), bool(shared)
        self.network = network
        self.image_shape = None if image_shape is None else tuple(int(s) for s in image_shape)
        hidden = self.hidden_sizes

        def mlp(sizes, activate):
            return lambda params=None, grads=None: MLP(sizes, activate_output=activate, params=params, grads=grads)

        if network == "minatar_cnn":  # conv(16, 3×3) → ReLU → dense 128 → ReLU, read by both heads (eq. 9)
            if self.image_shape is None or len(self.image_shape) != 3 or np.prod(self.image_shape) != self.obs_dim:
                raise ValueError(f"network 'minatar_cnn' needs images (H, W, C) of {obs_dim} numbers")
            self.shared = True

            def conv(params=None, grads=None):
                return ConvTrunk(self.image_shape, params=params, grads=grads)

            features = conv().dense_shape[1]
            specs = [  # (name, a maker of the net on given buffers, output gain)
                ("trunk", conv, SQRT2),
                ("policy", mlp((features, act_dim), False), 0.01),
                ("value", mlp((features, 1), False), 1.0),
            ]
        elif shared:
            specs = [
                ("trunk", mlp((obs_dim, *hidden), True), SQRT2),  # tanh after the trunk's last layer too
                ("policy", mlp((hidden[-1], act_dim), False), 0.01),
                ("value", mlp((hidden[-1], 1), False), 1.0),
            ]
        else:
            specs = [
                ("policy", mlp((obs_dim, *hidden, act_dim), False), 0.01),
                ("value", mlp((obs_dim, *hidden, 1), False), 1.0),
            ]
        sizes = [make().n_params for _, make, _ in specs]
        n_log_std = act_dim if kind == "continuous" else 0
        self.dtype = np.dtype(dtype)  # float64 for gradient checks; training defaults to float32 (Config.dtype)
        self.params = np.zeros(sum(sizes) + n_log_std, dtype=self.dtype)
        self.grads = np.zeros_like(self.params)
        offset, self.nets = 0, {}
        for (name, make, _), size in zip(specs, sizes):
            view = slice(offset, offset + size)
            self.nets[name] = make(self.params[view], self.grads[view])
            offset += size
        self.log_std = self.params[offset:]
        self.grad_log_std = self.grads[offset:]
        if rng is not None:
            for name, _, gain in specs:
                self.nets[name].init(rng, gain, SQRT2, orthogonal_init)
            self.log_std[...] = log_std_init

    def copy(self) -> ActorCritic:
        """A twin with its own parameters, equal to these (π_ref and the policy fine-tuned from it start so)."""
        twin = ActorCritic(
            self.obs_dim, self.kind, self.act_dim, self.hidden_sizes, shared=self.shared, dtype=self.dtype,
            network=self.network, image_shape=self.image_shape,
        )  # fmt: skip
        twin.params[...] = self.params
        return twin

    # forward and backward over a batch of (normalised) observations

    def forward(self, obs: np.ndarray):
        """Return (distribution parameters (logits or mean), values V(s) of shape (n,), cache)."""
        obs = obs.astype(self.dtype, copy=False)
        if self.shared:
            features, trunk_cache = self.nets["trunk"].forward(obs)
            out, policy_cache = self.nets["policy"].forward(features)
            values, value_cache = self.nets["value"].forward(features)
            return out, values[:, 0], (trunk_cache, policy_cache, value_cache)
        out, policy_cache = self.nets["policy"].forward(obs)
        values, value_cache = self.nets["value"].forward(obs)
        return out, values[:, 0], (None, policy_cache, value_cache)

    def backward(self, cache, grad_out: np.ndarray, grad_values: np.ndarray, grad_log_std=None) -> None:
        """Fill ``self.grads`` with dL/dθ, given dL/d(distribution parameters), dL/dV and dL/d log σ."""
        trunk_cache, policy_cache, value_cache = cache
        grad_features = self.nets["policy"].backward(policy_cache, grad_out, need_grad_input=self.shared)
        grad_from_value = self.nets["value"].backward(value_cache, grad_values[:, None], need_grad_input=self.shared)
        if self.shared:  # both heads read the trunk's features, so their gradients add up there
            self.nets["trunk"].backward(trunk_cache, grad_features + grad_from_value)
        if self.kind == "continuous":
            self.grad_log_std[...] = 0.0 if grad_log_std is None else grad_log_std

    def distribution(self, out: np.ndarray, log_std: np.ndarray | None = None):
        """π(·|s) from the network's output: logits, or the mean with log σ (the live one unless ``log_std`` is given,
        as it is for the old policy of a stored batch)."""
        if self.kind == "discrete":
            return Categorical(out)
        return DiagGaussian(out, self.log_std if log_std is None else log_std)

    def policy_output(self, obs: np.ndarray) -> np.ndarray:
        """Logits or mean only, for acting (the rollout's hot path: no cache, no value)."""
        obs = obs.astype(self.dtype, copy=False)
        if self.shared:
            return self.nets["policy"](self.nets["trunk"](obs))
        return self.nets["policy"](obs)

    def value(self, obs: np.ndarray) -> np.ndarray:
        obs = obs.astype(self.dtype, copy=False)
        features = self.nets["trunk"](obs) if self.shared else obs
        return self.nets["value"](features)[:, 0]

    def meta(self) -> dict:
        return {
            "obs_dim": self.obs_dim,
            "kind": self.kind,
            "act_dim": self.act_dim,
            "hidden_sizes": list(self.hidden_sizes),
            "dtype": self.dtype.name,
            "shared": self.shared,
            "network": self.network,
            "image_shape": None if self.image_shape is None else list(self.image_shape),
        }


def save_policy(path, agent: ActorCritic, obs_normalizer, extra: dict | None = None) -> None:
    """Write the weights and the observation statistics to ``path`` (.npz), atomically."""
    meta = {
        **agent.meta(),
        **(extra or {}),
        "normalize_observations": obs_normalizer.enabled,
        "obs_clip": obs_normalizer.clip,
    }
    stats = {f"obs_{key}": value for key, value in obs_normalizer.state_dict().items()}  # obs_mean, obs_var, obs_count
    write_atomically(
        path,
        lambda handle: np.savez(handle, params=agent.params, meta=np.array(json.dumps(meta)), **stats),
    )


def load_policy(path):
    """Return (agent, obs_normalizer, meta) from a policy.npz, or raise a one-line MinippoError."""
    try:
        with np.load(path, allow_pickle=False) as data:
            stored = {key: data[key] for key in data.files}
        meta = json.loads(str(stored["meta"]))
        agent = ActorCritic(
            meta["obs_dim"],
            meta["kind"],
            meta["act_dim"],
            meta["hidden_sizes"],
            meta["shared"],
            dtype=meta.get("dtype", "float64"),
            network=meta.get("network", "mlp"),
            image_shape=meta.get("image_shape"),
        )
        if stored["params"].shape != agent.params.shape:
            raise ValueError("weights of the wrong size")
        agent.params[...] = stored["params"]
        normalizer = ObservationNormalizer((meta["obs_dim"],), meta["obs_clip"], meta["normalize_observations"])
        normalizer.load_state_dict({key: stored[f"obs_{key}"] for key in ("mean", "var", "count")})
    except FileNotFoundError:
        raise MinippoError(f"no policy at {path}")
    except (OSError, ValueError, KeyError, zipfile.BadZipFile, json.JSONDecodeError, EOFError) as error:
        # NumPy's own message may advise allow_pickle, which would run code from the file: say it in our words
        reason = {
            zipfile.BadZipFile: "not an .npz archive",
            KeyError: f"no entry {error}",
            json.JSONDecodeError: "its description is not JSON",
            EOFError: "the file ends early",
        }.get(type(error), "its weights do not fit" if "wrong size" in str(error) else "not an .npz archive")
        raise MinippoError(f"cannot read the policy {path}: it is corrupted or not a minippo policy ({reason})")
    if not np.all(np.isfinite(agent.params)):
        raise MinippoError(f"the policy {path} holds NaN or infinite weights")
    return agent, normalizer, meta
