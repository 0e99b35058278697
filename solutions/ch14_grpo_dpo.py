"""Chapter 14: GRPO and DPO beside PPO. Three pieces that are new in PPO's descendants: GRPO's advantages, measured
within the group of responses to one prompt; GRPO's objective, the clipped surrogate minus β k3 per token, with its
gradient with respect to the token log-probabilities; and DPO's loss, the Bradley–Terry loss on the implicit reward
β log π_θ(y|x)/π_ref(y|x), with its gradient with respect to the policy's sequence log-probabilities.

Grade: ``minippo grade 14``
"""

from __future__ import annotations

import numpy as np

EXERCISES = ["group_advantages", "grpo_objective", "dpo_loss"]
TRANSFER = ["ipo_loss"]  # the chapter's idea applied to a case the book has not shown


def group_advantages(scores: np.ndarray, eps: float = 1e-8) -> np.ndarray:
    """The group-relative advantage of every response (the book's (14.1)), with the standard deviation of its group the
    population one (ddof = 0), ``eps`` added to it before dividing.

    scores: (m, G), row i the scores of the G responses to prompt i.  Returns (m, G) float64.
    """
    scores = np.asarray(scores, dtype=np.float64)
    centred = scores - scores.mean(axis=1, keepdims=True)
    return centred / (scores.std(axis=1, keepdims=True) + eps)


def grpo_objective(logp, logp_old, logp_ref, advantages, weights, epsilon: float, beta: float):
    """GRPO's objective over a minibatch of tokens (the book's (14.2), the per-token KL estimate k3 of (14.3)), each
    token weighted by w_t, to be maximised, and its gradient.

    logp, logp_old, logp_ref: (n,) log π_θ, log π_θold and log π_ref of the n tokens' actions; advantages: (n,) Â_t;
    weights: (n,) w_t (1 / (responses × its response's length) in GRPO). Returns (J as a float, ∂J/∂ log π_θ (n,)),
    the gradient taken with logp_old, logp_ref, the advantages and the weights held fixed. Where the two terms of the
    min are equal, take the unclipped one's derivative.
    """
    ratio = np.exp(logp - logp_old)
    unclipped = ratio * advantages
    clipped = np.clip(ratio, 1.0 - epsilon, 1.0 + epsilon) * advantages
    ref_over_policy = np.exp(logp_ref - logp)  # π_ref/π_θ
    k3 = ref_over_policy - (logp_ref - logp) - 1.0
    value = float(np.sum(weights * (np.minimum(unclipped, clipped) - beta * k3)))
    # d(r Â)/d log π = r Â where the unclipped term is the smaller (the clipped one is flat); dk3/d log π = 1 − π_ref/π
    grad = weights * (np.where(unclipped <= clipped, unclipped, 0.0) - beta * (1.0 - ref_over_policy))
    return value, grad


def dpo_loss(logp_preferred, logp_rejected, ref_preferred, ref_rejected, beta: float):
    """The DPO loss over n pairs (the book's (14.5)), the mean over the pairs, and its gradient.

    logp_preferred, logp_rejected: (n,) sequence log-probabilities of the preferred (y_w) and rejected (y_l)
    responses under the policy π_θ; ref_preferred, ref_rejected: the same under the frozen reference π_ref.  beta: β.
    Returns (loss, grad_preferred, grad_rejected): the loss as a float, and ∂L/∂ log π_θ(y_w|x) and
    ∂L/∂ log π_θ(y_l|x), both (n,). It must stay finite for margins of ±1000.
    """
    n = len(logp_preferred)
    margin = beta * ((logp_preferred - ref_preferred) - (logp_rejected - ref_rejected))
    loss = float(np.logaddexp(0.0, -margin).sum()) / n
    wrong = np.exp(-np.logaddexp(0.0, margin))  # σ(−Δ)
    return loss, -beta * wrong / n, beta * wrong / n


def ipo_loss(logp_preferred, logp_rejected, ref_preferred, ref_rejected, tau: float):
    """Transfer task: IPO's loss (Azar et al. 2023), DPO's pairs with a squared loss in place of −log σ, and its
    gradient.

    For each pair, h = (log π_θ(y_w|x) − log π_ref(y_w|x)) − (log π_θ(y_l|x) − log π_ref(y_l|x)); the loss is the mean
    over the n pairs of (h − 1/(2τ))², which pulls every margin h to the same target 1/(2τ) instead of pushing it up
    without end as DPO's does.
    logp_preferred, logp_rejected, ref_preferred, ref_rejected: (n,) as for dpo_loss.  tau: τ > 0.
    Returns (loss, grad_preferred, grad_rejected): the loss as a float, and ∂L/∂ log π_θ(y_w|x) and
    ∂L/∂ log π_θ(y_l|x), both (n,).
    """
    n = len(logp_preferred)
    gap = (logp_preferred - ref_preferred) - (logp_rejected - ref_rejected) - 1.0 / (2.0 * tau)
    return float(np.mean(gap * gap)), 2.0 * gap / n, -2.0 * gap / n
