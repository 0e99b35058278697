"""Chapter 1: a multilayer perceptron by hand, its backward pass, and Adam.

A network is a list of layers ``[(W_1, b_1), ..., (W_L, b_L)]``, W_i of shape (in_i, out_i) and b_i of shape (out_i,).
Every layer but the last is followed by tanh; the last layer is linear (it outputs logits, a mean or a value).
Batches are rows: an input x has shape (n, in_1). Every array is float64.

Every array returned is a new float64 array, never an argument itself or a view of one (except mlp_forward's cache,
whose h_0 is x).

Grade: ``minippo grade 1``
"""

from __future__ import annotations

import numpy as np

EXERCISES = ["linear_backward", "tanh_backward", "mlp_forward", "mlp_backward", "adam_step"]


def linear_backward(x: np.ndarray, W: np.ndarray, grad_y: np.ndarray):
    """The backward pass of one linear layer y = x W + b.

    x: (n, in), the layer's input.  W: (in, out).  grad_y: (n, out), ∂L/∂y for some scalar L.
    Returns (grad_x, grad_W, grad_b):
        ∂L/∂x = ∂L/∂y Wᵀ           shape (n, in)
        ∂L/∂W = xᵀ ∂L/∂y           shape (in, out)
        ∂L/∂b = Σ_rows ∂L/∂y       shape (out,)   (b is added to every row, so its gradient sums over the batch)
    New float64 arrays; the inputs are left unchanged.
    """
    grad_x = grad_y @ W.T
    grad_W = x.T @ grad_y
    grad_b = grad_y.sum(axis=0)
    return grad_x, grad_W, grad_b


def tanh_backward(h: np.ndarray, grad_h: np.ndarray) -> np.ndarray:
    """The backward pass of h = tanh(z), written with the output h (so z need not be kept).

    h: any shape, the tanh outputs.  grad_h: same shape, ∂L/∂h.
    Returns ∂L/∂z = ∂L/∂h · (1 − h²), same shape, since d tanh(z)/dz = 1 − tanh(z)².
    """
    return grad_h * (1.0 - h * h)


def mlp_forward(layers, x: np.ndarray):
    """The forward pass: h_0 = x, z_i = h_{i−1} W_i + b_i, h_i = tanh(z_i) for i < L, and the output is z_L.

    layers: a list of (W, b).  x: (n, in_1).
    Returns (out, cache): out of shape (n, out_L), and cache = [h_0, h_1, ..., h_{L−1}], the list of the input of
    every layer (L arrays; h_0 is x itself), which is what mlp_backward needs.
    """
    cache = []
    h = x
    for i, (W, b) in enumerate(layers):
        cache.append(h)
        z = h @ W + b
        h = np.tanh(z) if i < len(layers) - 1 else z
    return h, cache


def mlp_backward(layers, cache, grad_out: np.ndarray):
    """The backward pass of mlp_forward, by the chain rule from the last layer to the first.

    layers: the list of (W, b).  cache: [h_0, ..., h_{L−1}] as mlp_forward returns it.  grad_out: (n, out_L), ∂L/∂out.
    Returns (grads, grad_x): grads is a list [(∂L/∂W_1, ∂L/∂b_1), ..., (∂L/∂W_L, ∂L/∂b_L)] in the order of ``layers``
    with the shapes of W_i and b_i, and grad_x = ∂L/∂x of shape (n, in_1).
    Layer i's input is h_{i−1} = cache[i−1]; to carry ∂L/∂h_{i−1} back through the tanh that made it, multiply by
    1 − h_{i−1}² (for i ≥ 2 only: h_0 = x went through no tanh).
    """
    grads = [None] * len(layers)
    grad = grad_out
    for i in range(len(layers) - 1, -1, -1):
        W, _ = layers[i]
        grad_x, grad_W, grad_b = linear_backward(cache[i], W, grad)
        grads[i] = (grad_W, grad_b)
        # the input of layer i came out of the previous layer's tanh (the network's input has none)
        grad = tanh_backward(cache[i], grad_x) if i > 0 else grad_x
    return grads, grad


def adam_step(
    params: np.ndarray,
    grads: np.ndarray,
    m: np.ndarray,
    v: np.ndarray,
    t: int,
    lr: float = 3e-4,
    beta1: float = 0.9,
    beta2: float = 0.999,
    eps: float = 1e-8,
):
    """One step of Adam (Kingma & Ba 2015) that descends the loss whose gradient is ``grads``.

    params, grads, m, v: arrays of one shape; m and v are the running first and second moments (zeros before the
    first step).  t: the number of this step, 1 for the first.
        m ← β1 m + (1 − β1) g
        v ← β2 v + (1 − β2) g²
        m̂ = m / (1 − β1ᵗ),  v̂ = v / (1 − β2ᵗ)          (bias correction: m and v start at 0)
        θ ← θ − lr · m̂ / (√v̂ + eps)
    Returns (new_params, new_m, new_v) as new arrays; params, m and v themselves are left unchanged.
    """
    new_m = beta1 * m + (1.0 - beta1) * grads
    new_v = beta2 * v + (1.0 - beta2) * grads * grads
    m_hat = new_m / (1.0 - beta1**t)
    v_hat = new_v / (1.0 - beta2**t)
    new_params = params - lr * m_hat / (np.sqrt(v_hat) + eps)
    return new_params, new_m, new_v
