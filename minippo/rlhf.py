"""PPO on tokens: fine-tune the pretrained language model against the reward model, with a per-token KL penalty
that keeps it near the frozen pretrained model (Ziegler et al. 2019; Stiennon et al. 2020; Ouyang et al. 2022).

An episode is one generated sequence. The state s_t is the prefix, the action a_t the next token, and the reward

    r_t = −β (log π_θold(a_t|s_t) − log π_ref(a_t|s_t)) + [t = last token] R(x),

R the reward model's score of the whole sequence. Summed over a sequence, the penalty terms are −β times a sample of
KL[π ‖ π_ref] over sequences, so the return is R(x) − β KL. The rest is Algorithm 1 as minippo runs it: GAE over the
tokens (γ = 1), a value network, L^CLIP (eq. 7) and minippo's own minibatch update (ppo.update_minibatch).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from minippo import advantages as adv
from minippo import losses
from minippo.agent import ActorCritic
from minippo.distributions import Categorical
from minippo.language import (
    BOS,
    EOS,
    MAX_LEN,
    TOKEN,
    VOCAB,
    generate,
    is_well_formed,
    make_corpus,
    new_language_model,
    prefix_features,
    pretrain,
)
from minippo.optimizer import Adam
from minippo.ppo import Config, update_minibatch
from minippo.reward_model import RewardModel, make_preferences, rater_score


@dataclass
class RLHFConfig:
    seed: int = 0
    updates: int = 60  # PPO iterations
    sequences: int = 64  # sequences generated per iteration (the batch)
    beta: float = 0.1  # β of the per-token KL penalty against π_ref; 0 switches it off
    kl_target: float | None = None  # if set, β follows eq. 8's rule towards this KL per sequence
    objective: str = "clip"  # clip (L^CLIP, eq. 7) or cpi (L^CPI, eq. 6: no clip)
    clip_epsilon: float = 0.2  # ε
    epochs: int = 4  # K
    minibatch_size: int = 128  # M, in tokens
    lr: float = 1e-3  # Adam's step size
    gamma: float = 1.0  # γ: the score comes at the end, and nothing is discounted inside a sentence
    gae_lambda: float = 0.95  # λ
    value_coef: float = 0.5  # c1
    max_grad_norm: float = 0.5

    def ppo_config(self) -> Config:
        """The fields of minippo's Config that its minibatch update reads."""
        return Config(
            objective=self.objective,
            clip_epsilon=self.clip_epsilon,
            value_coef=self.value_coef,
            entropy_coef=0.0,
            normalize_advantages=True,
            clip_value_loss=False,
            grad_norm_clipping=True,
            max_grad_norm=self.max_grad_norm,
            dtype="float64",
        )


def kl_shaped_rewards(logp, logp_ref, scores, lengths, beta: float) -> np.ndarray:
    """r_t = −β (log π(a_t|s_t) − log π_ref(a_t|s_t)) on every token of a sequence, plus the score R(x) on its last
    token (t = length − 1); 0 after the end. logp, logp_ref: (n, T); scores, lengths: (n,). Returns (n, T)."""
    steps = np.arange(logp.shape[1])[None, :]
    inside = steps < lengths[:, None]
    rewards = np.where(inside, -beta * (logp - logp_ref), 0.0)
    return rewards + np.where(steps == lengths[:, None] - 1, scores[:, None], 0.0)


def copy_model(model: ActorCritic) -> ActorCritic:
    twin = ActorCritic(model.obs_dim, model.kind, model.act_dim, model.hidden_sizes, dtype=model.dtype)
    twin.params[...] = model.params
    return twin


def collect(
    agent: ActorCritic, reference: ActorCritic, reward_model: RewardModel, n: int, beta: float, rng: np.random.Generator
) -> dict:
    """Generate n sequences with π_θold and score them: everything PPO needs, as (n, T) arrays."""
    T = MAX_LEN
    tokens = np.full((n, T), TOKEN[BOS], dtype=np.int64)
    lengths = np.full(n, T, dtype=np.int64)
    done = np.zeros(n, dtype=bool)
    obs = np.zeros((n, T, agent.obs_dim))
    logp, logp_ref, values = np.zeros((n, T)), np.zeros((n, T)), np.zeros((n, T))
    for t in range(T):
        obs[:, t] = prefix_features(tokens, t)
        out, values[:, t], _ = agent.forward(obs[:, t])
        dist = Categorical(out)
        action = dist.sample(rng)
        logp[:, t] = dist.log_prob(action)
        logp_ref[:, t] = Categorical(reference.policy_output(obs[:, t])).log_prob(action)
        tokens[:, t] = np.where(done, TOKEN[BOS], action)
        ended = ~done & (action == TOKEN[EOS])
        lengths[ended] = t + 1
        done |= ended
    scores = reward_model.score(tokens, lengths)
    rewards = kl_shaped_rewards(logp, logp_ref, scores, lengths, beta)
    return {
        "tokens": tokens,
        "lengths": lengths,
        "obs": obs,
        "logp": logp,
        "logp_ref": logp_ref,
        "values": values,
        "scores": scores,
        "rewards": rewards,
    }


def token_advantages(batch: dict, gamma: float, lam: float):
    """GAE (eq. 11) along each sequence, which terminates at its last token: (advantages, value targets), (n, T)."""
    n, T = batch["values"].shape
    steps = np.arange(T)[None, :]
    terminated = steps >= batch["lengths"][:, None] - 1
    next_values = np.concatenate([batch["values"][:, 1:], np.zeros((n, 1))], axis=1)
    advantages = adv.gae(
        batch["rewards"].T, batch["values"].T, next_values.T, terminated.T, np.zeros((T, n), dtype=bool), gamma, lam
    ).T
    return advantages, advantages + batch["values"]


def sequence_stats(tokens, lengths) -> dict:
    """What the rater thinks of the sequences: its mean score and the fraction of well-formed sentences."""
    texts = [[VOCAB[t] for t in row[:length]] for row, length in zip(tokens, lengths)]
    return {
        "rater_score": float(np.mean([rater_score(words) for words in texts])),
        "well_formed": float(np.mean([is_well_formed(words) for words in texts])),
    }


def train_rlhf(pretrained: ActorCritic, reward_model: RewardModel, config: RLHFConfig, on_update=None):
    """Fine-tune a copy of ``pretrained`` with PPO; ``pretrained`` itself is π_ref and is never changed.

    Returns (the fine-tuned model, one dict of statistics per iteration)."""
    rng = np.random.default_rng(config.seed)
    agent, reference = copy_model(pretrained), copy_model(pretrained)
    optimizer = Adam(agent.params, lr=config.lr)
    ppo_config = config.ppo_config()
    beta, history = config.beta, []
    for update in range(1, config.updates + 1):
        batch = collect(agent, reference, reward_model, config.sequences, beta, rng)
        advantages, returns = token_advantages(batch, config.gamma, config.gae_lambda)
        valid = np.arange(MAX_LEN)[None, :] < batch["lengths"][:, None]
        data = {
            "obs": batch["obs"][valid],
            "actions": batch["tokens"][valid],
            "logp": batch["logp"][valid],
            "values": batch["values"][valid],
            "advantages": advantages[valid],
            "returns": returns[valid],
        }
        n = len(data["logp"])
        for _ in range(config.epochs):
            order = rng.permutation(n)
            for start in range(0, n, config.minibatch_size):
                take = order[start : start + config.minibatch_size]
                update_minibatch(agent, optimizer, {key: value[take] for key, value in data.items()}, ppo_config)
        logp_after = Categorical(agent.policy_output(data["obs"])).log_prob(data["actions"])
        kl = float(np.mean(np.where(valid, batch["logp"] - batch["logp_ref"], 0.0).sum(axis=1)))
        stats = {
            "update": update,
            "score": float(np.mean(batch["scores"])),
            **sequence_stats(batch["tokens"], batch["lengths"]),
            "kl_to_reference": kl,  # Ê over sequences of Σ_t log π/π_ref: a sample of KL[π ‖ π_ref]
            "length": float(np.mean(batch["lengths"])),
            "beta": beta,
            "approx_kl": losses.approx_kl(logp_after, data["logp"]),
            "clip_fraction": losses.clip_fraction(logp_after, data["logp"], config.clip_epsilon),
        }
        history.append(stats)
        if config.kl_target is not None:  # eq. 8's rule, on the KL to the reference
            beta = losses.adaptive_beta(beta, kl, config.kl_target)
        if on_update is not None:
            on_update(stats)
    return agent, history


def pretrained_pieces(seed: int = 0, corpus_size: int = 3000, pairs: int = 2000, hidden: int = 128, epochs: int = 12):
    """The two pieces RLHF starts from, made from ``seed``: the language model pretrained on a corpus of the grammar
    (π_ref), and the reward model fitted to the rater's preferences. Returns (model, reward model, record), the
    record holding the pretraining losses, the reward model's losses and its agreement with the rater on its own pairs
    and on fresh ones (where ties count half)."""
    rng = np.random.default_rng(seed)
    tokens, lengths = make_corpus(corpus_size, rng)
    model = new_language_model(rng, hidden)
    pretrain_losses = pretrain(model, tokens, lengths, rng, epochs=epochs)
    preferred, rejected = make_preferences(pairs, rng)
    reward_model = RewardModel()
    reward_losses = reward_model.fit(preferred, rejected)
    held_out = make_preferences(pairs, rng)
    rule = [np.array([rater_score(VOCAB[t] for t in row[:n]) for row, n in zip(*side)]) for side in held_out]
    record = {
        "pretrain_losses": pretrain_losses,
        "reward_losses": reward_losses,
        "train_accuracy": reward_model.accuracy(preferred, rejected),
        "held_out_accuracy": reward_model.accuracy(*held_out),
        # the rater's own rule as a model: the most any model can agree with the rater's noisy choices
        "rule_held_out_accuracy": float(np.mean((rule[0] > rule[1]) + 0.5 * (rule[0] == rule[1]))),
    }
    return model, reward_model, record


def samples(model: ActorCritic, n: int, rng: np.random.Generator) -> list[str]:
    """n sequences sampled from ``model``, as text."""
    tokens, lengths = generate(model, n, rng)
    return [" ".join(VOCAB[t] for t in row[:length]) for row, length in zip(tokens, lengths)]
