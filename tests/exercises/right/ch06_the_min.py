"""Other correct ways to write chapter 6."""

import numpy as np


def clip_objective_case_by_case(logp, logp_old, advantages, epsilon):
    """L^CLIP case by case: the clipped term is the min exactly past the band in the direction that helps."""
    ratio = np.exp(logp - logp_old)
    helped_high = (advantages > 0) & (ratio > 1.0 + epsilon)
    helped_low = (advantages < 0) & (ratio < 1.0 - epsilon)
    per_sample = np.where(helped_high, (1.0 + epsilon) * advantages, ratio * advantages)
    per_sample = np.where(helped_low, (1.0 - epsilon) * advantages, per_sample)
    flat = helped_high | helped_low
    return float(np.mean(per_sample)), np.where(flat, 0.0, ratio * advantages) / len(ratio)


def clip_objective_loop(logp, logp_old, advantages, epsilon):
    """One sample at a time, with Python's min."""
    n = len(logp)
    total, grad = 0.0, np.zeros(n)
    for t in range(n):
        r = float(np.exp(logp[t] - logp_old[t]))
        unclipped = r * advantages[t]
        clipped = min(max(r, 1.0 - epsilon), 1.0 + epsilon) * advantages[t]
        total += min(unclipped, clipped)
        grad[t] = unclipped / n if unclipped <= clipped else 0.0
    return total / n, grad


VARIANTS = {
    "clip_objective_case_by_case": {"clip_objective": clip_objective_case_by_case},
    "clip_objective_loop": {"clip_objective": clip_objective_loop},
}


def logits_gradient_by_jacobian(logits, actions, logp_old, advantages, epsilon):
    """The softmax's Jacobian written out per row, with a case-by-case switch instead of comparing the two terms."""
    n, k = logits.shape
    value, grad = 0.0, np.zeros((n, k))
    for t in range(n):
        probs = np.exp(logits[t] - logits[t].max())
        probs /= probs.sum()
        ratio = probs[actions[t]] / np.exp(logp_old[t])
        a = advantages[t]
        value += min(ratio * a, min(max(ratio, 1 - epsilon), 1 + epsilon) * a) / n
        switched_off = (a > 0 and ratio > 1 + epsilon) or (a < 0 and ratio < 1 - epsilon)
        if not switched_off:
            jacobian = np.diag(probs) - np.outer(probs, probs)  # ∂π/∂z
            grad[t] = a / np.exp(logp_old[t]) * jacobian[actions[t]] / n  # ∂(r Â)/∂z = Â ∂π(a)/∂z / π_old
    return float(value), grad


VARIANTS["logits_gradient_by_jacobian"] = {"clip_objective_logits_gradient": logits_gradient_by_jacobian}
