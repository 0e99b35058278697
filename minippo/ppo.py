"""Proximal Policy Optimization, Algorithm 1 of Schulman et al. (2017): ``Trainer.run_update`` is one iteration.

    for iteration = 1, 2, ...
        run π_θold in N environments for T timesteps            (Rollout.collect)
        compute advantage estimates Â_1 … Â_T                  (compute_advantages: GAE, eq. 11)
        optimise the surrogate for K epochs, minibatches of M   (update_minibatch, eq. 9)
        θ_old ← θ

``train`` repeats it and keeps the run folder (minippo/run_folder.py). Every implementation detail is a named field of
``Config`` (minippo/config.py), on by default where the "37 details" put it, and each can be switched off to see what
it does.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import time
from typing import Protocol

import numpy as np
from threadpoolctl import threadpool_limits

from minippo import advantages as adv
from minippo import losses
from minippo.agent import ActorCritic, AgentSpec
from minippo.config import OBJECTIVES, Config
from minippo.envs import image_shape_of, make_env, spaces_of
from minippo.errors import ConfigError, NonFiniteError
from minippo.minibatches import epochs_of
from minippo.normalization import ObservationNormalizer, RewardScaler
from minippo.optimizer import Adam, clip_grad_norm, linear_schedule
from minippo.rollout import Rollout

__all__ = ["OBJECTIVES", "Config", "Trainer", "compute_advantages", "flatten", "loss_and_grad", "old_policy", "train"]
__all__ += ["UpdateSettings", "spec_from", "update_minibatch"]


class UpdateSettings(Protocol):
    """What the minibatch update reads of its settings: ``Config`` has these fields, and so has the language models'
    ``RLHFConfig`` (minippo/lm/rlhf.py), which hands its tokens to the same update."""

    objective: str  # clip, cpi, klpen or pg
    clip_epsilon: float  # ε of eq. 7 (and of the value clip)
    value_coef: float  # c1 of eq. 9
    entropy_coef: float  # c2 of eq. 9
    normalize_advantages: bool
    clip_value_loss: bool
    grad_norm_clipping: bool
    max_grad_norm: float


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


def loss_and_grad(agent: ActorCritic, mb: dict, config: UpdateSettings, kl_beta: float = 1.0):
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


def update_minibatch(
    agent: ActorCritic, optimizer: Adam, mb: dict, config: UpdateSettings, kl_beta: float = 1.0
) -> dict:
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


def spec_from(config: Config, env) -> AgentSpec:
    """The agent ``config`` asks for, on ``env``'s observations and actions."""
    obs_dim, kind, act_dim = spaces_of(env)
    image_shape = image_shape_of(env)
    if config.network != "mlp" and image_shape is None:
        raise ConfigError("network", f"network={config.network} needs image observations; {config.env_id} has none")
    return AgentSpec(
        obs_dim, kind, act_dim, hidden_sizes=config.hidden_sizes, shared=config.shared_network, network=config.network,
        image_shape=image_shape, dtype=config.dtype, log_std_init=config.log_std_init,
        orthogonal_init=config.orthogonal_init,
    )  # fmt: skip


class Trainer:
    """Everything a run needs between two updates: the environments, the agent, Adam, the normalisers, the rng."""

    def __init__(self, config: Config):
        self.config = config.validate()
        self.rng = np.random.default_rng(config.seed)
        self.envs = [make_env(config.env_id) for _ in range(config.num_envs)]
        spec = spec_from(config, self.envs[0])
        self.agent = ActorCritic(spec, self.rng)
        self.optimizer = Adam(self.agent.params, lr=config.lr, eps=config.adam_eps)
        self.obs_normalizer = ObservationNormalizer((spec.obs_dim,), config.obs_clip, config.normalize_observations)
        self.reward_scaler = RewardScaler(config.gamma, config.reward_clip, config.scale_rewards, config.num_envs)
        self.rollout = Rollout(
            self.envs,
            self.agent,
            self.obs_normalizer,
            self.reward_scaler,
            horizon=config.horizon,
            rng=self.rng,
            seed=config.seed,
            clip_actions=config.clip_actions,
        )
        self.kl_beta = config.kl_beta
        self.update = 0
        self.wall_s = 0.0

    @threadpool_limits.wrap(limits=1, user_api="blas")  # 64 × 64 matrices: a second BLAS thread would only wait
    def run_update(self) -> dict:
        """One iteration of Algorithm 1; returns its statistics, a row of progress.csv."""
        started = time.perf_counter()
        self.update += 1
        config = self.annealed()  # this iteration's step size α (and ε, with anneal_clip)
        agent = self.agent

        batch = self.rollout.collect()  # run π_θold for T timesteps
        advantages, returns = compute_advantages(batch, config)  # Â_1 … Â_T
        data = flatten(batch, advantages, returns, agent.dtype)

        steps = []  # optimise the surrogate for K epochs with minibatches of M
        order = self.rng if config.shuffle_minibatches else None  # a new random order every epoch, or none
        try:
            for epoch in epochs_of(data, config.epochs, config.minibatch_size, order):
                epoch_steps = [update_minibatch(agent, self.optimizer, mb, config, self.kl_beta) for mb in epoch]
                steps += epoch_steps
                if config.target_kl is not None and np.mean([s["approx_kl"] for s in epoch_steps]) > config.target_kl:
                    break  # the policy moved past target_kl in this epoch: stop early
        except NonFiniteError as error:
            raise NonFiniteError(f"{error} at update {self.update}") from None

        # how far θ moved from θ_old over the whole batch; eq. 8 adapts β from it
        dist = agent.distribution(agent.policy_output(data["obs"]))
        kl = float(np.mean(dist.kl(old_policy(agent, data))))
        if config.objective == "klpen" and config.adaptive_kl:
            self.kl_beta = losses.adaptive_beta(self.kl_beta, kl, config.kl_target)
        self.wall_s += time.perf_counter() - started
        return self.statistics(config, data, dist, steps)

    def annealed(self) -> Config:
        """The Config of this iteration, with Adam's step size set: α falls linearly to 0 over the run with
        anneal_lr, and ε with it (ε·α, Table 5) with anneal_clip; the value clip follows ε."""
        config, now = self.config, (self.update, self.config.num_updates)
        self.optimizer.lr = linear_schedule(config.lr, *now) if config.anneal_lr else config.lr
        if config.anneal_clip:
            config = dataclasses.replace(config, clip_epsilon=linear_schedule(config.clip_epsilon, *now))
        return config

    # checkpoints: one dict of everything the next update depends on (nanoGPT's checkpoint, PyTorch's state_dict)

    def state_dict(self) -> dict:
        """The run between two updates, each part's own ``state_dict`` under its name, so that a Trainer given it by
        ``load_state_dict`` goes on as this one would have, bitwise."""
        return {
            "update": self.update,
            "wall_s": self.wall_s,
            "kl_beta": self.kl_beta,
            "rng": json.dumps(self.rng.bit_generator.state),  # PCG64's 128-bit integers, as text
            "params": self.agent.params.copy(),
            "optimizer": self.optimizer.state_dict(),
            "obs_normalizer": self.obs_normalizer.state_dict(),
            "reward_scaler": self.reward_scaler.state_dict(),
            "rollout": self.rollout.state_dict(),
        }

    def load_state_dict(self, state: dict) -> str | None:
        """Carry on from ``state`` (a ``state_dict``); returns a one-line notice when the run cannot go on exactly as
        it would have (its environments could not be saved)."""
        self.update = int(state["update"])
        self.wall_s = float(state["wall_s"])
        self.kl_beta = float(state["kl_beta"])
        self.rng.bit_generator.state = json.loads(str(state["rng"]))
        self.agent.params[...] = state["params"]
        self.optimizer.load_state_dict(state["optimizer"])
        self.obs_normalizer.load_state_dict(state["obs_normalizer"])
        self.reward_scaler.load_state_dict(state["reward_scaler"])
        if self.rollout.load_state_dict(state["rollout"], self.config.seed + 10_000 * self.update):
            return None
        return (
            f"the checkpoint holds no state of the {self.config.env_id} environments (minippo cannot save them, or "
            "an older minippo wrote it): they start fresh episodes, so the run goes on differently from one never "
            "interrupted"
        )

    def statistics(self, config: Config, data: dict, dist, steps: list[dict]) -> dict:
        """The update's row of progress.csv: the last 100 episodes, and the debug variables of the batch."""
        logp = dist.log_prob(data["actions"])
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
            "policy_objective": float(np.mean([s["policy_objective"] for s in steps])),
            "value_loss": float(np.mean([s["value_loss"] for s in steps])),
            "explained_variance": losses.explained_variance(data["values"], data["returns"]),
            "kl_beta": self.kl_beta,
            "lr": self.optimizer.lr,
            "steps_per_s": self.rollout.steps / self.wall_s,
            "wall_s": self.wall_s,
        }


def train(
    config: Config | Trainer,
    out: str | os.PathLike | None = None,
    resume: bool = False,
    on_update=None,
    stop=None,
    on_checkpoint=None,
) -> list[dict]:
    """Train PPO with ``config``; with ``out``, write config.json, progress.csv, checkpoint.npz and policy.npz there.

    ``config`` may be a ``Trainer`` already made from one (the command line makes it first, so that bad settings stop
    before the run folder is touched). ``resume``: carry on from the checkpoint in ``out``, exactly as the run would
    have gone on; without it, an earlier run's files in ``out`` are replaced. ``on_update(row)`` is called after every
    update (the command line draws its progress bar with it), ``on_checkpoint(out)`` after every checkpoint. ``stop``:
    an object whose ``is_set()`` turns true to end the run early (Ctrl-C); the update under way is finished and
    checkpointed first. Returns the progress rows. On NaN/inf, raises NonFiniteError; when a file cannot be written (a
    full disk), raises MinippoError; either way the last checkpoint in ``out`` is left as it was.
    """
    from minippo.run_folder import RunFolder

    trainer = config if isinstance(config, Trainer) else Trainer(config)
    config, folder = trainer.config, None if out is None else RunFolder(out)
    try:
        rows = [] if folder is None else folder.start(trainer, resume)
        while trainer.update < config.num_updates:
            row = trainer.run_update()
            rows.append(row)
            stopping = stop is not None and stop.is_set()  # this update is the last, and it is checkpointed
            if folder is not None:
                last = trainer.update == config.num_updates
                checkpoint = stopping or last or trainer.update % config.checkpoint_every == 0
                folder.write_update(trainer, row, checkpoint)
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
