"""Chapter 3: the vanilla policy gradient objective L^PG, and advantages with a baseline.

Objectives are written as the paper writes them, as something to *maximise*, averaged over a minibatch of n samples,
and each returns its value together with its gradient with respect to log π_θ(a_t|s_t), one entry per sample. The
distribution's ``*_backward`` (chapter 2) and the network's backward pass (chapter 1) carry that gradient on to θ.

Every array returned is a new float64 array (never an argument itself or a view of one); every value is a float.

Grade: ``minippo grade 3``
"""

from __future__ import annotations

import numpy as np

EXERCISES = ["pg_objective", "normalize_advantages"]
TRANSFER = ["linear_softmax_policy_gradient"]  # the chapter's idea applied to a case the book has not shown


def pg_objective(logp: np.ndarray, advantages: np.ndarray):
    """L^PG, the paper's eq. 2 (the book's (3.1)), the mean over the n samples of the batch, and its gradient.

    logp: (n,) log π_θ(a_t|s_t), the variable.  advantages: (n,) Â_t, constants (no gradient flows into them).
    Returns (value, grad): value a Python float; grad of shape (n,) is ∂L^PG/∂ log π_θ(a_t|s_t), one entry per sample.
    """
    n = len(logp)
    value = float(np.mean(logp * advantages))
    return value, advantages / n


def normalize_advantages(advantages: np.ndarray) -> np.ndarray:
    """The advantages of one minibatch shifted to mean 0 and scaled to standard deviation 1: a baseline and a scale.

    advantages: (n,).  Returns a new (n,) array. Use the population standard deviation (np.std) and add 1e-8 to it
    before dividing, so that equal advantages give zeros, never NaN. A batch of one sample has no spread to measure:
    return it unchanged (a copy).
    """
    if len(advantages) < 2:
        return np.array(advantages, dtype=np.float64)
    return (advantages - advantages.mean()) / (advantages.std() + 1e-8)


def linear_softmax_policy_gradient(features: np.ndarray, theta: np.ndarray, actions: np.ndarray, advantages):
    """Transfer task: L^PG's gradient carried all the way to the parameters of a linear softmax policy.

    The policy: π_θ(·|s_t) = softmax(s_t θ), features s_t one row of ``features``.
    features: (n, d).  theta: (d, k).  actions: (n,) integers in 0..k−1.  advantages: (n,) Â_t, constants.
    Returns (value, grad): value = L^PG (eq. 2, the mean over the batch) as a float; grad = ∂L^PG/∂θ, (d, k).
    """
    logits = features @ theta
    shifted = logits - logits.max(axis=1, keepdims=True)
    log_probs = shifted - np.log(np.exp(shifted).sum(axis=1, keepdims=True))
    rows, actions = np.arange(len(actions)), actions.astype(np.int64)
    n = len(actions)
    score = -np.exp(log_probs)
    score[rows, actions] += 1.0
    return float(np.mean(log_probs[rows, actions] * advantages)), features.T @ (score * advantages[:, None]) / n
