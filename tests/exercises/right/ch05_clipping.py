"""Other correct ways to write chapter 5."""

import numpy as np


def clip_fraction_two_sides(logp, logp_old, epsilon):
    """Counts r < 1 − ε and r > 1 + ε separately."""
    ratio = np.exp(logp - logp_old)
    return float(np.count_nonzero((ratio < 1.0 - epsilon) | (ratio > 1.0 + epsilon)) / len(ratio))


def clip_fraction_expm1(logp, logp_old, epsilon):
    """r − 1 computed as expm1(log π − log π_old), exact to the last digit near r = 1."""
    return float(np.mean(np.abs(np.expm1(logp - logp_old)) > epsilon))


VARIANTS = {
    "clip_fraction_two_sides": {"clip_fraction": clip_fraction_two_sides},
    "clip_fraction_expm1": {"clip_fraction": clip_fraction_expm1},
}


def dual_clip_case_by_case(logp, logp_old, advantages, epsilon, dual_clip):
    """Case by case on the sign of Â: (min(r, 1 + ε)) Â above 0; below it, Â times r held in [1 − ε, c] from both
    sides with the gradient alive only where r is strictly between the two."""
    ratio = np.exp(logp - logp_old)
    n = len(logp)
    positive = advantages >= 0
    value_pos = np.minimum(ratio, 1 + epsilon) * advantages
    grad_pos = np.where(ratio <= 1 + epsilon, ratio * advantages, 0.0)
    held = np.minimum(np.maximum(ratio, 1 - epsilon), dual_clip)
    value_neg = held * advantages
    grad_neg = np.where((ratio >= 1 - epsilon) & (ratio <= dual_clip), ratio * advantages, 0.0)
    return float(np.mean(np.where(positive, value_pos, value_neg))), np.where(positive, grad_pos, grad_neg) / n


VARIANTS["dual_clip_case_by_case"] = {"dual_clip_surrogate": dual_clip_case_by_case}
