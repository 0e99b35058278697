"""Every setting of a PPO run: ``Config``, frozen, each field with its type, default and meaning.

The command line is made from it (``minippo train --clip-epsilon 0.1``: a flag for every field), and so is the run
folder's config.json. Change a setting with ``dataclasses.replace(config, lr=1e-3)`` or ``config.with_overrides``.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import typing
from dataclasses import dataclass

from minippo.errors import ConfigError, MinippoError

OBJECTIVES = ("clip", "cpi", "klpen", "pg")
NETWORKS = ("mlp", "minatar_cnn")  # the actor-critic's trunks (minippo/agent.py)
DTYPES = ("float32", "float64")
TRUE, FALSE = ("true", "1", "yes", "on"), ("false", "0", "no", "off")


def setting(default, help: str, choices: tuple[str, ...] | None = None):
    """A field of ``Config`` with its meaning (the command line's help) and, for a word, the words it may be."""
    return dataclasses.field(default=default, metadata={"help": help, "choices": choices})


@dataclass(frozen=True)
class Config:
    """Defaults are the paper's MuJoCo settings (Table 3) and the "37 details" (Huang et al. 2022)."""

    env_id: str = setting("Hopper-v5", "a Gymnasium id with flat or image (H, W, C) Box observations")
    total_steps: int = setting(1_000_000, "environment steps in all (the paper: 1M for MuJoCo)")
    seed: int = setting(1, "seeds the initialisation, the action noise, the minibatch order and the environments")
    objective: str = setting(
        "clip", "clip (eq. 7) | cpi (eq. 6, no clipping or penalty) | klpen (eq. 8) | pg (eq. 2)", OBJECTIVES
    )
    # Algorithm 1
    num_envs: int = setting(1, "N, the actors (environments stepped side by side)")
    horizon: int = setting(2048, "T, the steps each actor collects per update")
    epochs: int = setting(10, "K, the passes over each batch")
    minibatch_size: int = setting(64, "M, the samples of one Adam step")
    gamma: float = setting(0.99, "γ, the discount")
    gae_lambda: float = setting(0.95, "λ of GAE (eq. 11)")
    clip_epsilon: float = setting(0.2, "ε, the clip range of eq. 7 (and of the value clip)")
    anneal_clip: bool = setting(False, "ε falls linearly to 0 with the step size α (the paper's Atari setting)")
    # eq. 8: the KL penalty (objective = klpen)
    kl_beta: float = setting(1.0, "β, the KL penalty's initial weight")
    kl_target: float = setting(0.01, "d_targ, the KL that β adapts towards")
    adaptive_kl: bool = setting(True, "β halves or doubles after each update (false: β stays fixed)")
    # eq. 9: one objective for policy, value and entropy
    value_coef: float = setting(0.5, "c1, the weight of the value loss ½ Ê[(V − V^targ)²] (with its ½; eq. 9)")
    entropy_coef: float = setting(0.0, "c2, the entropy bonus's weight (the paper uses none for MuJoCo)")
    shared_network: bool = setting(False, "one tanh trunk, a policy head and a value head")
    hidden_sizes: tuple[int, ...] = setting((64, 64), "the tanh layers' widths, for the policy and the value network")
    network: str = setting(
        "mlp", "mlp (tanh layers of hidden_sizes) | minatar_cnn (conv 16 3×3, dense 128, shared)", NETWORKS
    )
    dtype: str = setting("float32", "the networks' floats (the gradient checks use float64)", DTYPES)
    log_std_init: float = setting(0.0, "log σ of the Gaussian policy at the start, for every action")
    # the implementation details, each a switch
    lr: float = setting(3e-4, "α, Adam's step size (the paper's Table 3)")
    adam_eps: float = setting(1e-5, "Adam's ε in the denominator (PyTorch's default is 1e-8)")
    anneal_lr: bool = setting(True, "α falls linearly to 0 over the run")
    use_gae: bool = setting(True, "GAE (false: Â = discounted return − V)")
    shuffle_minibatches: bool = setting(True, "a new random order of the batch every epoch")
    normalize_advantages: bool = setting(True, "Â to mean 0 and std 1 in each minibatch")
    clip_value_loss: bool = setting(True, "V may move at most ±ε from the rollout's value (pessimistic max)")
    grad_norm_clipping: bool = setting(True, "scale the whole gradient down to norm max_grad_norm when larger")
    max_grad_norm: float = setting(0.5, "the global gradient norm limit")
    orthogonal_init: bool = setting(True, "orthogonal weights (gain √2, 0.01, 1), zero biases; else LeCun-uniform")
    normalize_observations: bool = setting(True, "running mean/std of observations, updated between batches")
    obs_clip: float = setting(10.0, "normalised observations are clipped to ±obs_clip")
    scale_rewards: bool = setting(True, "divide rewards by the running std of the discounted return")
    reward_clip: float = setting(10.0, "scaled rewards are clipped to ±reward_clip")
    clip_actions: bool = setting(True, "clip to the action bounds when stepping; the unclipped action is stored")
    target_kl: float | None = setting(None, "stop the epochs early once approx KL exceeds this (off in the paper)")
    checkpoint_every: int = setting(10, "updates between checkpoints (for --resume and for NaN recovery)")

    @property
    def batch_size(self) -> int:
        return self.num_envs * self.horizon

    @property
    def num_updates(self) -> int:
        return max(1, self.total_steps // self.batch_size)

    def validate(self) -> Config:
        """The same Config, or a ConfigError that names the field at fault."""

        def check(ok: bool, name: str, message: str) -> None:
            if not ok:
                raise ConfigError(name, f"{name} {message}")

        for name, words in choices().items():
            value = getattr(self, name)
            check(value in words, name, f"must be one of {', '.join(words)}, not '{value}'")
        check(0 < self.total_steps <= 10**10, "total_steps", f"must be between 1 and 10^10, not {self.total_steps}")
        for name in ("num_envs", "horizon", "epochs", "minibatch_size"):
            check(getattr(self, name) >= 1, name, f"must be a positive integer, not {getattr(self, name)}")
        check(self.minibatch_size <= self.batch_size, "minibatch_size",
              f"{self.minibatch_size} exceeds the batch N·T = {self.batch_size}")  # fmt: skip
        for name in ("gamma", "gae_lambda"):
            check(0 <= getattr(self, name) <= 1, name, f"must lie in [0, 1], not {getattr(self, name)}")
        check(self.network == "mlp" or self.shared_network, "shared_network",
              f"must be true with network={self.network}, whose one trunk feeds both heads")  # fmt: skip
        for name in ("clip_epsilon", "lr"):
            check(getattr(self, name) > 0, name, f"must be positive, not {getattr(self, name)}")
        return self

    @classmethod
    def field_help(cls) -> dict[str, tuple[object, str]]:
        """{field: (default, meaning)}, in the order of the fields."""
        return {f.name: (f.default, f.metadata["help"]) for f in dataclasses.fields(cls)}

    @classmethod
    def parse_value(cls, name: str, text: str):
        """A field's value from its text ('3e-4', 'false', '64,64', 'none'), read as the field's type says."""
        name = name.strip().replace("-", "_")
        types = field_types()
        if name not in types:
            close = difflib.get_close_matches(name, list(types), n=3)
            hint = f"; did you mean {', '.join(close)}?" if close else ""
            raise ConfigError(name, f"unknown config field '{name}'{hint}")
        kind, raw = types[name], text.strip()
        try:
            if raw.lower() == "none" and kind is not str:
                if type(None) not in typing.get_args(kind):
                    raise ValueError
                return None
            if kind is bool:
                if raw.lower() not in TRUE + FALSE:
                    raise ValueError
                return raw.lower() in TRUE
            if kind is int:
                return int(float(raw)) if float(raw).is_integer() else int(raw)
            if kind in (float, float | None):
                return float(raw)
            if typing.get_origin(kind) is tuple:
                return tuple(int(x) for x in raw.split(",") if x)
            return raw
        except ValueError:
            raise ConfigError(name, f"{name}: cannot read '{raw}' as {type_name(kind)}") from None

    @classmethod
    def parse_overrides(cls, texts) -> dict:
        """{field: value} of 'key=value' texts (``--config``), each value read as its field's type says."""
        changes = {}
        for text in texts:
            if "=" not in text:
                raise ConfigError("", f"'{text}' is not key=value")
            key, raw = text.split("=", 1)
            key = key.strip().replace("-", "_")
            changes[key] = cls.parse_value(key, raw)
        return changes

    def with_overrides(self, texts) -> Config:
        """A copy with 'key=value' overrides (``--config``)."""
        return dataclasses.replace(self, **self.parse_overrides(texts))

    def to_dict(self) -> dict:
        data = dataclasses.asdict(self)
        data["hidden_sizes"] = list(self.hidden_sizes)
        return data

    @classmethod
    def from_dict(cls, data: dict) -> Config:
        known = {f.name for f in dataclasses.fields(cls)}
        data = {key: value for key, value in data.items() if key != "extra" or value}  # an empty field of old runs
        unknown = set(data) - known
        if unknown:
            raise MinippoError(f"unknown config field(s): {', '.join(sorted(unknown))}")
        data = dict(data)
        if "hidden_sizes" in data:
            data["hidden_sizes"] = tuple(data["hidden_sizes"])
        return cls(**data)


@functools.cache
def field_types() -> dict[str, object]:
    """Each field's type, read from its annotation (``int``, ``float | None``, ``tuple[int, ...]`` …)."""
    return typing.get_type_hints(Config)


def choices() -> dict[str, tuple[str, ...]]:
    """The fields that take one of a few words, with their words."""
    return {f.name: f.metadata["choices"] for f in dataclasses.fields(Config) if f.metadata["choices"]}


def type_name(kind) -> str:
    """How a field's type is said in an error: int, float, bool, str, or a list of int (for a tuple)."""
    if typing.get_origin(kind) is tuple:
        return "a comma-separated list of int"
    if kind == float | None:
        return "float or none"
    return kind.__name__
