"""PPO on tokens: fine-tune the pretrained language model against the reward model, with a per-token KL penalty
that keeps it near the frozen pretrained model (Ziegler et al. 2019; Stiennon et al. 2020; Ouyang et al. 2022).

An episode is one response y to a prompt x drawn from the corpus. The state s_t is the prompt and the response so
far, the action a_t the response's next token, and the reward

    r_t = −β (log π_θold(a_t|s_t) − log π_ref(a_t|s_t)) + [t = last token] R(x, y),

R the reward model's score of the response. Summed over a response, the penalty terms are −β times a sample of
KL[π(·|x) ‖ π_ref(·|x)] over responses, so the return is R(x, y) − β KL; the prompt's tokens were not chosen by the
policy and pay nothing. The rest is Algorithm 1 as minippo runs it: GAE over the
tokens (γ = 1), a value network, L^CLIP (eq. 7) and minippo's own minibatch update (ppo.update_minibatch).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from minippo import advantages as adv
from minippo import losses
from minippo.agent import ActorCritic
from minippo.distributions import Categorical
from minippo.lm.language import (
    BOS,
    EOS,
    MAX_LEN,
    PROMPT_LEN,
    TOKEN,
    VOCAB,
    V,
    generate,
    is_well_formed,
    make_corpus,
    make_prompts,
    new_language_model,
    prefix_features,
    pretrain,
)
from minippo.lm.reward_model import RewardModel, make_preferences, rater_score
from minippo.minibatches import epochs_of
from minippo.optimizer import Adam
from minippo.ppo import update_minibatch


@dataclass
class RLHFConfig:
    """The settings of PPO on tokens. minippo's minibatch update reads its own straight from them (ppo.UpdateSettings:
    the objective, ε, c1, c2 and the last four fields)."""

    seed: int = 0
    updates: int = 60  # PPO iterations
    sequences: int = 64  # sequences generated per iteration (the batch)
    beta: float = 0.1  # β of the per-token KL penalty against π_ref; 0 switches it off
    kl_target: float | None = None  # if set, β is adapted towards this KL per response, by ``kl_rule``
    kl_rule: str = "eq8"  # eq8 (halve or double, chapter 9) or proportional (Ziegler et al. 2019, section 2.2)
    beta_max: float = 100.0  # the adapted β never goes above this
    proportional_gain: float = 0.1  # K_β of the proportional rule
    prompt_len: int = PROMPT_LEN  # the prompt: the first words of a corpus sentence
    response_len: int | None = None  # the longest response, in tokens (None: up to MAX_LEN tokens in all)
    objective: str = "clip"  # clip (L^CLIP, eq. 7) or cpi (L^CPI, eq. 6: no clip)
    clip_epsilon: float = 0.2  # ε
    epochs: int = 4  # K
    minibatch_size: int = 128  # M, in tokens
    lr: float = 1e-3  # Adam's step size
    gamma: float = 1.0  # γ: the score comes at the end, and nothing is discounted inside a sentence
    gae_lambda: float = 0.95  # λ
    value_coef: float = 0.5  # c1
    entropy_coef: float = 0.0  # c2: no entropy bonus
    normalize_advantages: bool = True  # Â to mean 0 and std 1 in each minibatch
    clip_value_loss: bool = False  # V free to move more than ±ε from the rollout's value
    grad_norm_clipping: bool = True  # the whole gradient scaled down to norm max_grad_norm when larger
    max_grad_norm: float = 0.5

    def __post_init__(self):
        if self.kl_rule not in ("eq8", "proportional"):
            raise ValueError(f"kl_rule must be 'eq8' or 'proportional', not {self.kl_rule!r}")


def kl_shaped_rewards(logp, logp_ref, scores, lengths, beta: float) -> np.ndarray:
    """r_t = −β (log π(a_t|s_t) − log π_ref(a_t|s_t)) on every token of a sequence, plus the score R(x) on its last
    token (t = length − 1); 0 after the end. logp, logp_ref: (n, T); scores, lengths: (n,). Returns (n, T)."""
    steps = np.arange(logp.shape[1])[None, :]
    inside = steps < lengths[:, None]
    rewards = np.where(inside, -beta * (logp - logp_ref), 0.0)
    return rewards + np.where(steps == lengths[:, None] - 1, scores[:, None], 0.0)


def proportional_beta(beta: float, kl: float, kl_target: float, gain: float = 0.1) -> float:
    """Ziegler et al.'s (2019) controller: e = clip((KL − KL_target) / KL_target, −0.2, 0.2), β ← β (1 + K_β e).
    β moves by at most 2 % per update (with K_β = 0.1), in proportion to how far the KL is from its target."""
    error = float(np.clip((kl - kl_target) / kl_target, -0.2, 0.2))
    return beta * (1.0 + gain * error)


def collect(
    agent: ActorCritic,
    reference: ActorCritic,
    reward_model: RewardModel,
    prompts: np.ndarray,
    beta: float,
    rng: np.random.Generator,
    response_len: int | None = None,
) -> dict:
    """Let π_θold answer each prompt (n, P) and score the responses: everything PPO needs. ``tokens`` (n, P + R) and
    ``text_lengths`` are the whole texts; the rest, (n, R) and ``lengths`` (n,), are the response's tokens only (a
    response ends with its first full stop, or after R = ``response_len`` tokens)."""
    n, P = prompts.shape
    R = MAX_LEN - P if response_len is None else response_len
    tokens = np.full((n, P + R), TOKEN[BOS], dtype=np.int64)
    tokens[:, :P] = prompts
    lengths = np.full(n, R, dtype=np.int64)
    done = np.zeros(n, dtype=bool)
    obs = np.zeros((n, R, agent.obs_dim))
    logp, logp_ref, values = np.zeros((n, R)), np.zeros((n, R)), np.zeros((n, R))
    for t in range(R):
        obs[:, t] = prefix_features(tokens, P + t)
        out, values[:, t], _ = agent.forward(obs[:, t])
        dist = Categorical(out)
        action = dist.sample(rng)
        logp[:, t] = dist.log_prob(action)
        logp_ref[:, t] = Categorical(reference.policy_output(obs[:, t])).log_prob(action)
        tokens[:, P + t] = np.where(done, TOKEN[BOS], action)
        ended = ~done & (action == TOKEN[EOS])
        lengths[ended] = t + 1
        done |= ended
    scores = reward_model.score(tokens, P + lengths, P)  # the response only, whatever the prompt's length
    rewards = kl_shaped_rewards(logp, logp_ref, scores, lengths, beta)
    return {
        "tokens": tokens,
        "text_lengths": P + lengths,
        "actions": tokens[:, P:],
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
    """Fine-tune a copy of ``pretrained`` with PPO on prompts drawn afresh every iteration; ``pretrained`` itself is
    π_ref and is never changed. ``on_update(stats, policy)`` is called after every iteration.

    Returns (the fine-tuned model, one dict of statistics per iteration)."""
    rng = np.random.default_rng(config.seed)
    agent, reference = pretrained.copy(), pretrained.copy()
    optimizer = Adam(agent.params, lr=config.lr)
    beta, history = config.beta, []
    for update in range(1, config.updates + 1):
        prompts = make_prompts(config.sequences, rng, config.prompt_len)
        batch = collect(agent, reference, reward_model, prompts, beta, rng, config.response_len)
        advantages, returns = token_advantages(batch, config.gamma, config.gae_lambda)
        valid = np.arange(batch["logp"].shape[1])[None, :] < batch["lengths"][:, None]
        data = {
            "obs": batch["obs"][valid],
            "actions": batch["actions"][valid],
            "logp": batch["logp"][valid],
            "values": batch["values"][valid],
            "advantages": advantages[valid],
            "returns": returns[valid],
        }
        for epoch in epochs_of(data, config.epochs, config.minibatch_size, rng):
            for minibatch in epoch:
                update_minibatch(agent, optimizer, minibatch, config)
        logp_after = Categorical(agent.policy_output(data["obs"])).log_prob(data["actions"])
        kl = float(np.mean(np.where(valid, batch["logp"] - batch["logp_ref"], 0.0).sum(axis=1)))
        stats = {
            "update": update,
            "score": float(np.mean(batch["scores"])),
            **sequence_stats(batch["tokens"], batch["text_lengths"]),
            "kl_to_reference": kl,  # Ê over responses of Σ_t log π/π_ref: a sample of KL[π(·|x) ‖ π_ref(·|x)]
            "length": float(np.mean(batch["lengths"])),  # of the responses
            "beta": beta,
            "approx_kl": losses.approx_kl(logp_after, data["logp"]),
            "clip_fraction": losses.clip_fraction(logp_after, data["logp"], config.clip_epsilon),
        }
        history.append(stats)
        if config.kl_target is not None and config.kl_rule == "eq8":  # eq. 8's rule, on the KL to the reference
            beta = min(losses.adaptive_beta(beta, kl, config.kl_target), config.beta_max)
        elif config.kl_target is not None:
            beta = min(proportional_beta(beta, kl, config.kl_target, config.proportional_gain), config.beta_max)
        if on_update is not None:
            on_update(stats, agent)
    return agent, history


def pretrained_pieces(seed: int = 0, corpus_size: int = 3000, pairs: int = 2000, hidden: int = 128, epochs: int = 12):
    """The two pieces RLHF starts from, made from ``seed``: the language model pretrained on a corpus of the grammar
    (π_ref), and the reward model fitted to the rater's preferences. Returns (model, reward model, record), the
    record holding the pretraining losses, the reward model's losses, its agreement with the rater on its own pairs
    and on fresh ones (where ties count half), that of a model blind to the prompt (one weight per word) on the fresh
    ones, and the training pairs themselves (``preferences``: preferred, rejected)."""
    rng = np.random.default_rng(seed)
    tokens, lengths = make_corpus(corpus_size, rng)
    model = new_language_model(rng, hidden)
    pretrain_losses = pretrain(model, tokens, lengths, rng, epochs=epochs)
    preferred, rejected = make_preferences(pairs, rng)
    reward_model = RewardModel(prompt_len=PROMPT_LEN)
    reward_losses = reward_model.fit(preferred, rejected)
    blind = RewardModel(prompt_len=PROMPT_LEN, by_subject=False)  # the same fit, with one weight per word only
    blind.fit(preferred, rejected)
    held_out = make_preferences(pairs, rng)
    rule = [np.array([rater_score(VOCAB[t] for t in row[:n]) for row, n in zip(*side)]) for side in held_out]
    record = {
        "pretrain_losses": pretrain_losses,
        "reward_losses": reward_losses,
        "train_accuracy": reward_model.accuracy(preferred, rejected),
        "held_out_accuracy": reward_model.accuracy(*held_out),
        "blind_held_out_accuracy": blind.accuracy(*held_out),
        # the rater's own rule as a model: the most any model can agree with the rater's noisy choices
        "rule_held_out_accuracy": float(np.mean((rule[0] > rule[1]) + 0.5 * (rule[0] == rule[1]))),
        "preferences": (preferred, rejected),
    }
    return model, reward_model, record


def samples(model: ActorCritic, n: int, rng: np.random.Generator, prompt_len: int = 0) -> list[str]:
    """n texts sampled from ``model``, as text: whole sentences, or responses to ``prompt_len``-word prompts drawn
    from the corpus (the prompt shown with its response)."""
    prompts = make_prompts(n, rng, prompt_len) if prompt_len else None
    tokens, lengths = generate(model, n, rng, prompts=prompts)
    return [" ".join(VOCAB[t] for t in row[:length]) for row, length in zip(tokens, lengths)]


# The optimum of the KL-regularised objective, where it can be enumerated. For each prompt x,
#   max_π E_{y∼π}[R(x, y)] − β KL[π(·|x) ‖ π_ref(·|x)]  is reached at  π*(y|x) = π_ref(y|x) exp(R(x, y)/β) / Z(x),
# and for any π the gap to it is  J(π*) − J(π) = β KL[π(·|x) ‖ π*(·|x)],  with J(π*) = β log Z(x).


def all_prompts(length: int = 3) -> np.ndarray:
    """Every prompt of ``length`` words the grammar can start with (3 × 6 × 4 = 72 for DET NOUN VERB), (m, length):
    the corpus draws each word uniformly, so these are equally likely."""
    from itertools import product

    from minippo.lm.language import DETERMINERS, NOUNS, VERBS

    words = list(product(*(DETERMINERS, NOUNS, VERBS)[:length]))
    return np.array([[TOKEN[w] for w in prompt] for prompt in words], dtype=np.int64)


def short_responses() -> tuple[np.ndarray, np.ndarray]:
    """Every response of at most two tokens, as generation makes them: "." alone (it ends the response), or any
    other first token followed by any token. Returns (tokens (K, 2), lengths (K,)), K = 1 + (V − 1) V."""
    firsts = np.array([t for t in range(V) if t != TOKEN[EOS]])
    pairs = np.stack([np.repeat(firsts, V), np.tile(np.arange(V), len(firsts))], axis=1)
    tokens = np.concatenate([[[TOKEN[EOS], TOKEN[BOS]]], pairs])
    lengths = np.concatenate([[1], np.full(len(firsts) * V, 2)])
    return tokens.astype(np.int64), lengths.astype(np.int64)


def response_log_probs(model: ActorCritic, prompts: np.ndarray) -> np.ndarray:
    """log π(y|x) of every short response (short_responses' order) to every prompt, (m, K), exactly."""
    m, P = prompts.shape
    tokens, _ = short_responses()
    texts = np.full((m, P + 2), TOKEN[BOS], dtype=np.int64)
    texts[:, :P] = prompts
    first = Categorical(model.policy_output(prefix_features(texts, P))).log_probs
    firsts = tokens[1::V, 0]  # the first tokens other than ".", in order
    continued = np.repeat(texts, len(firsts), axis=0)
    continued[:, P] = np.tile(firsts, m)
    second = Categorical(model.policy_output(prefix_features(continued, P + 1))).log_probs
    two = first[:, firsts][:, :, None] + second.reshape(m, len(firsts), V)
    return np.concatenate([first[:, [TOKEN[EOS]]], two.reshape(m, -1)], axis=1)


def short_response_scores(reward_model: RewardModel, prompts: np.ndarray) -> np.ndarray:
    """R(x, y) of every short response (short_responses' order) to every prompt (m, P), (m, K): the reward model reads
    the prompt's noun and counts the response's tokens."""
    tokens, lengths = short_responses()
    m, P = prompts.shape
    texts = np.concatenate([np.repeat(prompts, len(tokens), axis=0), np.tile(tokens, (m, 1))], axis=1)
    return reward_model.score(texts, P + np.tile(lengths, m), P).reshape(m, len(tokens))


def optimal_log_probs(logp_ref: np.ndarray, scores: np.ndarray, beta: float):
    """log π*(y|x) = log π_ref(y|x) + R(x, y)/β − log Z(x), and log Z(x): (m, K) and (m,)."""
    logits = logp_ref + scores / beta
    top = logits.max(axis=1, keepdims=True)
    log_z = top[:, 0] + np.log(np.exp(logits - top).sum(axis=1))
    return logits - log_z[:, None], log_z


def response_kl(logp: np.ndarray, logq: np.ndarray) -> float:
    """Ê_x KL[p(·|x) ‖ q(·|x)] = Ê_x Σ_y p(y|x) (log p − log q), exactly: the KL between two distributions over
    the responses y (columns, as response_log_probs gives them), averaged over the prompts x (rows)."""
    return float(np.mean(np.sum(np.exp(logp) * (logp - logq), axis=1)))
