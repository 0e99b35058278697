"""Proximal Policy Optimization, Algorithm 1 of Schulman et al. (2017), read top to bottom in ``train``.

    for iteration = 1, 2, ...
        run π_θold in N environments for T timesteps            (Rollout.collect)
        compute advantage estimates Â_1 … Â_T                  (gae, eq. 11)
        optimise the surrogate for K epochs, minibatches of M   (update_minibatch)
        θ_old ← θ

Every implementation detail is a named field of ``Config``, on by default where the "37 details" put it, and
each can be switched off to see what it does.
"""

from __future__ import annotations

import csv
import dataclasses
import difflib
import inspect
import io
import json
import math
import os
import sys
import time
import tokenize
import zipfile
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from minippo import advantages as adv
from minippo import losses
from minippo.agent import NETWORKS, ActorCritic, save_policy
from minippo.checkpoint import write_atomically
from minippo.envs import image_shape_of, make_env, spaces_of
from minippo.errors import ConfigError, MinippoError, NonFiniteError
from minippo.normalization import ObservationNormalizer, RewardScaler
from minippo.optimizer import Adam, clip_grad_norm, linear_schedule
from minippo.rollout import Rollout

OBJECTIVES = ("clip", "cpi", "klpen", "pg")
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


@dataclass
class Config:
    """Defaults are the paper's MuJoCo settings (Table 3) and the "37 details" (Huang et al. 2022)."""

    env_id: str = "Hopper-v5"  # any Gymnasium id with flat or image (H, W, C) Box observations, Discrete or Box actions
    total_steps: int = 1_000_000  # environment steps in all (the paper: 1M for MuJoCo)
    seed: int = 1  # seeds the initialisation, the action noise, the minibatch order and the environments
    objective: str = "clip"  # clip (eq. 7) | cpi (eq. 6, no clipping or penalty) | klpen (eq. 8) | pg (eq. 2)
    # Algorithm 1
    num_envs: int = 1  # N actors
    horizon: int = 2048  # T
    epochs: int = 10  # K
    minibatch_size: int = 64  # M
    gamma: float = 0.99  # γ
    gae_lambda: float = 0.95  # λ
    clip_epsilon: float = 0.2  # ε
    anneal_clip: bool = False  # ε falls linearly to 0 with the step size α (the paper's Atari setting, Table 5)
    # eq. 8: the KL penalty (objective = klpen)
    kl_beta: float = 1.0  # β, its initial value
    kl_target: float = 0.01  # d_targ
    adaptive_kl: bool = True  # False: β stays fixed (Table 1's "fixed KL" rows)
    # eq. 9: one objective for policy, value and entropy
    value_coef: float = 0.5  # c1
    entropy_coef: float = 0.0  # c2 (the paper uses none for MuJoCo)
    shared_network: bool = False  # one tanh trunk, a policy head and a value head
    hidden_sizes: tuple = (64, 64)  # two tanh layers of 64, for the policy and for the value network
    network: str = "mlp"  # mlp (tanh layers of hidden_sizes) | minatar_cnn (images: conv 16 3×3, dense 128, shared)
    dtype: str = "float32"  # the networks' floats: float32 or float64 (the gradient checks use float64)
    log_std_init: float = 0.0  # the Gaussian policy starts with σ = e^0 = 1 for every action
    # the implementation details, each a switch
    lr: float = 3e-4  # Adam step size α (the paper's Table 3)
    adam_eps: float = 1e-5  # Adam's ε in the denominator (PyTorch's default is 1e-8)
    anneal_lr: bool = True  # α falls linearly to 0 over the run
    use_gae: bool = True  # False: Â = discounted return − V (λ = 1)
    shuffle_minibatches: bool = True  # a new random order of the batch every epoch
    normalize_advantages: bool = True  # per minibatch
    clip_value_loss: bool = True  # V may move at most ±ε from the rollout's value (pessimistic max)
    grad_norm_clipping: bool = True  # scale the whole gradient down to norm max_grad_norm when larger
    max_grad_norm: float = 0.5  # the global norm limit
    orthogonal_init: bool = True  # orthogonal weights (gain √2, 0.01, 1), zero biases; else LeCun-uniform
    normalize_observations: bool = True  # running mean/std of observations, updated between batches
    obs_clip: float = 10.0  # normalised observations are clipped to ±obs_clip
    scale_rewards: bool = True  # divide rewards by the running std of the discounted return
    reward_clip: float = 10.0  # scaled rewards are clipped to ±reward_clip
    clip_actions: bool = True  # clip to the action bounds when stepping; the unclipped action is stored
    target_kl: float | None = None  # stop the epochs early once approx KL exceeds this (off in the paper)
    checkpoint_every: int = 10  # updates between checkpoints (for --resume and for NaN recovery)

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

        choices = ", ".join(OBJECTIVES)
        check(self.objective in OBJECTIVES, "objective", f"must be one of {choices}, not '{self.objective}'")
        check(0 < self.total_steps <= 10**10, "total_steps", f"must be between 1 and 10^10, not {self.total_steps}")
        for name in ("num_envs", "horizon", "epochs", "minibatch_size"):
            check(getattr(self, name) >= 1, name, f"must be a positive integer, not {getattr(self, name)}")
        check(self.minibatch_size <= self.batch_size, "minibatch_size",
              f"{self.minibatch_size} exceeds the batch N·T = {self.batch_size}")  # fmt: skip
        for name in ("gamma", "gae_lambda"):
            check(0 <= getattr(self, name) <= 1, name, f"must lie in [0, 1], not {getattr(self, name)}")
        check(self.dtype in ("float32", "float64"), "dtype", f"must be float32 or float64, not {self.dtype}")
        check(self.network in NETWORKS, "network", f"must be one of {', '.join(NETWORKS)}, not '{self.network}'")
        check(self.network == "mlp" or self.shared_network, "shared_network",
              f"must be true with network={self.network}, whose one trunk feeds both heads")  # fmt: skip
        for name in ("clip_epsilon", "lr"):
            check(getattr(self, name) > 0, name, f"must be positive, not {getattr(self, name)}")
        return self

    @classmethod
    def field_help(cls) -> dict[str, tuple[object, str]]:
        """{field: (default, the comment beside it in this class)}: the one description of every setting, which the
        command line's help is built from."""
        comments = {}
        tokens = tokenize.generate_tokens(io.StringIO(inspect.getsource(cls)).readline)
        name = None
        for token in tokens:
            if token.type == tokenize.NAME and token.start[1] == 4 and name is None:
                name = token.string
            elif token.type == tokenize.COMMENT and name is not None:
                comments[name] = token.string.lstrip("# ")
            if token.type in (tokenize.NEWLINE, tokenize.NL):
                name = None
        defaults = cls()
        return {f.name: (getattr(defaults, f.name), comments.get(f.name, "")) for f in dataclasses.fields(cls)}

    @classmethod
    def parse_value(cls, name: str, text: str):
        """A field's value from its text ('3e-4', 'false', '64,64', 'none'), typed like the field's default."""
        name = name.strip().replace("-", "_")
        defaults = {f.name: getattr(cls(), f.name) for f in dataclasses.fields(cls)}
        if name not in defaults:
            close = difflib.get_close_matches(name, list(defaults), n=3)
            hint = f"; did you mean {', '.join(close)}?" if close else ""
            raise ConfigError(name, f"unknown config field '{name}'{hint}")
        default, raw = defaults[name], text.strip()
        try:
            if raw.lower() == "none":
                return None
            if isinstance(default, bool):
                if raw.lower() not in ("true", "false", "1", "0", "yes", "no", "on", "off"):
                    raise ValueError
                return raw.lower() in ("true", "1", "yes", "on")
            if isinstance(default, int):
                return int(float(raw)) if float(raw).is_integer() else int(raw)
            if isinstance(default, float) or default is None:
                return float(raw)
            if isinstance(default, tuple):
                return tuple(int(x) for x in raw.split(",") if x)
            return raw
        except ValueError:
            raise ConfigError(name, f"{name}: cannot read '{raw}' as {type(default).__name__}") from None

    def with_overrides(self, texts) -> Config:
        """A copy with 'key=value' overrides (``minippo train --config``), each value typed like its field."""
        changes = {}
        for text in texts:
            if "=" not in text:
                raise ConfigError("", f"'{text}' is not key=value")
            key, raw = text.split("=", 1)
            key = key.strip().replace("-", "_")
            changes[key] = self.parse_value(key, raw)
        return dataclasses.replace(self, **changes)

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


def compute_advantages(batch, config: Config):
    """Â_t by truncated GAE (eq. 11), and the value targets V^targ_t = Â_t + V(s_t)."""
    if config.use_gae:
        advantages = adv.gae(
            batch.rewards,
            batch.values,
            batch.next_values,
            batch.terminated,
            batch.truncated,
            config.gamma,
            config.gae_lambda,
        )
        return advantages, advantages + batch.values
    returns = adv.discounted_returns(batch.rewards, batch.next_values, batch.terminated, batch.truncated, config.gamma)
    return returns - batch.values, returns


def loss_and_grad(agent: ActorCritic, mb: dict, config: Config, kl_beta: float = 1.0):
    """The loss we minimise on one minibatch, −(L^surrogate − c1 L^VF + c2 S) (eq. 9), with its gradient written
    into ``agent.grads``. Returns (loss, statistics)."""
    out, values, cache = agent.forward(mb["obs"])
    dist = agent.distribution(out)
    logp = dist.log_prob(mb["actions"])
    advantages = mb["advantages"]
    if config.normalize_advantages and len(advantages) > 1:
        centered = advantages - losses.mean(advantages)  # (Â − mean) / (std + 1e-8), std = √Ê[(Â − mean)²]
        advantages = centered / (math.sqrt(losses.mean(centered * centered)) + 1e-8)

    grad_kl = None
    if config.objective == "clip":
        objective, grad_logp = losses.clip_objective(logp, mb["logp"], advantages, config.clip_epsilon)
    elif config.objective == "cpi":
        objective, grad_logp = losses.cpi_objective(logp, mb["logp"], advantages)
    elif config.objective == "pg":
        objective, grad_logp = losses.pg_objective(logp, advantages)
    else:
        old = old_policy(agent, mb)
        objective, grad_logp, grad_kl = losses.kl_penalty_objective(logp, mb["logp"], advantages, dist.kl(old), kl_beta)
    value_clip = config.clip_epsilon if config.clip_value_loss else None
    value_loss, grad_values = losses.value_loss(values, mb["returns"], mb["values"], value_clip)
    entropy = 0.0
    loss = -objective + config.value_coef * value_loss

    # carry −∂L/∂(log π, KL, S) back through the distribution, then through the networks
    grads = dist.log_prob_backward(mb["actions"], -grad_logp)
    if grad_kl is not None:
        grads = [g + k for g, k in zip(grads, dist.kl_backward(old, -grad_kl))]
    if config.entropy_coef:
        entropy, grad_entropy = losses.entropy_bonus(dist.entropy())
        loss -= config.entropy_coef * entropy
        grads = [g + e for g, e in zip(grads, dist.entropy_backward(-config.entropy_coef * grad_entropy))]
    agent.backward(cache, grads[0], config.value_coef * grad_values, grads[1] if len(grads) > 1 else None)
    return loss, {
        "policy_objective": objective,
        "value_loss": value_loss,
        "entropy": entropy,
        "approx_kl": losses.approx_kl(logp, mb["logp"]),
    }


def old_policy(agent: ActorCritic, data: dict):
    """π_θold as the batch stored it: its logits, or its means with its own log σ (not the live one, which the
    update moves)."""
    return agent.distribution(data["policy_out"], data["policy_log_std"])


def update_minibatch(agent: ActorCritic, optimizer: Adam, mb: dict, config: Config, kl_beta: float = 1.0) -> dict:
    """One Adam step on one minibatch, after the global gradient-norm clip."""
    loss, stats = loss_and_grad(agent, mb, config, kl_beta)
    if config.grad_norm_clipping:
        norm = clip_grad_norm(agent.grads, config.max_grad_norm)
    else:
        norm = float(np.sqrt(agent.grads @ agent.grads))
    if not (math.isfinite(norm) and math.isfinite(loss)):
        raise NonFiniteError("non-finite loss or gradient")
    optimizer.step(agent.grads)
    return stats


def flatten(batch, advantages, returns, dtype) -> dict:
    """The (T, N) batch as T·N samples, its floats in the networks' dtype (mixing dtypes would upcast every step)."""
    T, N = batch.values.shape
    data = {
        "obs": batch.obs.reshape(T * N, -1),
        "actions": batch.actions.reshape(T * N, *batch.actions.shape[2:]),
        "logp": batch.logp.reshape(-1),
        "policy_out": batch.policy_out.reshape(T * N, -1),
        "policy_log_std": np.broadcast_to(batch.policy_log_std, (T * N, batch.policy_log_std.size)),  # per sample
        "values": batch.values.reshape(-1),
        "advantages": advantages.reshape(-1),
        "returns": returns.reshape(-1),
    }
    return {key: v.astype(dtype, copy=False) if v.dtype.kind == "f" else v for key, v in data.items()}


class Trainer:
    """Holds everything a run needs, so that it can be checkpointed and resumed."""

    def __init__(self, config: Config):
        self.config = config.validate()
        self.rng = np.random.default_rng(config.seed)
        self.envs = [make_env(config.env_id) for _ in range(config.num_envs)]
        obs_dim, kind, act_dim = spaces_of(self.envs[0])
        if config.network != "mlp" and image_shape_of(self.envs[0]) is None:
            raise ConfigError("network", f"network={config.network} needs image observations; {config.env_id} has none")
        self.agent = ActorCritic(
            obs_dim,
            kind,
            act_dim,
            config.hidden_sizes,
            config.shared_network,
            config.log_std_init,
            config.orthogonal_init,
            self.rng,
            config.dtype,
            config.network,
            image_shape_of(self.envs[0]),
        )
        self.optimizer = Adam(self.agent.params, lr=config.lr, eps=config.adam_eps)
        self.obs_normalizer = ObservationNormalizer((obs_dim,), config.obs_clip, config.normalize_observations)
        self.reward_scaler = RewardScaler(config.gamma, config.reward_clip, config.scale_rewards, config.num_envs)
        self.rollout = Rollout(
            self.envs,
            self.agent,
            self.obs_normalizer,
            self.reward_scaler,
            config.horizon,
            self.rng,
            config.seed,
            config.clip_actions,
        )
        self.kl_beta = config.kl_beta
        self.update = 0
        self.wall_s = 0.0

    @threadpool_limits.wrap(limits=1, user_api="blas")  # 64 × 64 matrices: a second BLAS thread would only wait
    def run_update(self) -> dict:
        """One iteration of Algorithm 1."""
        config, agent = self.config, self.agent
        started = time.perf_counter()
        self.update += 1
        lr = linear_schedule(config.lr, self.update, config.num_updates) if config.anneal_lr else config.lr
        self.optimizer.lr = lr
        if config.anneal_clip:  # ε·α with the same α as the step size (Table 5); the value clip follows it
            config = dataclasses.replace(
                config, clip_epsilon=linear_schedule(config.clip_epsilon, self.update, config.num_updates)
            )

        batch = self.rollout.collect()  # run π_θold for T timesteps
        advantages, returns = compute_advantages(batch, config)  # Â_1 … Â_T
        data = flatten(batch, advantages, returns, agent.dtype)
        n = len(data["logp"])

        stats = []  # optimise the surrogate for K epochs with minibatches of M
        for epoch in range(config.epochs):
            order = self.rng.permutation(n) if config.shuffle_minibatches else np.arange(n)
            shuffled = {key: value.take(order, axis=0) for key, value in data.items()}  # one gather an epoch
            epoch_kl = []
            for start in range(0, n, config.minibatch_size):
                minibatch = {key: value[start : start + config.minibatch_size] for key, value in shuffled.items()}
                try:
                    step = update_minibatch(agent, self.optimizer, minibatch, config, self.kl_beta)
                except NonFiniteError as error:
                    raise NonFiniteError(
                        f"{error} at update {self.update}, epoch {epoch + 1}, "
                        f"minibatch {start // config.minibatch_size + 1}"
                    ) from None
                stats.append(step)
                epoch_kl.append(step["approx_kl"])
            if config.target_kl is not None and np.mean(epoch_kl) > config.target_kl:
                break

        # how far θ moved from θ_old over the whole batch; eq. 8 adapts β from it
        dist = agent.distribution(agent.policy_output(data["obs"]))
        logp = dist.log_prob(data["actions"])
        kl = float(np.mean(dist.kl(old_policy(agent, data))))
        if config.objective == "klpen" and config.adaptive_kl:
            self.kl_beta = losses.adaptive_beta(self.kl_beta, kl, config.kl_target)
        self.wall_s += time.perf_counter() - started

        recent = self.rollout.completed_returns[-100:]
        recent_lengths = self.rollout.completed_lengths[-100:]
        return {
            "update": self.update,
            "step": self.rollout.steps,
            "episodes": len(self.rollout.completed_returns),
            "return_mean": float(np.mean(recent)) if recent else float("nan"),
            "length_mean": float(np.mean(recent_lengths)) if recent_lengths else float("nan"),
            "approx_kl": losses.approx_kl(logp, data["logp"]),
            "clip_fraction": losses.clip_fraction(logp, data["logp"], config.clip_epsilon),
            "entropy": float(np.mean(dist.entropy())),
            "policy_objective": float(np.mean([s["policy_objective"] for s in stats])),
            "value_loss": float(np.mean([s["value_loss"] for s in stats])),
            "explained_variance": losses.explained_variance(data["values"], data["returns"]),
            "kl_beta": self.kl_beta,
            "lr": lr,
            "steps_per_s": self.rollout.steps / self.wall_s,
            "wall_s": self.wall_s,
        }

    # checkpoints: everything the next update depends on, so that a resumed run is the uninterrupted run

    def state(self) -> dict:
        return {
            "params": self.agent.params.copy(),
            "update": np.array(self.update),
            "wall_s": np.array(self.wall_s),
            "kl_beta": np.array(self.kl_beta),
            "rng": np.array(json.dumps(self.rng.bit_generator.state)),
            "reward_discounted": self.reward_scaler.discounted,
            **self.rollout.state(),
            **{f"adam_{k}": v for k, v in self.optimizer.state_dict().items()},
            **self.obs_normalizer.stats.state("obs"),
            **self.reward_scaler.stats.state("ret"),
        }

    def load_state(self, state: dict) -> str | None:
        """Carry on from ``state``; returns a one-line notice when the run cannot go on exactly as it would have."""
        self.agent.params[...] = state["params"]
        self.update = int(state["update"])
        self.wall_s = float(state["wall_s"])
        self.kl_beta = float(state["kl_beta"])
        self.rng.bit_generator.state = json.loads(str(state["rng"]))
        self.reward_scaler.discounted = np.array(state["reward_discounted"], dtype=np.float64)
        self.optimizer.load_state_dict({k[5:]: v for k, v in state.items() if k.startswith("adam_")})
        self.obs_normalizer.stats.load(state, "obs")
        self.obs_normalizer.refresh()
        self.reward_scaler.stats.load(state, "ret")
        if self.rollout.load_state(state, self.config.seed + 10_000 * self.update):
            return None
        return (
            f"the checkpoint holds no state of the {self.config.env_id} environments (minippo cannot save them, or "
            "an older minippo wrote it): they start fresh episodes, so the run goes on differently from one never "
            "interrupted"
        )

    def save_checkpoint(self, out: Path) -> None:
        """Write checkpoint.npz, then policy.npz, each whole or not at all."""
        state = self.state()
        write_atomically(out / "checkpoint.npz", lambda handle: np.savez(handle, **state))
        save_policy(
            out / "policy.npz", self.agent, self.obs_normalizer, {"env_id": self.config.env_id, "update": self.update}
        )


def train(
    config: Config,
    out: str | os.PathLike | None = None,
    resume: bool = False,
    on_update=None,
    stop=None,
    on_checkpoint=None,
) -> list[dict]:
    """Train PPO with ``config``; with ``out``, write config.json, progress.csv, checkpoint.npz and policy.npz there.

    ``resume``: carry on from the checkpoint in ``out``, exactly as the run would have gone on. ``on_update(row)`` is
    called after every update (the command line draws its progress bar with it), ``on_checkpoint(out)`` after every
    checkpoint. ``stop``: an object whose ``is_set()`` turns true to end the run early (Ctrl-C); the update under way
    is finished and checkpointed first. Returns the progress rows. On NaN/inf, raises NonFiniteError; when a file
    cannot be written (a full disk), raises MinippoError; either way the last checkpoint in ``out`` is left as it was.
    """
    trainer = Trainer(config)
    try:
        rows = [] if out is None else start_folder(Path(out), trainer, resume)
        while trainer.update < config.num_updates:
            row = trainer.run_update()
            rows.append(row)
            stopping = stop is not None and stop.is_set()  # this update is the last, and it is checkpointed
            if out is not None:
                last = trainer.update == config.num_updates
                checkpoint = stopping or last or trainer.update % config.checkpoint_every == 0
                write_update(Path(out), trainer, row, checkpoint)
                if checkpoint and on_checkpoint is not None:
                    on_checkpoint(out)
            if on_update is not None:
                on_update(row)
            if stopping:
                break
    finally:
        for env in trainer.envs:
            env.close()
    return rows


def start_folder(out: Path, trainer: Trainer, resume: bool) -> list[dict]:
    """Write config.json and progress.csv's header; with ``resume``, first load the checkpoint, and keep the rows of
    its updates. Returns those rows."""
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    with run_files(out, trainer):
        if resume and (out / "checkpoint.npz").exists():
            with np.load(out / "checkpoint.npz", allow_pickle=False) as data:
                notice = trainer.load_state({key: data[key] for key in data.files})
            if notice:
                print(f"minippo: {notice}", file=sys.stderr)
            rows = progress_until(out / "progress.csv", trainer.update)
        text = json.dumps(trainer.config.to_dict(), indent=2) + "\n"
        write_atomically(out / "config.json", lambda handle: handle.write(text.encode()))
        table = io.StringIO(newline="")
        writer = csv.DictWriter(table, fieldnames=PROGRESS_FIELDS)
        writer.writeheader()
        writer.writerows(csv_row(row) for row in rows)
        write_atomically(out / "progress.csv", lambda handle: handle.write(table.getvalue().encode()))
    return rows


def write_update(out: Path, trainer: Trainer, row: dict, checkpoint: bool) -> None:
    """Append the update's row to progress.csv, then write the checkpoint when it is time for one."""
    with run_files(out, trainer):
        with open(out / "progress.csv", "a", newline="") as handle:
            csv.DictWriter(handle, fieldnames=PROGRESS_FIELDS).writerow(csv_row(row))
        if checkpoint:
            trainer.save_checkpoint(out)


@contextmanager
def run_files(out: Path, trainer: Trainer):
    """A run folder's file that cannot be written (a full disk, no permission) stops the run with one line."""
    try:
        yield
    except OSError as error:
        kept = checkpoint_update(out)
        kept = "no checkpoint yet" if kept is None else f"the checkpoint of update {kept} is kept"
        reason = error.strerror or str(error)
        raise MinippoError(f"cannot write the run's files in {out} ({reason}) at update {trainer.update}; {kept}")


def checkpoint_update(out) -> int | None:
    """The update of the checkpoint in the run folder ``out``, or None when it has none (or none that can be read)."""
    try:
        with np.load(Path(out) / "checkpoint.npz", allow_pickle=False) as data:
            return int(data["update"])
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        return None


def csv_row(row: dict) -> dict:
    """A progress row as progress.csv holds it: floats by repr, which reads back to the same float."""
    return {key: (repr(value) if isinstance(value, float) else value) for key, value in row.items()}


def progress_until(path: Path, update: int) -> list[dict]:
    """progress.csv's rows of updates 1 … ``update`` (the checkpoint's), read back to the numbers they were written
    from: the rows a killed run wrote after its last checkpoint, and a row cut short by the kill, are dropped."""
    try:
        with open(path, newline="") as handle:
            rows = list(csv.DictReader(handle))[:update]
        rows = [{key: (int if key in COUNTS else float)(row[key]) for key in PROGRESS_FIELDS} for row in rows]
    except FileNotFoundError:
        rows = []
    except (KeyError, TypeError, ValueError):
        rows = None
    if rows is None or [row["update"] for row in rows] != list(range(1, update + 1)):
        raise MinippoError(f"{path} does not hold the rows of updates 1 to {update}, the checkpoint's; cannot resume")
    return rows
