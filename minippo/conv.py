"""A convolutional network written by hand: 2-D convolution, ReLU and flatten, forward and backward side by side.

Images are NHWC arrays, (n, height, width, channels), as MinAtar gives them; a kernel K is (kh, kw, C, F). The
convolution is what deep learning means by the word, a cross-correlation with stride 1 and no padding ("valid"):

    y[n, i, j, f] = b[f] + Σ_{p, q, c} x[n, i + p, j + q, c] K[p, q, c, f],   i < H − kh + 1,  j < W − kw + 1.

It is computed as one matrix product: ``patches`` lays the kh·kw shifted copies of x side by side (im2col), so that
each output pixel's receptive field becomes one row, and the kernel becomes a (kh·kw·C, F) matrix.
"""

from __future__ import annotations

import numpy as np

from minippo.network import flat_views, linear_backward, linear_forward, orthogonal


def patches(x: np.ndarray, kh: int, kw: int) -> np.ndarray:
    """(n, H, W, C) → (n, H−kh+1, W−kw+1, kh·kw·C): the receptive field of every output pixel, in (p, q, c) order."""
    _, H, W, _ = x.shape
    out_h, out_w = H - kh + 1, W - kw + 1
    return np.concatenate([x[:, p : p + out_h, q : q + out_w, :] for p in range(kh) for q in range(kw)], axis=-1)


def conv2d_forward(x: np.ndarray, K: np.ndarray, b: np.ndarray) -> np.ndarray:
    """y = x ⋆ K + b for a batch x of shape (n, H, W, C) and K of shape (kh, kw, C, F): (n, H−kh+1, W−kw+1, F)."""
    kh, kw, C, F = K.shape
    cols = patches(x, kh, kw)
    rows = cols.reshape(-1, kh * kw * C)  # a 2-D product: NumPy hands only those to BLAS
    return (rows.dot(K.reshape(kh * kw * C, F)) + b).reshape(*cols.shape[:3], F)


def conv2d_backward(x: np.ndarray, K: np.ndarray, grad_y: np.ndarray, need_grad_x: bool = True):
    """Given dL/dy, return (dL/dx, dL/dK, dL/db).

    dL/dK[p, q, c, f] = Σ_{n, i, j} x[n, i + p, j + q, c] dL/dy[n, i, j, f]   (patchesᵀ dL/dy, as for a linear layer)
    dL/db[f] = Σ_{n, i, j} dL/dy[n, i, j, f]
    dL/dx[n, a, b, c] = Σ_{p, q, f} dL/dy[n, a − p, b − q, f] K[p, q, c, f] over the (a − p, b − q) inside y: every
    input pixel collects from each output pixel whose receptive field holds it, so overlapping fields add up.
    """
    kh, kw, C, F = K.shape
    n, out_h, out_w, _ = grad_y.shape
    rows = grad_y.reshape(n * out_h * out_w, F)
    grad_patches, grad_K, grad_b = linear_backward(
        patches(x, kh, kw).reshape(-1, kh * kw * C), K.reshape(kh * kw * C, F), rows, need_grad_x
    )
    if not need_grad_x:
        return None, grad_K.reshape(K.shape), grad_b
    grad_patches = grad_patches.reshape(n, out_h, out_w, kh * kw, C)
    grad_x = np.zeros_like(x, dtype=grad_patches.dtype)
    for k, (p, q) in enumerate((p, q) for p in range(kh) for q in range(kw)):
        grad_x[:, p : p + out_h, q : q + out_w, :] += grad_patches[:, :, :, k, :]  # col2im: the shifts, added back
    return grad_x, grad_K.reshape(K.shape), grad_b


def relu_forward(z: np.ndarray) -> np.ndarray:
    """h = max(z, 0), elementwise."""
    return np.maximum(z, 0.0)


def relu_backward(h: np.ndarray, grad_h: np.ndarray) -> np.ndarray:
    """dL/dz = dL/dh · 1[z > 0], read off the output h = max(z, 0) (h > 0 exactly where z > 0)."""
    return grad_h * (h > 0)


def flatten_forward(x: np.ndarray) -> np.ndarray:
    """(n, ...) → (n, everything else), row-major."""
    return x.reshape(len(x), -1)


def flatten_backward(shape: tuple, grad_y: np.ndarray) -> np.ndarray:
    """A reshape moves no number, so its gradient is the same numbers in the input's shape."""
    return grad_y.reshape(shape)


class ConvTrunk:
    """conv(F, kh×kw) → ReLU → flatten → dense → ReLU: the shared trunk used for MinAtar (Young & Tian 2019).

    It reads flat observations of ``image_shape`` = (H, W, C) in row-major order and returns ``hidden`` features per
    sample. The parameters are views into one flat vector, like ``MLP``'s, and the interface is ``MLP``'s, so the
    actor-critic can put either under its two heads.
    """

    def __init__(
        self,
        image_shape: tuple[int, int, int],
        channels: int = 16,
        kernel: int = 3,
        hidden: int = 128,
        params: np.ndarray | None = None,
        grads: np.ndarray | None = None,
    ):
        self.image_shape = tuple(int(s) for s in image_shape)
        H, W, C = self.image_shape
        if H < kernel or W < kernel:
            raise ValueError(f"a {kernel}×{kernel} kernel does not fit a {H}×{W} image")
        self.kernel_shape = (kernel, kernel, C, channels)
        self.dense_shape = ((H - kernel + 1) * (W - kernel + 1) * channels, hidden)
        shapes = [self.kernel_shape, (channels,), self.dense_shape, (hidden,)]
        self.n_params = sum(int(np.prod(s)) for s in shapes)
        self.params = np.zeros(self.n_params) if params is None else params
        self.grads = np.zeros(self.n_params) if grads is None else grads
        if self.params.shape != (self.n_params,) or self.grads.shape != (self.n_params,):
            raise ValueError(f"ConvTrunk{self.image_shape} needs flat buffers of {self.n_params} parameters")
        views, grad_views = flat_views(self.params, self.grads, shapes)
        self.K, self.conv_b, self.W, self.b = views
        self.grad_K, self.grad_conv_b, self.grad_W, self.grad_b = grad_views

    def init(self, rng: np.random.Generator, out_gain: float, hidden_gain: float, orthogonal_init: bool = True):
        """Orthogonal weights (the kernel as a (kh·kw·C, F) matrix) with gain ``out_gain``, zero biases; or
        LeCun-uniform. Both layers are followed by a ReLU, so both take the trunk's gain, ``out_gain``;
        ``hidden_gain`` is not used (it is there so that ``ActorCritic`` calls every trunk as it calls ``MLP.init``)."""
        for weights in (self.K, self.W):
            matrix = weights.reshape(-1, weights.shape[-1])
            if orthogonal_init:
                matrix[...] = orthogonal(matrix.shape, out_gain, rng)
            else:
                bound = 1.0 / np.sqrt(matrix.shape[0])
                matrix[...] = rng.uniform(-bound, bound, matrix.shape)
        self.conv_b[...] = 0.0
        self.b[...] = 0.0

    def forward(self, x: np.ndarray):
        """Return the features (n, hidden) and the cache the backward pass needs."""
        images = x.reshape(len(x), *self.image_shape)
        feature_maps = relu_forward(conv2d_forward(images, self.K, self.conv_b))
        flat = flatten_forward(feature_maps)
        features = relu_forward(linear_forward(flat, self.W, self.b))
        return features, (images, feature_maps, flat, features)

    def backward(self, cache, grad_out: np.ndarray, need_grad_input: bool = False):
        """Write dL/dθ into ``self.grads`` (overwriting it) and return dL/dx, flat like x (or None)."""
        images, feature_maps, flat, features = cache
        grad = relu_backward(features, grad_out)
        grad_flat, self.grad_W[...], self.grad_b[...] = linear_backward(flat, self.W, grad)
        grad = relu_backward(feature_maps, flatten_backward(feature_maps.shape, grad_flat))
        grad_images, self.grad_K[...], self.grad_conv_b[...] = conv2d_backward(images, self.K, grad, need_grad_input)
        return None if grad_images is None else grad_images.reshape(len(images), -1)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return self.forward(x)[0]
