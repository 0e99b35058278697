"""Other correct ways to write chapter 13's exercises."""

import numpy as np


def plackett_luce_by_suffix_sums(scores):
    """The normalisers of every choice at once, from cumulative log-sum-exps taken from the last column backwards."""
    n, K = scores.shape
    suffix = np.logaddexp.accumulate(scores[:, ::-1], axis=1)[:, ::-1]  # log Σ_{j ≥ i} e^{s_j}
    loss = float(np.sum(suffix[:, : K - 1] - scores[:, : K - 1])) / n
    grad = np.zeros(scores.shape)
    for i in range(K - 1):
        grad[:, i:] += np.exp(scores[:, i:] - suffix[:, i : i + 1])
    grad[:, : K - 1] -= 1.0
    return loss, grad / n


VARIANTS = {"plackett_luce_by_suffix_sums": {"plackett_luce_loss": plackett_luce_by_suffix_sums}}
