"""Chapter 12: pixels. The 2-D convolution under the network that plays MinAtar from its images, forward and
backward, by hand.

Images are NHWC arrays, (n, H, W, C), channels last, as MinAtar gives them; a kernel K is (kh, kw, C, F), F the
number of filters (output channels); a bias b is (F,). The convolution is deep learning's: a cross-correlation, the
kernel not flipped, with stride 1 and no padding ("valid"), so the output is (n, H − kh + 1, W − kw + 1, F): the book's
(12.1), with a bias per filter.

Grade: ``minippo grade 12``
"""

from __future__ import annotations

import numpy as np

EXERCISES = ["conv2d_forward", "conv2d_backward"]
TRANSFER = ["max_pool2d_backward"]  # the chapter's idea applied to a case the book has not shown


def conv2d_forward(x: np.ndarray, K: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The valid cross-correlation of a batch of images with F kernels, plus a bias per kernel: the book's (12.1).

    x: (n, H, W, C) images, channels last.  K: (kh, kw, C, F); kh ≤ H and kw ≤ W, not necessarily square.  b: (F,).
    Returns y, (n, H − kh + 1, W − kw + 1, F) float64, a new array.
    """
    kh, kw, _, F = K.shape
    n, H, W, _ = x.shape
    out_h, out_w = H - kh + 1, W - kw + 1
    y = np.zeros((n, out_h, out_w, F)) + b
    for p in range(kh):
        for q in range(kw):
            # every output pixel's input shifted by (p, q), times the kernel's slice there: a (C, F) matrix
            y += x[:, p : p + out_h, q : q + out_w, :] @ K[p, q]
    return y


def conv2d_backward(x: np.ndarray, K: np.ndarray, grad_y: np.ndarray, need_grad_x: bool = True):
    """Given grad_y = ∂L/∂y for y = conv2d_forward(x, K, b), return (∂L/∂x, ∂L/∂K, ∂L/∂b): the book's (12.2) and (12.3).

    x: (n, H, W, C).  K: (kh, kw, C, F).  grad_y: (n, H − kh + 1, W − kw + 1, F).  Returns grad_x (n, H, W, C), or
    None when need_grad_x is False (the first layer's input needs no gradient); grad_K (kh, kw, C, F); grad_b (F,);
    all float64 and new arrays.
    """
    kh, kw, C, F = K.shape
    _, out_h, out_w, _ = grad_y.shape
    grad_K = np.zeros((kh, kw, C, F))
    grad_x = np.zeros(x.shape) if need_grad_x else None
    for p in range(kh):
        for q in range(kw):
            shifted = x[:, p : p + out_h, q : q + out_w, :]
            grad_K[p, q] = np.einsum("nijc,nijf->cf", shifted, grad_y)
            if need_grad_x:
                grad_x[:, p : p + out_h, q : q + out_w, :] += grad_y @ K[p, q].T  # overlapping fields add up
    return grad_x, grad_K, grad_y.sum(axis=(0, 1, 2))


def max_pool2d_backward(x: np.ndarray, size: int, grad_y: np.ndarray) -> np.ndarray:
    """Transfer task: the backward pass of max pooling, a layer this chapter's network does not have.

    Forward (given): each channel of each image is cut into non-overlapping size × size windows (H and W multiples of
    size), and y[n, i, j, c] = max over the window's pixels x[n, size·i + p, size·j + q, c], 0 ≤ p, q < size.
    x: (n, H, W, C).  size: the window's side.  grad_y: (n, H / size, W / size, C), ∂L/∂y.
    Returns ∂L/∂x, (n, H, W, C), a new float64 array. Where a window's maximum is reached by several pixels, the
    gradient goes to the first of them in row-major order (smallest p, then smallest q), as np.argmax picks it.
    """
    n, H, W, C = x.shape
    h, w = H // size, W // size
    windows = x.reshape(n, h, size, w, size, C).transpose(0, 1, 3, 5, 2, 4).reshape(n, h, w, C, size * size)
    first = windows.argmax(axis=-1)
    mask = np.zeros(windows.shape)
    np.put_along_axis(mask, first[..., None], 1.0, axis=-1)
    grad_windows = mask * grad_y[..., None]
    return grad_windows.reshape(n, h, w, C, size, size).transpose(0, 1, 4, 2, 5, 3).reshape(n, H, W, C)
