"""Central finite differences: the check every hand-derived gradient in minippo is held to (in float64)."""

from __future__ import annotations

import numpy as np


def central_differences(f, array: np.ndarray, step: float = 1e-6, at=None) -> np.ndarray:
    """∂f/∂array by central differences, (f(θ + Δ e_i) − f(θ − Δ e_i)) / 2Δ, one entry at a time.

    ``f`` takes no argument and reads ``array``, which is changed in place and restored entry by entry. ``at``
    picks flat indices to differentiate along (all entries by default); the result then has one entry per index.
    """
    indices = range(array.size) if at is None else at
    grad = np.zeros(array.shape if at is None else len(at), dtype=np.float64)
    flat_grad = grad.reshape(-1)
    for j, i in enumerate(indices):
        saved = array.flat[i]
        array.flat[i] = saved + step
        up = f()
        array.flat[i] = saved - step
        down = f()
        array.flat[i] = saved
        flat_grad[j] = (up - down) / (2 * step)
    return grad
