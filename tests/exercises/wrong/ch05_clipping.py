"""Plausible mistakes in chapter 5: the clipped term and the clip fraction."""

import numpy as np


def clipped_gradient_not_zeroed(logp, logp_old, advantages, epsilon):
    """The value is clipped, but the gradient is r Â / n everywhere, as if the clip were not there."""
    ratio = np.exp(logp - logp_old)
    value = float(np.mean(np.clip(ratio, 1 - epsilon, 1 + epsilon) * advantages))
    return value, ratio * advantages / len(logp)


def clipped_gradient_without_ratio(logp, logp_old, advantages, epsilon):
    """Inside the band the gradient is Â / n, missing ∂r/∂ log π = r."""
    ratio = np.exp(logp - logp_old)
    inside = np.abs(ratio - 1) < epsilon
    value = float(np.mean(np.clip(ratio, 1 - epsilon, 1 + epsilon) * advantages))
    return value, np.where(inside, advantages, 0.0) / len(logp)


def clipped_band_around_zero(logp, logp_old, advantages, epsilon):
    """clip(r, −ε, ε): the band put around 0 instead of 1."""
    ratio = np.exp(logp - logp_old)
    inside = np.abs(ratio) < epsilon
    value = float(np.mean(np.clip(ratio, -epsilon, epsilon) * advantages))
    return value, np.where(inside, ratio * advantages, 0.0) / len(logp)


def clipped_log_ratio(logp, logp_old, advantages, epsilon):
    """Clips the log-ratio to [1 − ε, 1 + ε] instead of the ratio."""
    log_ratio = logp - logp_old
    inside = np.abs(log_ratio - 1) < epsilon
    value = float(np.mean(np.clip(log_ratio, 1 - epsilon, 1 + epsilon) * advantages))
    return value, np.where(inside, advantages, 0.0) / len(logp)


def clip_fraction_one_side(logp, logp_old, epsilon):
    """Counts only ratios above 1 + ε."""
    return float(np.mean(np.exp(logp - logp_old) > 1 + epsilon))


def clip_fraction_counts_inside(logp, logp_old, epsilon):
    """The fraction inside the band, the complement of what is asked."""
    return float(np.mean(np.abs(np.exp(logp - logp_old) - 1) <= epsilon))


def clip_fraction_a_count(logp, logp_old, epsilon):
    """The number of clipped samples rather than their fraction."""
    return float(np.sum(np.abs(np.exp(logp - logp_old) - 1) > epsilon))


VARIANTS = {
    "clipped_gradient_not_zeroed": {"clipped_surrogate": clipped_gradient_not_zeroed},
    "clipped_gradient_without_ratio": {"clipped_surrogate": clipped_gradient_without_ratio},
    "clipped_band_around_zero": {"clipped_surrogate": clipped_band_around_zero},
    "clipped_log_ratio": {"clipped_surrogate": clipped_log_ratio},
    "clip_fraction_one_side": {"clip_fraction": clip_fraction_one_side},
    "clip_fraction_counts_inside": {"clip_fraction": clip_fraction_counts_inside},
    "clip_fraction_a_count": {"clip_fraction": clip_fraction_a_count},
}
