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
    """Ê_t[clip(r_t, 1 − ε, 1 + ε) Â_t] with r_t = exp(log π_θ − log π_θold), and its gradient.

    logp: (n,) the variable.  logp_old, advantages: (n,) constants.  epsilon: ε > 0.
    Returns (value, grad): value a float; grad = ∂/∂ log π_t of the value, shape (n,):
        r_t Â_t / n   where 1 − ε < r_t < 1 + ε  (the clip does nothing there, and ∂r_t/∂ log π_t = r_t)
        0             where r_t is outside the band (the clipped ratio is a constant there)
    """
    n = len(logp)
    ratio = np.exp(logp - logp_old)
    clipped = np.clip(ratio, 1.0 - epsilon, 1.0 + epsilon)
    inside = (ratio > 1.0 - epsilon) & (ratio < 1.0 + epsilon)
    return float(np.mean(clipped * advantages)), np.where(inside, ratio * advantages, 0.0) / n


def clip_fraction(logp: np.ndarray, logp_old: np.ndarray, epsilon: float) -> float:
    """The fraction of samples whose ratio r_t lies outside the band, |r_t − 1| > ε: a float in [0, 1].

    A diagnostic logged at every update: how much of the batch the clip acts on.
    """
    ratio = np.exp(logp - logp_old)
    return float(np.mean(np.abs(ratio - 1.0) > epsilon))
