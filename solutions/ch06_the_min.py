"""Chapter 6: the min in L^CLIP, and the asymmetry it creates.

L^CLIP takes the smaller of the unclipped term r_t Â_t and the clipped term clip(r_t, 1 − ε, 1 + ε) Â_t. The result
is a pessimistic bound: the objective never gains from moving r_t past the band in the direction that helps, but it
keeps the full (unclipped) penalty for moves that make things worse.

Every array returned is a new float64 array (never an argument itself or a view of one); every value is a float.

Grade: ``minippo grade 6``
"""

from __future__ import annotations

import numpy as np

EXERCISES = ["clip_objective"]
TRANSFER = ["clip_objective_logits_gradient"]  # the chapter's idea applied to a case the book has not shown


def clip_objective(logp: np.ndarray, logp_old: np.ndarray, advantages: np.ndarray, epsilon: float):
    """L^CLIP, the paper's eq. 7 (the book's (5.1)), the mean over the batch, and its gradient.

    logp: (n,) log π_θ, the variable.  logp_old, advantages: (n,) constants.  epsilon: ε > 0.
    Returns (value, grad): value a float, never above L^CPI on the same batch; grad = ∂L^CLIP/∂ log π_θ(a_t|s_t),
    shape (n,). Where the two terms of the min are equal, use the unclipped term's derivative.
    """
    n = len(logp)
    ratio = np.exp(logp - logp_old)
    unclipped = ratio * advantages
    clipped = np.clip(ratio, 1.0 - epsilon, 1.0 + epsilon) * advantages
    # the clipped term is flat in θ; where it is the smaller, the min passes no gradient
    unclipped_is_min = unclipped <= clipped
    return float(np.mean(np.minimum(unclipped, clipped))), np.where(unclipped_is_min, unclipped, 0.0) / n


def clip_objective_logits_gradient(logits, actions, logp_old, advantages, epsilon: float):
    """Transfer task: L^CLIP for a categorical policy, differentiated all the way to its logits.

    logits: (n, k) z, the variable; π_θ(·|s_t) = softmax(z_t).  actions: (n,) integers.  logp_old, advantages: (n,)
    constants.  epsilon: ε > 0.
    Returns (value, grad): value = L^CLIP (eq. 7) on the batch, a float; grad = ∂L^CLIP/∂z, shape (n, k). Where the two
    terms of the min are equal, take the unclipped term's derivative, as clip_objective does.
    """
    n = len(actions)
    rows, actions = np.arange(n), actions.astype(np.int64)
    shifted = logits - logits.max(axis=1, keepdims=True)
    log_probs = shifted - np.log(np.exp(shifted).sum(axis=1, keepdims=True))
    ratio = np.exp(log_probs[rows, actions] - logp_old)
    unclipped = ratio * advantages
    clipped = np.clip(ratio, 1.0 - epsilon, 1.0 + epsilon) * advantages
    grad_logp = np.where(unclipped <= clipped, unclipped, 0.0) / n
    score = -np.exp(log_probs)
    score[rows, actions] += 1.0
    return float(np.mean(np.minimum(unclipped, clipped))), score * grad_logp[:, None]
