"""Chapter 13: PPO for a language model in miniature. Two pieces of RLHF: the Bradley–Terry loss that fits a reward
model to preferences, and the per-token reward that PPO maximises, the score at the end minus β times the log-ratio
to the frozen pretrained model at every token.

Bradley–Terry: P(w ≻ l) = σ(r_w − r_l), so the loss of a batch of n pairs is L = −(1/n) Σ log σ(r_w − r_l).

Grade: ``minippo grade 13``
"""

from __future__ import annotations

import numpy as np

EXERCISES = ["bradley_terry_loss", "kl_shaped_rewards"]
TRANSFER = ["plackett_luce_loss"]  # the chapter's idea applied to a case the book has not shown


def bradley_terry_loss(scores_preferred: np.ndarray, scores_rejected: np.ndarray):
    """The Bradley–Terry loss of n preference pairs (the book's (13.2)), the mean over the pairs, and its gradient with
    respect to both scores.

    scores_preferred (r_w), scores_rejected (r_l): (n,).  Returns (loss, grad_preferred, grad_rejected): the loss as
    a float, and ∂L/∂r_w and ∂L/∂r_l, both (n,). It must stay finite for margins r_w − r_l of ±1000.
    """
    n = len(scores_preferred)
    margin = scores_preferred - scores_rejected
    loss = float(np.logaddexp(0.0, -margin).sum()) / n
    wrong = np.exp(-np.logaddexp(0.0, margin))  # σ(−Δ)
    return loss, -wrong / n, wrong / n


def kl_shaped_rewards(logp, logp_ref, scores, lengths, beta: float) -> np.ndarray:
    """The reward of every generated token (the book's (13.7)): the KL penalty at every token of the sequence, with the
    sequence's score R(x) added on its last token t = length − 1, and 0 for the padding after the end.

    logp, logp_ref: (n, T) log-probabilities of the tokens under the policy that sampled them and under the frozen
    reference.  scores: (n,) the reward model's scores.  lengths: (n,) integers in 1 … T.  beta: β ≥ 0.
    Returns (n, T).
    """
    steps = np.arange(logp.shape[1])[None, :]
    inside = steps < lengths[:, None]
    rewards = np.where(inside, -beta * (logp - logp_ref), 0.0)
    return rewards + np.where(steps == lengths[:, None] - 1, scores[:, None], 0.0)


def plackett_luce_loss(scores: np.ndarray):
    """Transfer task: Bradley–Terry's model extended from a pair to a ranking of K responses (Plackett–Luce).

    Each row of scores holds the reward model's scores of K responses to one prompt, ranked best first (column 0 the
    best). The model picks the best response with probability softmax over all K scores, then the next best among
    those left, and so on; the probability of the ranking is the product of these K − 1 choices. The loss is the mean
    over the n rows of the negative log-probability of their ranking. K = 2 is the Bradley–Terry loss.
    scores: (n, K), K ≥ 2.  Returns (loss, grad): the loss as a float and ∂loss/∂scores, (n, K). Finite for scores
    of ±1000.
    """
    n, K = scores.shape
    loss = 0.0
    grad = np.zeros(scores.shape)
    for i in range(K - 1):
        rest = scores[:, i:]
        log_norm = np.logaddexp.reduce(rest, axis=1)
        loss += float(np.sum(log_norm - scores[:, i]))
        grad[:, i:] += np.exp(rest - log_norm[:, None])  # the choice's softmax over the responses still left
        grad[:, i] -= 1.0
    return loss / n, grad / n
