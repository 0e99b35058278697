"""Other correct ways to write chapter 8."""

import numpy as np

from minippo.losses import clip_objective


def clipped_value_loss_ties_to_clipped(values, value_targets, values_old, epsilon):
    """Where the two errors are equal, the clipped branch takes the tie (inside the band it is V itself)."""
    n = len(values)
    error = values - value_targets
    clipped_values = values_old + np.clip(values - values_old, -epsilon, epsilon)
    clipped_error = clipped_values - value_targets
    use_clipped = clipped_error**2 >= error**2
    inside = np.abs(values - values_old) <= epsilon
    grad = np.where(use_clipped, np.where(inside, clipped_error, 0.0), error) / n
    return 0.5 * float(np.mean(np.maximum(error**2, clipped_error**2))), grad


def clip_vf_s_objective_terms(logp, logp_old, advantages, values, value_targets, entropy, epsilon, c1, c2):
    """The three terms and their gradients written one by one."""
    n = len(logp)
    clip_value, grad_logp = clip_objective(logp, logp_old, advantages, epsilon)
    value_term = 0.5 * np.mean((values - value_targets) ** 2)
    entropy_term = np.mean(entropy)
    value = clip_value - c1 * value_term + c2 * entropy_term
    return float(value), grad_logp, -c1 * (values - value_targets) / n, c2 * np.ones(n) / n


VARIANTS = {
    "clipped_value_loss_ties_to_clipped": {"clipped_value_loss": clipped_value_loss_ties_to_clipped},
    "clip_vf_s_objective_terms": {"clip_vf_s_objective": clip_vf_s_objective_terms},
}


def huber_as_clipped_parabola(values, value_targets, delta):
    """½ m² + δ (|e| − m) with m = min(|e|, δ), one expression for both parts."""
    error = values - value_targets
    m = np.minimum(np.abs(error), delta)
    return float(np.mean(0.5 * m * m + delta * (np.abs(error) - m))), np.sign(error) * m / len(values)


VARIANTS["huber_as_clipped_parabola"] = {"huber_value_loss": huber_as_clipped_parabola}
