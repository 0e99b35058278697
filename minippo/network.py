"""A multilayer perceptron written by hand: linear and tanh layers, forward and backward side by side.

The parameters of a network live in one flat vector; each layer's weight ``W`` and bias ``b`` are views
into it, and the gradients live in a second flat vector of the same shape. One flat vector lets Adam and the
global gradient-norm clip work on all parameters at once, in a handful of NumPy calls.
"""

from __future__ import annotations

import numpy as np


def orthogonal(shape: tuple[int, int], gain: float, rng: np.random.Generator) -> np.ndarray:
    """An (in, out) matrix with orthonormal rows or columns, scaled by ``gain`` (Saxe et al. 2014).

    The QR factor of a Gaussian matrix is orthogonal; fixing the signs by diag(R) makes it uniformly distributed.
    """
    rows, cols = shape
    a = rng.standard_normal((max(rows, cols), min(rows, cols)))
    q, r = np.linalg.qr(a)
    q *= np.sign(np.diag(r))
    if rows < cols:
        q = q.T
    return gain * q[:rows, :cols]


# Each operation's forward and backward, side by side.


def linear_forward(x: np.ndarray, W: np.ndarray, b: np.ndarray) -> np.ndarray:
    """y = x W + b, for a batch x of shape (n, in): one row per sample."""
    return x.dot(W) + b


def linear_backward(x: np.ndarray, W: np.ndarray, grad_y: np.ndarray, need_grad_x: bool = True):
    """Given dL/dy, return (dL/dx, dL/dW, dL/db): dL/dW = xᵀ dL/dy, dL/db = Σ_n dL/dy, dL/dx = dL/dy Wᵀ."""
    grad_W = x.T.dot(grad_y)
    grad_b = grad_y.sum(axis=0)
    grad_x = grad_y.dot(W.T) if need_grad_x else None
    return grad_x, grad_W, grad_b


def tanh_forward(z: np.ndarray) -> np.ndarray:
    """h = tanh(z), elementwise."""
    return np.tanh(z)


def tanh_backward(h: np.ndarray, grad_h: np.ndarray) -> np.ndarray:
    """dL/dz = dL/dh · (1 − h²), written with the output h = tanh(z) so z need not be kept."""
    return grad_h * (1.0 - h * h)


def flat_views(params: np.ndarray, grads: np.ndarray, shapes) -> tuple[list, list]:
    """Views of one flat parameter vector and of its gradient, shaped as ``shapes`` in turn: the layers' weights
    live in one array, so that Adam and the gradient checks see one vector."""
    views, grad_views, offset = [], [], 0
    for shape in shapes:
        size = int(np.prod(shape))
        views.append(params[offset : offset + size].reshape(shape))
        grad_views.append(grads[offset : offset + size].reshape(shape))
        offset += size
    return views, grad_views


class MLP:
    """Linear layers with tanh between them (and optionally after the last one).

    ``sizes`` = (in, hidden..., out). Initialisation follows the "37 details": orthogonal weights with gain √2 on the
    hidden layers and ``out_gain`` on the last (0.01 for a policy head, 1 for a value head), zero biases.
    """

    def __init__(
        self,
        sizes: tuple[int, ...],
        out_gain: float = 1.0,
        activate_output: bool = False,
        rng: np.random.Generator | None = None,
        params: np.ndarray | None = None,
        grads: np.ndarray | None = None,
        hidden_gain: float = np.sqrt(2.0),
        orthogonal_init: bool = True,
    ):
        self.sizes = tuple(int(s) for s in sizes)
        self.activate_output = activate_output
        shapes = [(self.sizes[i], self.sizes[i + 1]) for i in range(len(self.sizes) - 1)]
        self.n_params = sum(i * o + o for i, o in shapes)
        self.params = np.zeros(self.n_params) if params is None else params
        self.grads = np.zeros(self.n_params) if grads is None else grads
        if self.params.shape != (self.n_params,) or self.grads.shape != (self.n_params,):
            raise ValueError(f"MLP{self.sizes} needs flat buffers of {self.n_params} parameters")
        views, grad_views = flat_views(self.params, self.grads, [s for i, o in shapes for s in ((i, o), (o,))])
        self.W, self.b, self.grad_W, self.grad_b = views[0::2], views[1::2], grad_views[0::2], grad_views[1::2]
        if rng is not None:
            self.init(rng, out_gain, hidden_gain, orthogonal_init)

    def init(self, rng: np.random.Generator, out_gain: float, hidden_gain: float, orthogonal_init: bool = True):
        last = len(self.W) - 1
        for i, W in enumerate(self.W):
            gain = out_gain if i == last else hidden_gain
            if orthogonal_init:
                W[...] = orthogonal(W.shape, gain, rng)
            else:  # LeCun-uniform, roughly what a framework does by default
                bound = 1.0 / np.sqrt(W.shape[0])
                W[...] = rng.uniform(-bound, bound, W.shape)
            self.b[i][...] = 0.0

    def forward(self, x: np.ndarray):
        """Return the output and the cache the backward pass needs (the input of every layer, and the output)."""
        cache = [x]
        last = len(self.W) - 1
        for i, (W, b) in enumerate(zip(self.W, self.b)):
            x = linear_forward(x, W, b)
            if i < last or self.activate_output:
                x = tanh_forward(x)
            cache.append(x)
        return x, cache

    def backward(self, cache, grad_out: np.ndarray, need_grad_input: bool = False):
        """Write dL/dθ into ``self.grads`` (overwriting it) and return dL/dx (or None)."""
        grad = grad_out
        last = len(self.W) - 1
        for i in range(last, -1, -1):
            if i < last or self.activate_output:
                grad = tanh_backward(cache[i + 1], grad)
            grad, grad_W, grad_b = linear_backward(cache[i], self.W[i], grad, need_grad_x=i > 0 or need_grad_input)
            self.grad_W[i][...] = grad_W
            self.grad_b[i][...] = grad_b
        return grad

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return self.forward(x)[0]
