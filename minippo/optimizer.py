"""Adam, the global gradient-norm clip and the linear learning-rate schedule, on one flat parameter vector."""

from __future__ import annotations

import math

import numpy as np


class Adam:
    """Adam (Kingma & Ba 2015) with bias correction, updating ``params`` in place.

    m ← β1 m + (1 − β1) g,  v ← β2 v + (1 − β2) g²,
    θ ← θ − α · m̂ / (√v̂ + eps),  m̂ = m / (1 − β1ᵗ),  v̂ = v / (1 − β2ᵗ).
    The paper's MuJoCo step size is α = 3e-4; the "37 details" use eps = 1e-5 (PyTorch's default is 1e-8).
    """

    def __init__(
        self, params: np.ndarray, lr: float = 3e-4, betas=(0.9, 0.999), eps: float = 1e-5, bias_correction: bool = True
    ):
        self.params = params
        self.lr = lr
        self.beta1, self.beta2 = betas
        self.eps = eps
        self.bias_correction = bias_correction
        self.m = np.zeros_like(params)
        self.v = np.zeros_like(params)
        self.t = 0
        self._scratch = np.empty_like(params)

    def step(self, grads: np.ndarray) -> None:
        """One descent step along ``grads`` (the gradient of the loss to minimise)."""
        self.t += 1
        scratch = self._scratch  # one buffer for the intermediate results, in the params' dtype
        self.m *= self.beta1
        self.m += np.multiply(grads, 1.0 - self.beta1, out=scratch)
        self.v *= self.beta2
        np.multiply(grads, grads, out=scratch)
        scratch *= 1.0 - self.beta2
        self.v += scratch
        if self.bias_correction:
            step = self.lr * math.sqrt(1.0 - self.beta2**self.t) / (1.0 - self.beta1**self.t)
            eps = self.eps * math.sqrt(1.0 - self.beta2**self.t)
        else:
            step, eps = self.lr, self.eps
        # θ −= α m̂ / (√v̂ + eps), with the corrections folded into the step and eps (same algebra, fewer passes)
        denom = np.sqrt(self.v, out=scratch)
        denom += eps
        np.divide(self.m, denom, out=scratch)
        scratch *= step
        self.params -= scratch

    def state_dict(self) -> dict:
        return {"m": self.m.copy(), "v": self.v.copy(), "t": np.array(self.t)}

    def load_state_dict(self, state: dict) -> None:
        self.m[...] = state["m"]
        self.v[...] = state["v"]
        self.t = int(state["t"])


def clip_grad_norm(grads: np.ndarray, max_norm: float) -> float:
    """Scale ``grads`` in place so that its global L2 norm is at most ``max_norm``; return the norm before."""
    norm = float(np.sqrt(np.dot(grads, grads)))
    if norm > max_norm:
        grads *= max_norm / (norm + 1e-6)
    return norm


def linear_schedule(initial: float, update: int, num_updates: int) -> float:
    """The step size for ``update`` (1-based) when it falls linearly from ``initial`` to 0 over ``num_updates``."""
    return initial * (1.0 - (update - 1.0) / num_updates)
