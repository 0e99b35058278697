"""Chapter 5: clipping the probability ratio to the band [1 − ε, 1 + ε].

This chapter's surrogate uses the clipped ratio alone, clip(r_t, 1 − ε, 1 + ε) Â_t. It is half of L^CLIP: chapter 6
adds the min with the unclipped term, and shows why the clipped term alone is not enough.

Every array returned is a new float64 array (never an argument itself or a view of one); every value is a float.

Grade: ``minippo grade 5``
"""

from __future__ import annotations

import numpy as np

EXERCISES = ["clipped_surrogate", "clip_fraction"]
TRANSFER = ["dual_clip_surrogate"]  # the chapter's idea applied to a case the book has not shown


def clipped_surrogate(logp: np.ndarray, logp_old: np.ndarray, advantages: np.ndarray, epsilon: float):
    """Ê_t[clip(r_t, 1 − ε, 1 + ε) Â_t], the clipped term of L^CLIP on its own, and its gradient.

    logp: (n,) log π_θ(a_t|s_t), the variable.  logp_old, advantages: (n,) constants.  epsilon: ε > 0.
    Returns (value, grad): value a float; grad = ∂value/∂ log π_θ(a_t|s_t), shape (n,). There is no min here: this is
    not chapter 6's L^CLIP. The band is closed: a ratio exactly on an edge, |r_t − 1| = ε, is inside it (the clip
    leaves it unchanged), as in clip_fraction.
    """
    n = len(logp)
    ratio = np.exp(logp - logp_old)
    clipped = np.clip(ratio, 1.0 - epsilon, 1.0 + epsilon)
    inside = (ratio >= 1.0 - epsilon) & (ratio <= 1.0 + epsilon)  # the closed band: an edge is inside
    return float(np.mean(clipped * advantages)), np.where(inside, ratio * advantages, 0.0) / n


def clip_fraction(logp: np.ndarray, logp_old: np.ndarray, epsilon: float) -> float:
    """The fraction of samples whose ratio r_t is clipped: outside the closed band [1 − ε, 1 + ε] (a ratio exactly on an
    edge, |r_t − 1| = ε, is inside and not counted). A float in [0, 1].

    A diagnostic logged at every update: how much of the batch the clip acts on.
    """
    ratio = np.exp(logp - logp_old)
    return float(np.mean(np.abs(ratio - 1.0) > epsilon))


def dual_clip_surrogate(logp, logp_old, advantages, epsilon: float, dual_clip: float):
    """Transfer task: dual-clip PPO's surrogate (Ye et al. 2020), and its gradient.

    For a sample with Â_t ≥ 0 the term is L^CLIP's, min(r_t Â_t, clip(r_t, 1 − ε, 1 + ε) Â_t). For Â_t < 0 it is
    that min bounded from below by c Â_t: max(min(r_t Â_t, clip(r_t, 1 − ε, 1 + ε) Â_t), c Â_t), c = dual_clip > 1,
    so that a bad action whose ratio has grown huge no longer dominates the batch. The value is the mean of the terms.
    logp: (n,) the variable.  logp_old, advantages: (n,) constants.  epsilon: ε > 0.  dual_clip: c > 1 + ε.
    Returns (value, grad): value a float; grad = ∂value/∂ log π_θ(a_t|s_t), shape (n,). Where two terms of a min or
    a max are equal, take the unclipped term's derivative.
    """
    n = len(logp)
    ratio = np.exp(logp - logp_old)
    unclipped = ratio * advantages
    clipped = np.clip(ratio, 1.0 - epsilon, 1.0 + epsilon) * advantages
    term = np.minimum(unclipped, clipped)
    grad = np.where(unclipped <= clipped, unclipped, 0.0)
    floor = dual_clip * advantages
    bounded = (advantages < 0) & (term < floor)  # the floor is a constant: where it binds, no gradient
    return float(np.mean(np.where(bounded, floor, term))), np.where(bounded, 0.0, grad) / n
