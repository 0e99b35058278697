"""GRPO (Shao et al. 2024): PPO without a value network. Each prompt is answered G times, and a response's advantage
is its score measured against the others in its group,

    Â_i = (R_i − mean(R_1 … R_G)) / (std(R_1 … R_G) + ε_std),

the same for every token of response i. The KL to the reference is not in the reward but in the loss, per token, with
Schulman's (2020) "k3" estimator of KL[π_θ ‖ π_ref], unbiased on tokens sampled from π_θ and never negative:

    k3_t = π_ref/π_θ − log(π_ref/π_θ) − 1,      ∂k3_t/∂ log π_θ = 1 − π_ref/π_θ.

The objective is L^CLIP's clipped ratio with these advantages, minus β k3, averaged over each response's tokens and
then over the responses (Shao et al.'s eq. 3). Everything else is minippo's: the language model, the categorical,
Adam, and the collection of responses of minippo.lm.rlhf.

k3's value is unbiased, but its gradient in the loss is not the gradient of that KL: under a ~ π_θ,
E[(1 − π_ref/π_θ) ∇log π_θ] = −Σ_a π_ref(a) ∇log π_θ(a) = ∇KL[π_ref ‖ π_θ], the forward KL, token by token (Tang &
Munos 2025). So GRPO as published does not aim at the optimum π* ∝ π_ref exp(R/β) of chapter 13's objective. Three
switches turn its departures from that objective off one by one, each a variant used in practice: ``normalize_std``
(the division by the group's std), ``kl_in`` (the KL in the loss, or in the reward as PPO has it) and
``average_over_tokens`` (the 1/|y| weight of each response's tokens). With all three off the update is the group-
baseline policy gradient of chapter 13's objective. A fourth, ``kl_estimator="k2"``, keeps the KL in the loss, per
token, but with k2 = ½ log²(π_θ/π_ref), whose gradient in the loss, log(π_θ/π_ref) per unit of log π_θ, is on average
the reverse KL's at each token: it separates the estimator from the place of the KL (in the loss each token sees its own
log-ratio only, where the reward charges it for the tokens after it as well, the partial gradient of Tang & Munos).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from minippo import losses
from minippo.agent import ActorCritic
from minippo.distributions import Categorical
from minippo.lm.language import PROMPT_LEN, make_prompts
from minippo.lm.reward_model import RewardModel
from minippo.lm.rlhf import collect, sequence_stats
from minippo.minibatches import epochs_of
from minippo.optimizer import Adam, clip_grad_norm

KL_ESTIMATORS = ("k3", "k2")  # the KL estimators GRPOConfig.kl_estimator can put in the loss


@dataclass
class GRPOConfig:
    seed: int = 0
    updates: int = 80  # iterations
    prompts: int = 8  # prompts per iteration
    group: int = 8  # G, responses per prompt (prompts × group responses per iteration)
    beta: float = 0.04  # β of the k3 KL in the loss (Shao et al.'s value)
    clip_epsilon: float = 0.2  # ε
    epochs: int = 4  # K
    minibatch_responses: int = 16  # responses per minibatch
    lr: float = 1e-3  # Adam's step size
    max_grad_norm: float = 0.5
    prompt_len: int = PROMPT_LEN
    response_len: int | None = None  # the longest response (None: up to MAX_LEN tokens in all)
    # divide each group's centred scores by the group's std (Shao et al.); False: centre them only (Liu et al. 2025)
    normalize_std: bool = True
    # where the KL to π_ref goes: "loss", β k3 per token in the objective (Shao et al.), or "reward", β Σ_t log
    # π_θold/π_ref subtracted from each response's score before the group advantages, as PPO does (chapter 13)
    kl_in: str = "loss"
    # weight each response's tokens 1/|y| (Shao et al.'s eq. 3); False: weight 1, the gradient of log π(y) = Σ_t log
    # π(a_t|s_t) of the whole response (Liu et al. 2025); either way the responses are then averaged
    average_over_tokens: bool = True
    # the estimator of the KL in the loss (kl_in="loss"): "k3" (Shao et al.), whose gradient there follows KL[π_ref ‖
    # π_θ], or "k2", ½ log²(π_θ/π_ref), whose gradient there follows KL[π_θ ‖ π_ref] token by token
    kl_estimator: str = "k3"

    def __post_init__(self):
        if self.kl_in not in ("loss", "reward"):
            raise ValueError(f"kl_in must be 'loss' or 'reward', not {self.kl_in!r}")
        if self.kl_estimator not in KL_ESTIMATORS:
            raise ValueError(f"kl_estimator must be 'k3' or 'k2', not {self.kl_estimator!r}")


def group_advantages(scores: np.ndarray, eps: float = 1e-8, normalize_std: bool = True) -> np.ndarray:
    """Â = (R − mean of its group) / (std of its group + eps), for scores (m, G), one row per prompt; the std is
    the population one (ddof = 0). A group whose responses all score the same gets advantages of 0. With
    ``normalize_std`` False, Â = R − mean of its group."""
    centred = scores - scores.mean(axis=1, keepdims=True)
    if not normalize_std:
        return centred
    return centred / (scores.std(axis=1, keepdims=True) + eps)


def k3(logp: np.ndarray, logp_ref: np.ndarray) -> np.ndarray:
    """k3 = π_ref/π − log(π_ref/π) − 1 per token: an estimate of KL[π ‖ π_ref] from a token sampled from π (its
    value; its gradient as a loss, 1 − π_ref/π per unit of log π, follows KL[π_ref ‖ π] instead)."""
    log_ratio = logp_ref - logp
    return np.exp(log_ratio) - log_ratio - 1.0


def k2(logp: np.ndarray, logp_ref: np.ndarray) -> np.ndarray:
    """k2 = ½ log²(π/π_ref) per token, never negative; its gradient as a loss, log(π/π_ref) per unit of log π, has
    the expectation under π of the gradient of KL[π ‖ π_ref] (its value is a biased estimate of that KL)."""
    return 0.5 * (logp - logp_ref) ** 2


def kl_estimate_and_grad(logp, logp_ref, estimator: str = "k3"):
    """The per-token KL estimate of ``estimator`` ("k3" or "k2") and its derivative with respect to log π_θ:
    k3: 1 − π_ref/π_θ;  k2: log(π_θ/π_ref)."""
    if estimator == "k3":
        return k3(logp, logp_ref), 1.0 - np.exp(logp_ref - logp)
    if estimator == "k2":
        return k2(logp, logp_ref), logp - logp_ref
    raise ValueError(f"estimator must be 'k3' or 'k2', not {estimator!r}")


def grpo_objective(logp, logp_old, logp_ref, advantages, weights, epsilon: float, beta: float, estimator="k3"):
    """J = Σ_t w_t [min(r_t Â_t, clip(r_t, 1−ε, 1+ε) Â_t) − β k_t], with r_t = π_θ/π_θold, k_t the KL estimate
    (k3 by default, or k2) and w_t the weight of token t (1 / (responses × the length of its response), so that each
    response counts once).

    Returns (J, ∂J/∂ log π_θ): w_t (r_t Â_t where the unclipped term is the smaller, else 0, − β ∂k_t/∂ log π_θ),
    with ∂k3/∂ log π_θ = 1 − π_ref/π_θ and ∂k2/∂ log π_θ = log(π_θ/π_ref).
    """
    ratio = np.exp(logp - logp_old)
    unclipped = ratio * advantages
    clipped = np.clip(ratio, 1.0 - epsilon, 1.0 + epsilon) * advantages
    kl, kl_grad = kl_estimate_and_grad(logp, logp_ref, estimator)
    value = float(np.sum(weights * (np.minimum(unclipped, clipped) - beta * kl)))
    grad = weights * (np.where(unclipped <= clipped, unclipped, 0.0) - beta * kl_grad)
    return value, grad


def grpo_step(policy, optimizer: Adam, minibatch: dict, config: GRPOConfig) -> float:
    """One Adam step that raises the GRPO objective on one minibatch of tokens (after the gradient-norm clip)."""
    logits, cache = policy.forward(minibatch["obs"])
    dist = Categorical(logits)
    logp = dist.log_prob(minibatch["actions"])
    value, grad_logp = grpo_objective(
        logp,
        minibatch["logp"],
        minibatch["logp_ref"],
        minibatch["advantages"],
        minibatch["weights"],
        config.clip_epsilon,
        config.beta if config.kl_in == "loss" else 0.0,
        config.kl_estimator,
    )
    (grad_logits,) = dist.log_prob_backward(minibatch["actions"], -grad_logp)  # minimise −J
    policy.backward(cache, grad_logits)
    clip_grad_norm(policy.grads, config.max_grad_norm)
    optimizer.step(policy.grads)
    return value


def train_grpo(pretrained: ActorCritic, reward_model: RewardModel, config: GRPOConfig, on_update=None):
    """Fine-tune a copy of ``pretrained`` (π_ref, never changed) with GRPO. Its value network is never used.
    ``on_update(stats, policy)`` is called after every iteration. Returns (the fine-tuned model, statistics)."""
    rng = np.random.default_rng(config.seed)
    agent, reference = pretrained.copy(), pretrained.copy()
    policy = agent.nets["policy"]
    optimizer = Adam(policy.params, lr=config.lr)
    history = []
    for update in range(1, config.updates + 1):
        prompts = np.repeat(make_prompts(config.prompts, rng, config.prompt_len), config.group, axis=0)
        batch = collect(agent, reference, reward_model, prompts, 0.0, rng, config.response_len)
        inside = np.arange(batch["logp"].shape[1])[None, :] < batch["lengths"][:, None]
        returns = batch["scores"]
        if config.kl_in == "reward":  # R − β Σ_t log π_θold/π_ref: a one-sample estimate of R − β KL per response
            returns = returns - config.beta * np.where(inside, batch["logp"] - batch["logp_ref"], 0.0).sum(axis=1)
        grouped = returns.reshape(config.prompts, config.group)
        advantages = group_advantages(grouped, normalize_std=config.normalize_std).reshape(-1)
        for epoch in epochs_of(len(prompts), config.epochs, config.minibatch_responses, rng):
            for take in epoch:
                lengths = batch["lengths"][take]
                valid = np.arange(batch["logp"].shape[1])[None, :] < lengths[:, None]
                minibatch = {key: batch[key][take][valid] for key in ("obs", "actions", "logp", "logp_ref")}
                minibatch["advantages"] = np.broadcast_to(advantages[take][:, None], valid.shape)[valid]
                per_token = 1.0 / (len(take) * (lengths if config.average_over_tokens else np.ones_like(lengths)))
                minibatch["weights"] = np.broadcast_to(per_token[:, None], valid.shape)[valid]
                grpo_step(policy, optimizer, minibatch, config)
        logp_after = Categorical(policy(batch["obs"][inside])).log_prob(batch["actions"][inside])
        stats = {
            "update": update,
            "score": float(np.mean(batch["scores"])),
            **sequence_stats(batch["tokens"], batch["text_lengths"]),
            "kl_to_reference": float(np.mean(np.where(inside, batch["logp"] - batch["logp_ref"], 0.0).sum(axis=1))),
            "length": float(np.mean(batch["lengths"])),
            "approx_kl": losses.approx_kl(logp_after, batch["logp"][inside]),
            "clip_fraction": losses.clip_fraction(logp_after, batch["logp"][inside], config.clip_epsilon),
        }
        history.append(stats)
        if on_update is not None:
            on_update(stats, agent)
    return agent, history
