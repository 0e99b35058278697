"""Algorithm 1's inner loop: K epochs over one batch, each in minibatches of M (PPO, RLHF, GRPO, DPO and the book)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np


def minibatch_indices(n: int, size: int, rng: np.random.Generator | None) -> Iterator[np.ndarray]:
    """One epoch over a batch of ``n`` samples: the indices of each minibatch of ``size`` (the last one shorter when
    ``size`` does not divide ``n``), in a new random order drawn from ``rng``, or in the batch's order when ``rng`` is
    None. One ``rng.permutation(n)`` per epoch: the draw every trainer of minippo has always made."""
    order = rng.permutation(n) if rng is not None else np.arange(n)
    for start in range(0, n, size):
        yield order[start : start + size]


def minibatches(data: dict, size: int, rng: np.random.Generator | None) -> Iterator[dict]:
    """One epoch over ``data`` (arrays of one length, the batch): each minibatch as a dict of the same keys."""
    n = len(next(iter(data.values())))
    for index in minibatch_indices(n, size, rng):
        yield {key: value[index] for key, value in data.items()}
