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


VARIANTS = {
    "pg_objective_dot": {"pg_objective": pg_objective_dot},
    "normalize_advantages_by_hand": {"normalize_advantages": normalize_advantages_by_hand},
}
