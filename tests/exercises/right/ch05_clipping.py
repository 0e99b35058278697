"""Other correct ways to write chapter 5."""

import numpy as np


def clipped_surrogate_closed_band(logp, logp_old, advantages, epsilon):
    """The gradient passed on the closed band 1 − ε ≤ r ≤ 1 + ε (a tie at the edge sent the other way)."""
    ratio = np.exp(logp - logp_old)
    inside = (ratio >= 1.0 - epsilon) & (ratio <= 1.0 + epsilon)
    value = np.mean(np.minimum(np.maximum(ratio, 1.0 - epsilon), 1.0 + epsilon) * advantages)
    return float(value), np.where(inside, ratio * advantages, 0.0) / len(ratio)


def clip_fraction_two_sides(logp, logp_old, epsilon):
    """Counts r < 1 − ε and r > 1 + ε separately."""
    ratio = np.exp(logp - logp_old)
    return float(np.count_nonzero((ratio < 1.0 - epsilon) | (ratio > 1.0 + epsilon)) / len(ratio))


def clip_fraction_expm1(logp, logp_old, epsilon):
    """r − 1 computed as expm1(log π − log π_old), exact to the last digit near r = 1."""
    return float(np.mean(np.abs(np.expm1(logp - logp_old)) > epsilon))


VARIANTS = {
    "clipped_surrogate_closed_band": {"clipped_surrogate": clipped_surrogate_closed_band},
    "clip_fraction_two_sides": {"clip_fraction": clip_fraction_two_sides},
    "clip_fraction_expm1": {"clip_fraction": clip_fraction_expm1},
}
