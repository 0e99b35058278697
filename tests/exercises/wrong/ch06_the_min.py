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


def case_by_case_on_log_ratio(logp, logp_old, advantages, epsilon):
    """Case by case, with the clip's cases tested on log r against ±ε instead of r against 1 ± ε."""
    log_ratio = logp - logp_old
    ratio = np.exp(log_ratio)
    clipped = ((log_ratio > epsilon) & (advantages > 0)) | ((log_ratio < -epsilon) & (advantages < 0))
    bound = np.where(advantages > 0, 1 + epsilon, 1 - epsilon)
    value = np.where(clipped, bound * advantages, ratio * advantages)
    return float(np.mean(value)), np.where(clipped, 0.0, ratio * advantages) / len(logp)


def gradient_mask_strict(logp, logp_old, advantages, epsilon):
    """The gradient passes where the unclipped term is strictly smaller: inside the band the two are equal, so the
    gradient is lost there."""
    ratio = np.exp(logp - logp_old)
    unclipped = ratio * advantages
    clipped = np.clip(ratio, 1 - epsilon, 1 + epsilon) * advantages
    return float(np.mean(np.minimum(unclipped, clipped))), np.where(unclipped < clipped, unclipped, 0.0) / len(logp)


def epsilon_fixed(logp, logp_old, advantages, epsilon):
    """ε = 0.2 written into the code."""
    ratio = np.exp(logp - logp_old)
    unclipped = ratio * advantages
    clipped = np.clip(ratio, 0.8, 1.2) * advantages
    return float(np.mean(np.minimum(unclipped, clipped))), np.where(unclipped <= clipped, unclipped, 0.0) / len(logp)


def gradient_of_the_min_value(logp, logp_old, advantages, epsilon):
    """min(r Â, clip(r) Â) / n as the gradient: the value of the chosen term where its derivative belongs."""
    ratio = np.exp(logp - logp_old)
    smaller = np.minimum(ratio * advantages, np.clip(ratio, 1 - epsilon, 1 + epsilon) * advantages)
    return float(np.mean(smaller)), smaller / len(logp)


def clip_of_the_product(logp, logp_old, advantages, epsilon):
    """np.clip(r Â, (1 − ε) Â, (1 + ε) Â): with Â < 0 the lower bound is above the upper one, and np.clip returns the
    upper bound (1 + ε) Â wherever r is."""
    ratio = np.exp(logp - logp_old)
    unclipped = ratio * advantages
    clipped = np.clip(unclipped, (1 - epsilon) * advantages, (1 + epsilon) * advantages)
    return float(np.mean(np.minimum(unclipped, clipped))), np.where(unclipped <= clipped, unclipped, 0.0) / len(logp)


def clip_of_the_log_ratio(logp, logp_old, advantages, epsilon):
    """exp(clip(log r, −ε, ε)): the ratio held to (e^−ε, e^ε) instead of (1 − ε, 1 + ε)."""
    ratio = np.exp(logp - logp_old)
    unclipped = ratio * advantages
    clipped = np.exp(np.clip(logp - logp_old, -epsilon, epsilon)) * advantages
    return float(np.mean(np.minimum(unclipped, clipped))), np.where(unclipped <= clipped, unclipped, 0.0) / len(logp)


VARIANTS.update(
    {
        "clip_of_the_product": {"clip_objective": clip_of_the_product},
        "clip_of_the_log_ratio": {"clip_objective": clip_of_the_log_ratio},
        "case_by_case_on_log_ratio": {"clip_objective": case_by_case_on_log_ratio},
        "gradient_mask_strict": {"clip_objective": gradient_mask_strict},
        "epsilon_fixed": {"clip_objective": epsilon_fixed},
        "gradient_of_the_min_value": {"clip_objective": gradient_of_the_min_value},
    }
)

FIRST_FAILURE = {
    "without_the_min": r"r = 1\.5, Â = -1\.0.*, not -1\.2: the clipped term alone",
    "max_instead_of_min": r"the optimistic bound; L\^CLIP takes the min",
    "min_of_the_ratios": r", not -0\.5: min\(r, clip\(r\)\) Â: the min taken over the ratios",
    "gradient_zero_outside_the_band": r"r = 1\.5, Â = -1\.0.*, not 0: the gradient of the clipped term alone",
    "gradient_never_zero": r"r = 1\.5, Â = 1\.0.*should be 0",
    "case_by_case_on_log_ratio": r"r = 1\.21.*not on log r.*, not 1\.21: the log-ratio clipped to ±ε",
    "gradient_mask_strict": r"r = 1\.1, Â = 2\.0.*should be 2\.2.*inside the band.*, not 0",
    "epsilon_fixed": r"ε = 0\.1.*ε fixed at 0\.2",
    "gradient_of_the_min_value": r"r = 1\.5, Â = 1\.0.*should be 0",
    "ratio_from_exponentials": r"near −900.*exp\(log π − log π_old\)",
    "clip_of_the_product": r"r = 0\.9, Â = -1\.0.*np\.clip\(r Â, \(1 − ε\) Â, \(1 \+ ε\) Â\)",
    "clip_of_the_log_ratio": r"r = 1\.5, Â = 1\.0.*the log-ratio clipped to ±ε",
}


# the transfer task


def _logits_parts(logits, actions, logp_old, advantages, epsilon):
    n = len(actions)
    log_probs = logits - np.log(np.exp(logits).sum(axis=1, keepdims=True))
    ratio = np.exp(log_probs[np.arange(n), actions] - logp_old)
    unclipped = ratio * advantages
    clipped = np.clip(ratio, 1 - epsilon, 1 + epsilon) * advantages
    score = -np.exp(log_probs)
    score[np.arange(n), actions] += 1.0
    return float(np.mean(np.minimum(unclipped, clipped))), unclipped, clipped, score


def logits_cpi_gradient(logits, actions, logp_old, advantages, epsilon):
    """L^CPI's gradient r Â / n carried to the logits: nothing switched off."""
    value, unclipped, _, score = _logits_parts(logits, actions, logp_old, advantages, epsilon)
    return value, score * (unclipped / len(actions))[:, None]


def logits_onehot_only(logits, actions, logp_old, advantages, epsilon):
    """Only the chosen action's logit gets the gradient: the softmax's −π term forgotten."""
    value, unclipped, clipped, score = _logits_parts(logits, actions, logp_old, advantages, epsilon)
    grad_logp = np.where(unclipped <= clipped, unclipped, 0.0) / len(actions)
    onehot = np.zeros(logits.shape)
    onehot[np.arange(len(actions)), actions] = 1.0
    return value, onehot * grad_logp[:, None]


def logits_broadcast(logits, actions, logp_old, advantages, epsilon):
    """∂L/∂ log π copied to every logit of the row."""
    value, unclipped, clipped, _ = _logits_parts(logits, actions, logp_old, advantages, epsilon)
    grad_logp = np.where(unclipped <= clipped, unclipped, 0.0) / len(actions)
    return value, np.repeat(grad_logp[:, None], logits.shape[1], axis=1)


def logits_probability_gradient(logits, actions, logp_old, advantages, epsilon):
    """The chain taken through π instead of log π: the score times π(a|s) once more."""
    value, unclipped, clipped, score = _logits_parts(logits, actions, logp_old, advantages, epsilon)
    log_probs = logits - np.log(np.exp(logits).sum(axis=1, keepdims=True))
    grad_logp = np.where(unclipped <= clipped, unclipped, 0.0) / len(actions)
    prob = np.exp(log_probs[np.arange(len(actions)), actions])
    return value, score * (grad_logp * prob)[:, None]


VARIANTS.update(
    {
        "logits_cpi_gradient": {"clip_objective_logits_gradient": logits_cpi_gradient},
        "logits_onehot_only": {"clip_objective_logits_gradient": logits_onehot_only},
        "logits_broadcast": {"clip_objective_logits_gradient": logits_broadcast},
        "logits_probability_gradient": {"clip_objective_logits_gradient": logits_probability_gradient},
    }
)
FIRST_FAILURE.update(
    {
        "logits_cpi_gradient": r"L\^CPI's gradient carried to the logits",
        "logits_onehot_only": r"only the chosen action's logit",
        "logits_broadcast": r"broadcast to every logit",
        "logits_probability_gradient": r"π = \(½, ½\), a = 0, r = 1",
    }
)
