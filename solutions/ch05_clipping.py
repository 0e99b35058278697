"""Chapter 5: clipping the probability ratio to the band [1 − ε, 1 + ε].

This chapter's surrogate uses the clipped ratio alone, clip(r_t, 1 − ε, 1 + ε) Â_t. It is half of L^CLIP: chapter 6
adds the min with the unclipped term, and shows why the clipped term alone is not enough.

Every array returned is a new float64 array (never an argument itself or a view of one); every value is a float.

Grade: ``minippo grade 5``
"""

from __future__ import annotations

import numpy as np

EXERCISES = ["clipped_surrogate", "clip_fraction"]


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
