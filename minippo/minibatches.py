"""Algorithm 1's inner loop: K epochs over one batch, each in minibatches of M (PPO, RLHF, GRPO, DPO, pretraining
and the book)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np


def epochs_of(batch: dict | int, k: int, size: int, rng: np.random.Generator | None) -> Iterator[Iterator]:
    """``k`` epochs over one batch, each an iterator over its minibatches of ``size``: for epoch in epochs_of(…):
    for minibatch in epoch: one step. ``batch`` is a dict of arrays of one length (each minibatch is then a dict of
    the same keys) or the number n of samples (each minibatch is then the indices of its samples)."""
    for _ in range(k):
        yield minibatches(batch, size, rng)


def minibatches(batch: dict | int, size: int, rng: np.random.Generator | None) -> Iterator:
    """One epoch: the minibatches of ``size`` (the last one shorter when ``size`` does not divide the batch), in a new
    random order drawn from ``rng``, or in the batch's order when ``rng`` is None. One ``rng.permutation(n)`` per
    epoch, drawn when its first minibatch is taken (an epoch that is never started draws nothing): the draw every
    trainer of minippo has always made."""
    n = len(next(iter(batch.values()))) if isinstance(batch, dict) else int(batch)
    order = rng.permutation(n) if rng is not None else np.arange(n)
    for start in range(0, n, size):
        index = order[start : start + size]
        yield {key: value[index] for key, value in batch.items()} if isinstance(batch, dict) else index
