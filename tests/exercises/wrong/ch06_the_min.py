"""Plausible mistakes in chapter 6: L^CLIP without its min, or with the min in the wrong place."""

import numpy as np

from solutions.ch05_clipping import clipped_surrogate


def without_the_min(logp, logp_old, advantages, epsilon):
    """The clipped term alone (chapter 5's surrogate): optimistic where the move hurts."""
    return clipped_surrogate(logp, logp_old, advantages, epsilon)


def max_instead_of_min(logp, logp_old, advantages, epsilon):
    """max(r Â, clip(r) Â): an optimistic bound."""
    ratio = np.exp(logp - logp_old)
    unclipped = ratio * advantages
    clipped = np.clip(ratio, 1 - epsilon, 1 + epsilon) * advantages
    use_unclipped = unclipped >= clipped
    return float(np.mean(np.maximum(unclipped, clipped))), np.where(use_unclipped, unclipped, 0.0) / len(logp)


def min_of_the_ratios(logp, logp_old, advantages, epsilon):
    """min(r, clip(r)) · Â: the min taken before multiplying by Â, which is wrong whenever Â < 0."""
    ratio = np.exp(logp - logp_old)
    clipped_ratio = np.clip(ratio, 1 - epsilon, 1 + epsilon)
    smaller = np.minimum(ratio, clipped_ratio)
    grad = np.where(ratio <= clipped_ratio, ratio * advantages, 0.0) / len(logp)
    return float(np.mean(smaller * advantages)), grad


def gradient_zero_outside_the_band(logp, logp_old, advantages, epsilon):
    """The right value, but the gradient cut wherever r leaves the band, also where the move hurts."""
    ratio = np.exp(logp - logp_old)
    unclipped = ratio * advantages
    clipped = np.clip(ratio, 1 - epsilon, 1 + epsilon) * advantages
    inside = np.abs(ratio - 1) < epsilon
    return float(np.mean(np.minimum(unclipped, clipped))), np.where(inside, unclipped, 0.0) / len(logp)


def gradient_never_zero(logp, logp_old, advantages, epsilon):
    """The right value, but the gradient of the unclipped term everywhere."""
    ratio = np.exp(logp - logp_old)
    unclipped = ratio * advantages
    clipped = np.clip(ratio, 1 - epsilon, 1 + epsilon) * advantages
    return float(np.mean(np.minimum(unclipped, clipped))), unclipped / len(logp)


def ratio_from_exponentials(logp, logp_old, advantages, epsilon):
    """Right formula, but r = exp(log π)/exp(log π_old), which is 0/0 near −900."""
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.exp(logp) / np.exp(logp_old)
    unclipped = ratio * advantages
    clipped = np.clip(ratio, 1 - epsilon, 1 + epsilon) * advantages
    return float(np.mean(np.minimum(unclipped, clipped))), np.where(unclipped <= clipped, unclipped, 0.0) / len(logp)


VARIANTS = {
    "without_the_min": {"clip_objective": without_the_min},
    "max_instead_of_min": {"clip_objective": max_instead_of_min},
    "min_of_the_ratios": {"clip_objective": min_of_the_ratios},
    "gradient_zero_outside_the_band": {"clip_objective": gradient_zero_outside_the_band},
    "gradient_never_zero": {"clip_objective": gradient_never_zero},
    "ratio_from_exponentials": {"clip_objective": ratio_from_exponentials},
}
