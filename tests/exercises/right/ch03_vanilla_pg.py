"""Other correct ways to write chapter 3."""

import numpy as np


def pg_objective_dot(logp, advantages):
    """The mean as a dot product over n."""
    n = logp.shape[0]
    return float(logp @ advantages) / n, advantages * (1.0 / n)


def normalize_advantages_by_hand(advantages):
    """Mean and population standard deviation written out; a batch of one copied with np.copy."""
    n = len(advantages)
    if n == 1:
        return np.copy(advantages).astype(np.float64)
    mean = advantages.sum() / n
    std = np.sqrt(((advantages - mean) ** 2).sum() / n)
    return (advantages - mean) / (std + 1e-8)


def normalize_advantages_guarding_zero_std(advantages):
    """A guard against std = 0 in place of the 1e-8: the same numbers unless the spread is below about 1e-5."""
    if len(advantages) < 2:
        return advantages.copy()
    std = advantages.std()
    return (advantages - advantages.mean()) / std if std > 0 else np.zeros(len(advantages))


VARIANTS = {
    "pg_objective_dot": {"pg_objective": pg_objective_dot},
    "normalize_advantages_by_hand": {"normalize_advantages": normalize_advantages_by_hand},
    "normalize_advantages_guarding_zero_std": {"normalize_advantages": normalize_advantages_guarding_zero_std},
}


def linear_pg_sample_by_sample(features, theta, actions, advantages):
    """One sample at a time: the outer product of the features with that sample's score, averaged."""
    n, (d, k) = len(actions), theta.shape
    grad, value = np.zeros((d, k)), 0.0
    for t in range(n):
        logits = features[t] @ theta
        probs = np.exp(logits - logits.max())
        probs /= probs.sum()
        score = -probs
        score[actions[t]] += 1.0
        grad += np.outer(features[t], score) * advantages[t] / n
        value += np.log(probs[actions[t]]) * advantages[t] / n
    return float(value), grad


VARIANTS["linear_pg_sample_by_sample"] = {"linear_softmax_policy_gradient": linear_pg_sample_by_sample}
