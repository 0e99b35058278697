"""The actor-critic: the policy π_θ and the value function V, as two MLPs (the paper's MuJoCo setup) or one shared
trunk with two heads (eq. 9), the trunk a tanh MLP or, for images, a small convolutional network (the paper's Atari
setup, in MinAtar's size); all parameters in one flat vector. ``AgentSpec`` says what the agent is, and
``ActorCritic(spec, rng)`` builds it (minippo/agent_files.py saves it and reads it back)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from minippo.config import NETWORKS
from minippo.conv import ConvTrunk
from minippo.distributions import Categorical, DiagGaussian
from minippo.network import MLP

SQRT2 = float(np.sqrt(2.0))


@dataclass(frozen=True)
class AgentSpec:
    """What an agent is: everything its constructor needs, and all that a policy file records of it
    (``dataclasses.asdict(spec)``). ``ppo.spec_from(config, env)`` gives the one a run trains."""

    obs_dim: int  # the observation's size (an image's H·W·C)
    kind: str  # "discrete" (a categorical over act_dim actions) or "continuous" (a Gaussian of act_dim numbers)
    act_dim: int
    hidden_sizes: tuple[int, ...] = (64, 64)  # the tanh layers' widths
    shared: bool = False  # one trunk read by a policy head and a value head (eq. 9), or two networks
    network: str = "mlp"  # the trunk: tanh layers of hidden_sizes, or minatar_cnn for images
    image_shape: tuple[int, int, int] | None = None  # (H, W, C) of image observations
    dtype: str = "float64"  # float64 for gradient checks; training defaults to float32 (Config.dtype)
    log_std_init: float = 0.0  # log σ of the Gaussian at the start
    orthogonal_init: bool = True  # orthogonal weights (gain √2, 0.01, 1), zero biases; else LeCun-uniform

    def __post_init__(self):
        if self.kind not in ("discrete", "continuous"):
            raise ValueError(f"kind must be 'discrete' or 'continuous', not {self.kind!r}")
        if self.network not in NETWORKS:
            raise ValueError(f"network must be one of {', '.join(NETWORKS)}, not {self.network!r}")
        if self.network == "minatar_cnn":
            shape = self.image_shape
            if shape is None or len(shape) != 3 or np.prod(shape) != self.obs_dim:
                raise ValueError(f"network 'minatar_cnn' needs images (H, W, C) of {self.obs_dim} numbers")
            if not self.shared:
                raise ValueError("network 'minatar_cnn' has one trunk for both heads: shared must be True")


class ActorCritic:
    def __init__(self, spec: AgentSpec, rng: np.random.Generator | None = None):
        """The agent ``spec`` describes, initialised from ``rng`` (None: all parameters 0, to be filled in)."""
        self.spec = spec
        self.obs_dim, self.kind, self.act_dim, self.shared = spec.obs_dim, spec.kind, spec.act_dim, spec.shared
        obs_dim, act_dim, hidden = spec.obs_dim, spec.act_dim, spec.hidden_sizes

        def mlp(sizes, activate):
            return lambda params=None, grads=None: MLP(sizes, activate_output=activate, params=params, grads=grads)

        if spec.network == "minatar_cnn":  # conv(16, 3×3) → ReLU → dense 128 → ReLU, read by both heads (eq. 9)

            def conv(params=None, grads=None):
                return ConvTrunk(spec.image_shape, params=params, grads=grads)

            features = conv().dense_shape[1]
            specs = [  # (name, a maker of the net on given buffers, output gain)
                ("trunk", conv, SQRT2),
                ("policy", mlp((features, act_dim), False), 0.01),
                ("value", mlp((features, 1), False), 1.0),
            ]
        elif spec.shared:
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
        n_log_std = act_dim if spec.kind == "continuous" else 0
        self.dtype = np.dtype(spec.dtype)
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
                self.nets[name].init(rng, gain, SQRT2, spec.orthogonal_init)
            self.log_std[...] = spec.log_std_init

    def copy(self) -> ActorCritic:
        """A twin with its own parameters, equal to these (π_ref and the policy fine-tuned from it start so)."""
        twin = ActorCritic(self.spec)
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
