"""The atlas's tasks and faults, the names its runs (benchmarks/atlas.py) and its analysis
(benchmarks/atlas_signatures.py) share: the tasks a run trains on, every mode with what it injects, and the record of
the runs, ``results/atlas_runs.csv``, which the first writes and the second reads.

A fault is a change of Config fields (``dataclasses.replace``), or a function of minippo replaced for the length of a
``with fault.injected_into():`` block and put back after it; the library itself has no switch for any of them.
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

import minippo.losses
import minippo.ppo
from benchmarks import common
from minippo.distributions import DiagGaussian
from minippo.presets import ATARI, CARTPOLE_PPO
from minippo.rollout import Rollout

RUNS_CSV = common.RESULTS / "atlas_runs.csv"  # every update of every run: mode, task, seed, then progress.csv's columns

# the tasks: the book's CartPole PPO setting, the paper's Hopper setting (Config's defaults), and the paper's Atari
# setting on a MinAtar game (healthy runs only); each with the number of updates of a run
TASKS = {
    "CartPole-v1": (dict(CARTPOLE_PPO), 150),
    "Hopper-v5": (dict(env_id="Hopper-v5"), 60),
    "MinAtar/Breakout-v1": (dict(ATARI, env_id="MinAtar/Breakout-v1"), 200),
}
FAULT_TASKS = ("CartPole-v1", "Hopper-v5")


def task_config(task: str, seed: int):
    settings, updates = TASKS[task]
    config = minippo.ppo.Config(**settings, seed=seed)
    return dataclasses.replace(config, total_steps=updates * config.batch_size)


# ---- injecting: functions of minippo replaced where they are looked up, and put back


@contextmanager
def replaced(*replacements):
    """For each (owner, name, make): ``owner.name`` becomes ``make(original)`` inside the block, in ``owner`` (a module
    or a class) and in every loaded minippo module that imported the same object by name; all are restored on exit."""
    saved = []
    try:
        for owner, name, make in replacements:
            original = getattr(owner, name)
            new = make(original)
            holders = [owner]
            if not isinstance(owner, type):
                holders += [
                    module
                    for key, module in list(sys.modules.items())
                    if key.split(".")[0] == "minippo"
                    and module is not owner
                    and getattr(module, name, None) is original
                ]
            for holder in holders:
                saved.append((holder, name, original))
                setattr(holder, name, new)
        yield
    finally:
        for holder, name, original in reversed(saved):
            setattr(holder, name, original)


def value_gradient_flipped(original):
    def value_loss(*args, **kwargs):
        loss, grad = original(*args, **kwargs)
        return loss, -grad  # the critic climbs its own error; the logged value loss is still the true one

    return value_loss


class _StaleCritic:
    """The live agent in every respect but V, which is a frozen copy's."""

    def __init__(self, live, frozen):
        self._live, self._frozen = live, frozen

    def __getattr__(self, name):
        return getattr(self._live, name)

    def value(self, obs):
        return self._frozen.value(obs)


def critic_frozen_at_start(original):
    frozen = {}  # the critic as it was at the first rollout, one per agent

    def collect(self):
        live = self.agent
        critic = frozen.setdefault(id(live), live.copy())
        self.agent = _StaleCritic(live, critic)
        try:
            return original(self)
        finally:
            self.agent = live

    return collect


def episode_ends_changed(terminal_as_truncation: bool):
    def make(original):
        def compute_advantages(batch, config):
            ends = batch.terminated | batch.truncated
            if terminal_as_truncation:  # bootstraps a fall from V of the next episode's first observation
                batch = dataclasses.replace(batch, terminated=np.zeros_like(ends), truncated=ends)
            else:  # a time limit counted as a terminal state: V = 0 after it
                batch = dataclasses.replace(batch, terminated=ends, truncated=np.zeros_like(ends))
            return original(batch, config)

        return compute_advantages

    return make


def against_current_policy(original):
    def with_current(logp, logp_old, *rest):
        return original(logp, logp, *rest)  # r_t = π_θ / π_θ = 1, though its gradient is still ∇ log π_θ

    return with_current


def old_policy_is_current(original):
    def old_policy(agent, data):
        return agent.distribution(agent.policy_output(data["obs"]))

    return old_policy


def log_prob_over_samples(original):
    def log_prob(self, actions):
        per_sample = original(self, actions)
        return np.full_like(per_sample, per_sample.mean())  # Σ over the samples (÷ n): every sample gets the same

    return log_prob


def log_prob_backward_over_samples(original):
    def log_prob_backward(self, actions, grad_logp):
        # log π'_i = (1/n) Σ_j log π_j for every i, so ∂L/∂ log π_j = Σ_i ∂L/∂ log π'_i / n
        return original(self, actions, np.full_like(grad_logp, grad_logp.sum() / len(grad_logp)))

    return log_prob_backward


# ---- the modes


@dataclass(frozen=True)
class Fault:
    name: str
    injected: str  # what the lab changes
    cause: str  # the bug or the bad setting, in words
    fix: str
    changes: Callable = lambda config: {}  # Config fields to change, from the task's Config
    patches: tuple = ()  # (owner, name, make) for ``replaced``
    not_applicable: dict = field(default_factory=dict)  # task: why the mode does not apply there

    def configure(self, config):
        return dataclasses.replace(config, **self.changes(config)).validate()

    def injected_into(self):
        return replaced(*self.patches)


def _losses(*names):
    return tuple((minippo.losses, name, against_current_policy) for name in names)


NOT_SET_ON_CARTPOLE = "the book's CartPole setting already has it off: the healthy CartPole run is this run"
FAULTS = {
    fault.name: fault
    for fault in [
        Fault("healthy", "nothing", "", ""),
        Fault("lr_10x", "Adam's step size α × 10", "a step size ten times too large", "α back to the task's value",
              lambda c: {"lr": 10 * c.lr}),
        Fault("lr_100x_epochs_40", "α × 100 and K = 40 epochs (CartPole only)",
              "a step size a hundred times too large, with far too many epochs on one batch",
              "α and K back to the task's values", lambda c: {"lr": 100 * c.lr, "epochs": 40},
              not_applicable={"Hopper-v5": "the doctor's test case is made on CartPole only"}),
        Fault("epochs_50", "K = 50 epochs", "far too many passes over one batch: the policy walks far from θ_old",
              "K back to 3–10", lambda c: {"epochs": 50}),
        Fault("minibatch_whole", "M = N·T (one minibatch: the whole batch)",
              "one Adam step per epoch: K steps per batch, too few to learn", "M back to 64–256",
              lambda c: {"minibatch_size": c.batch_size}),
        Fault("minibatch_4", "M = 4", "minibatches so small that every step is noise, and many more steps per batch",
              "M back to 64–256", lambda c: {"minibatch_size": 4}),
        Fault("no_advantage_normalization", "normalize_advantages = False",
              "advantages on the scale of the returns: the step size of the policy moves with the reward scale",
              "normalise Â per minibatch", lambda c: {"normalize_advantages": False}),
        Fault("value_loss_sign", "losses.value_loss returns −∂L^VF/∂V (its logged value unchanged)",
              "the value loss added with the wrong sign: the critic ascends its squared error",
              "total loss −L^CLIP + c1 L^VF − c2 S (eq. 9)",
              patches=((minippo.losses, "value_loss", value_gradient_flipped),)),
        Fault("stale_value_targets", "Rollout.collect takes V(s_t), V(s_{t+1}) from a copy of the critic frozen at the "
              "first update (the batch's stored values, the advantages and the targets)",
              "value estimates computed once and never refreshed: Â and V^targ are built on the initial critic",
              "compute V with the current critic for every new batch",
              patches=((Rollout, "collect", critic_frozen_at_start),)),
        Fault("entropy_wrong_sign", "c2 = −0.01 (CartPole's bonus negated; Hopper has none, so −0.01 as on CartPole)",
              "the entropy bonus subtracted from the objective: the policy is pushed to be certain",
              "loss −= c2 S with c2 ≥ 0", lambda c: {"entropy_coef": -(c.entropy_coef or 0.01)}),
        Fault("entropy_too_large", "c2 = 0.5", "an entropy bonus that outweighs the advantage term",
              "c2 = 0 to 0.01", lambda c: {"entropy_coef": 0.5}),
        Fault("bootstrap_at_termination", "compute_advantages sees every termination as a truncation",
              "terminated ignored: a fall is bootstrapped with γV of the next state the batch holds (the next "
              "episode's first), so falling costs nothing", "V(s_{t+1}) = 0 after a termination",
              patches=((minippo.ppo, "compute_advantages", episode_ends_changed(terminal_as_truncation=True)),)),
        Fault("no_bootstrap_at_truncation", "compute_advantages sees every time-limit truncation as a termination",
              "a time limit treated as a terminal state: V = 0 where the episode would have gone on",
              "bootstrap with V(final observation) when truncated",
              patches=((minippo.ppo, "compute_advantages", episode_ends_changed(terminal_as_truncation=False)),)),
        Fault("no_observation_normalization", "normalize_observations = False",
              "raw observations of very different scales fed to a tanh network", "running mean/std normalisation",
              lambda c: {"normalize_observations": False}, not_applicable={"CartPole-v1": NOT_SET_ON_CARTPOLE}),
        Fault("no_reward_scaling", "scale_rewards = False",
              "returns in the hundreds or thousands for a critic that starts near 0", "divide r by the std of G",
              lambda c: {"scale_rewards": False}, not_applicable={"CartPole-v1": NOT_SET_ON_CARTPOLE}),
        Fault("ratio_vs_current_policy", "losses.clip_objective, approx_kl, clip_fraction and ppo.old_policy read "
              "the current policy where they should read θ_old",
              "log π_θold recomputed from the current θ: r_t = 1, the clip never engages, K epochs of plain policy "
              "gradient; the logged KL and clip fraction are 0", "store log π_θold(a_t|s_t) at the rollout and use it",
              patches=(*_losses("clip_objective", "approx_kl", "clip_fraction"),
                       (minippo.ppo, "old_policy", old_policy_is_current))),
        Fault("log_prob_wrong_axis", "DiagGaussian.log_prob (and its backward) reduce over the samples, axis 0, not "
              "over the action components: every sample gets the batch's mean log-probability",
              "the Gaussian log-density summed over the wrong axis", "sum over the last axis (the action components)",
              patches=((DiagGaussian, "log_prob", log_prob_over_samples),
                       (DiagGaussian, "log_prob_backward", log_prob_backward_over_samples)),
              not_applicable={"CartPole-v1": "CartPole's policy is categorical: there is no Gaussian"}),
        Fault("gamma_1", "γ = 1", "no discount on a long task: returns and their variance grow with the episode",
              "γ = 0.99", lambda c: {"gamma": 1.0}),
    ]
}  # fmt: skip
