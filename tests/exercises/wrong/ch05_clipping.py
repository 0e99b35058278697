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


def clipped_band_on_log_ratio(logp, logp_old, advantages, epsilon):
    """The value clipped right, but the gradient's band tested on |log r| < ε instead of |r − 1| < ε."""
    ratio = np.exp(logp - logp_old)
    inside = np.abs(logp - logp_old) < epsilon
    value = float(np.mean(np.clip(ratio, 1 - epsilon, 1 + epsilon) * advantages))
    return value, np.where(inside, ratio * advantages, 0.0) / len(logp)


def clipped_epsilon_fixed(logp, logp_old, advantages, epsilon):
    """ε = 0.2 written into the code, whatever epsilon is passed."""
    ratio = np.exp(logp - logp_old)
    inside = (ratio > 0.8) & (ratio < 1.2)
    return float(np.mean(np.clip(ratio, 0.8, 1.2) * advantages)), np.where(inside, ratio * advantages, 0.0) / len(logp)


def clipped_gradient_of_the_clipped_ratio(logp, logp_old, advantages, epsilon):
    """The gradient clip(r) Â / n everywhere: the clipped ratio's value where its derivative belongs."""
    ratio = np.exp(logp - logp_old)
    clipped = np.clip(ratio, 1 - epsilon, 1 + epsilon)
    return float(np.mean(clipped * advantages)), clipped * advantages / len(logp)


def clipped_float32(logp, logp_old, advantages, epsilon):
    """Right numbers, computed and returned in float32."""
    ratio = np.exp(logp - logp_old).astype(np.float32)
    inside = (ratio > 1 - epsilon) & (ratio < 1 + epsilon)
    value = float(np.mean(np.clip(ratio, 1 - epsilon, 1 + epsilon) * advantages))
    return value, np.where(inside, ratio * advantages.astype(np.float32), np.float32(0)) / np.float32(len(logp))


def clipped_summed(logp, logp_old, advantages, epsilon):
    """The sum over the batch instead of the mean (value and gradient)."""
    ratio = np.exp(logp - logp_old)
    inside = (ratio >= 1 - epsilon) & (ratio <= 1 + epsilon)
    return float(np.sum(np.clip(ratio, 1 - epsilon, 1 + epsilon) * advantages)), np.where(
        inside, ratio * advantages, 0.0
    )


def clip_fraction_on_log_ratio(logp, logp_old, epsilon):
    """Counts |log r| > ε, a band that differs from |r − 1| > ε between 1 + ε and e^ε and between e^−ε and 1 − ε."""
    return float(np.mean(np.abs(logp - logp_old) > epsilon))


def clip_fraction_python_or(logp, logp_old, epsilon):
    """A Python `or` between two arrays: fine for one sample, an error for a batch."""
    ratio = np.exp(logp - logp_old)
    return float(np.mean((ratio < 1 - epsilon) or (ratio > 1 + epsilon)))


def clip_fraction_epsilon_fixed(logp, logp_old, epsilon):
    """ε = 0.2 written into the code."""
    return float(np.mean(np.abs(np.exp(logp - logp_old) - 1) > 0.2))


def clip_fraction_of_the_inverse_ratio(logp, logp_old, epsilon):
    """r computed as π_old/π, exp(log π_old − log π): the same for ratios far from 1, wrong near the band's edges."""
    return float(np.mean(np.abs(np.exp(logp_old - logp) - 1) > epsilon))


def clip_fraction_at_least_epsilon(logp, logp_old, epsilon):
    """|r − 1| ≥ ε: a ratio exactly on an edge of the band counted as outside."""
    return float(np.mean(np.abs(np.exp(logp - logp_old) - 1) >= epsilon))


VARIANTS.update(
    {
        "clip_fraction_of_the_inverse_ratio": {"clip_fraction": clip_fraction_of_the_inverse_ratio},
        "clip_fraction_at_least_epsilon": {"clip_fraction": clip_fraction_at_least_epsilon},
        "clipped_band_on_log_ratio": {"clipped_surrogate": clipped_band_on_log_ratio},
        "clipped_epsilon_fixed": {"clipped_surrogate": clipped_epsilon_fixed},
        "clipped_gradient_of_the_clipped_ratio": {"clipped_surrogate": clipped_gradient_of_the_clipped_ratio},
        "clipped_float32": {"clipped_surrogate": clipped_float32},
        "clipped_summed": {"clipped_surrogate": clipped_summed},
        "clip_fraction_on_log_ratio": {"clip_fraction": clip_fraction_on_log_ratio},
        "clip_fraction_python_or": {"clip_fraction": clip_fraction_python_or},
        "clip_fraction_epsilon_fixed": {"clip_fraction": clip_fraction_epsilon_fixed},
    }
)


def clipped_surrogate_open_band(logp, logp_old, advantages, epsilon):
    """The gradient passed on the open band 1 − ε < r < 1 + ε only: a ratio exactly on an edge loses its gradient,
    where the contract's closed band keeps it."""
    ratio = np.exp(logp - logp_old)
    inside = (ratio > 1.0 - epsilon) & (ratio < 1.0 + epsilon)
    value = np.mean(np.minimum(np.maximum(ratio, 1.0 - epsilon), 1.0 + epsilon) * advantages)
    return float(value), np.where(inside, ratio * advantages, 0.0) / len(ratio)


def clipped_with_the_min(logp, logp_old, advantages, epsilon):
    """The chapter's L^CLIP, min(r Â, clip(r) Â), with its asymmetric gradient, where the clipped term is asked."""
    ratio = np.exp(logp - logp_old)
    unclipped, clipped = ratio * advantages, np.clip(ratio, 1 - epsilon, 1 + epsilon) * advantages
    grad = np.where(unclipped <= clipped, unclipped, 0.0) / len(logp)
    return float(np.mean(np.minimum(unclipped, clipped))), grad


VARIANTS.update(
    {
        "clipped_surrogate_open_band": {"clipped_surrogate": clipped_surrogate_open_band},
        "clipped_with_the_min": {"clipped_surrogate": clipped_with_the_min},
    }
)

# what the first failing test's message must say (a regular expression), so that the scoreboard names the mistake
FIRST_FAILURE = {
    "clipped_gradient_not_zeroed": r"gradient for one sample with r = 1\.5.*should be 0",
    "clipped_gradient_without_ratio": r"gradient for one sample .* should be 0\.9 \(r Â",
    "clipped_band_around_zero": r"one sample",
    "clipped_log_ratio": r"one sample",
    "clip_fraction_one_side": r"r = 0\.5 .*should be 1",
    "clip_fraction_counts_inside": r"r = 1\.5 .*should be 1, not 0",
    "clip_fraction_a_count": r"fraction .* got 4, expected 1",
    "clipped_band_on_log_ratio": r"r = 1\.21.*not on log r\), not 1\.21: the gradient's band tested on \|log r\|",
    "clipped_epsilon_fixed": r"r = 1\.15, Â = 1\.0, ε = 0\.1.*ε fixed at 0\.2",
    "clipped_gradient_of_the_clipped_ratio": r"r = 1\.5.*should be 0",
    "clipped_float32": r"float64 .*not float32",
    "clipped_summed": r"n times too large everywhere: a sum where the mean belongs",
    "clip_fraction_on_log_ratio": r"r = 1\.21 .*not on log r\): a band on \|log r\|\?",
    "clip_fraction_python_or": r"clip_fraction\(logp=array \(\d+,\).*truth value.*np\.where",
    "clip_fraction_epsilon_fixed": r"r = 1\.15 and ε = 0\.1",
    "clip_fraction_of_the_inverse_ratio": r"r = 0\.83 .*should be 0, not 1.*π_old/π",
    "clip_fraction_at_least_epsilon": r"exactly on the edges.*≥ ε",
    "clipped_surrogate_open_band": r"exactly on the edges of the band.*open band",
    "clipped_with_the_min": r"r = 0\.5, .*should be 0\.8.*: the min's asymmetric .*chapter 6's L\^CLIP",
}


# the transfer task


def _clip_parts(logp, logp_old, advantages, epsilon):
    ratio = np.exp(logp - logp_old)
    unclipped = ratio * advantages
    clipped = np.clip(ratio, 1 - epsilon, 1 + epsilon) * advantages
    return np.minimum(unclipped, clipped), np.where(unclipped <= clipped, unclipped, 0.0)


def dual_clip_without_the_bound(logp, logp_old, advantages, epsilon, dual_clip):
    """Plain L^CLIP: the lower bound c Â never applied."""
    term, grad = _clip_parts(logp, logp_old, advantages, epsilon)
    return float(np.mean(term)), grad / len(logp)


def dual_clip_bound_on_every_sign(logp, logp_old, advantages, epsilon, dual_clip):
    """max(L^CLIP's term, c Â) for every sample, positive advantages included."""
    term, grad = _clip_parts(logp, logp_old, advantages, epsilon)
    floor = dual_clip * advantages
    bounded = term < floor
    return float(np.mean(np.where(bounded, floor, term))), np.where(bounded, 0.0, grad) / len(logp)


def dual_clip_gradient_not_zeroed(logp, logp_old, advantages, epsilon, dual_clip):
    """The value bounded, but the gradient left as L^CLIP's where the bound binds."""
    term, grad = _clip_parts(logp, logp_old, advantages, epsilon)
    floor = dual_clip * advantages
    bounded = (advantages < 0) & (term < floor)
    return float(np.mean(np.where(bounded, floor, term))), grad / len(logp)


def dual_clip_min_for_max(logp, logp_old, advantages, epsilon, dual_clip):
    """min(term, c Â) for Â < 0: the bound taken as a ceiling instead of a floor."""
    term, grad = _clip_parts(logp, logp_old, advantages, epsilon)
    floor = dual_clip * advantages
    bounded = (advantages < 0) & (floor < term)
    return float(np.mean(np.where(bounded, floor, term))), np.where(bounded, 0.0, grad) / len(logp)


VARIANTS.update(
    {
        "dual_clip_without_the_bound": {"dual_clip_surrogate": dual_clip_without_the_bound},
        "dual_clip_bound_on_every_sign": {"dual_clip_surrogate": dual_clip_bound_on_every_sign},
        "dual_clip_gradient_not_zeroed": {"dual_clip_surrogate": dual_clip_gradient_not_zeroed},
        "dual_clip_min_for_max": {"dual_clip_surrogate": dual_clip_min_for_max},
    }
)
FIRST_FAILURE.update(
    {
        "dual_clip_without_the_bound": r"r = 4\.0, Â = -1\.0.*without the bound",
        "dual_clip_bound_on_every_sign": r"r = 0\.5, Â = 1\.0.*positive advantage too",
        "dual_clip_gradient_not_zeroed": r"gradient for one sample with r = 4\.0, Â = -1\.0.*L\^CLIP's gradient where",
        "dual_clip_min_for_max": r"r = 0\.5, Â = -1\.0.*a floor for Â < 0",
    }
)
