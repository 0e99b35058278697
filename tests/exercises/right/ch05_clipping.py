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
