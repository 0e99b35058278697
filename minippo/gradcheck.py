"""The references minippo's hand-written math is checked against (in float64): central finite differences for every
hand-derived gradient, and the convolution written as its formula, one output number at a time."""

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


def conv2d_by_definition(x: np.ndarray, K: np.ndarray, b: np.ndarray) -> np.ndarray:
    """y[n, i, j, f] = b[f] + Σ_{p, q, c} x[n, i + p, j + q, c] K[p, q, c, f], one output number at a time (valid,
    stride 1): what ``minippo.conv.conv2d_forward`` computes as one matrix product."""
    n, H, W, C = x.shape
    kh, kw, _, F = K.shape
    y = np.zeros((n, H - kh + 1, W - kw + 1, F))
    for s in range(n):
        for i in range(H - kh + 1):
            for j in range(W - kw + 1):
                for f in range(F):
                    total = b[f]
                    for p in range(kh):
                        for q in range(kw):
                            for c in range(C):
                                total += x[s, i + p, j + q, c] * K[p, q, c, f]
                    y[s, i, j, f] = total
    return y
