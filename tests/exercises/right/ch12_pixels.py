"""Other correct ways to write chapter 12: one output pixel at a time, im2col (minippo's way), and sliding windows with
np.einsum, whose input gradient is the full convolution of ∂L/∂y with the kernel flipped."""

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view


def forward_pixel_by_pixel(x, K, b):
    """Each output pixel is its receptive field, (n, kh, kw, C), contracted with K over (kh, kw, C)."""
    kh, kw, _, F = K.shape
    n, H, W, _ = x.shape
    y = np.empty((n, H - kh + 1, W - kw + 1, F))
    for i in range(H - kh + 1):
        for j in range(W - kw + 1):
            y[:, i, j, :] = np.tensordot(x[:, i : i + kh, j : j + kw, :], K, axes=3) + b
    return y


def backward_pixel_by_pixel(x, K, grad_y, need_grad_x=True):
    """Each output pixel sends its gradient back to its own receptive field, which adds it to what it has."""
    kh, kw, _, _ = K.shape
    _, out_h, out_w, _ = grad_y.shape
    grad_x = np.zeros(x.shape)
    grad_K = np.zeros(K.shape)
    for i in range(out_h):
        for j in range(out_w):
            field = x[:, i : i + kh, j : j + kw, :]
            grad_K += np.tensordot(field, grad_y[:, i, j, :], axes=([0], [0]))
            grad_x[:, i : i + kh, j : j + kw, :] += np.tensordot(grad_y[:, i, j, :], K, axes=([1], [3]))
    grad_b = np.zeros(K.shape[-1])
    for row in grad_y.reshape(-1, K.shape[-1]):
        grad_b += row
    return (grad_x if need_grad_x else None), grad_K, grad_b


def _columns(x, kh, kw):
    """(n, H, W, C) → (n·out_h·out_w, kh·kw·C): one row per output pixel, its receptive field in (p, q, c) order."""
    n, H, W, C = x.shape
    out_h, out_w = H - kh + 1, W - kw + 1
    columns = np.empty((n, out_h, out_w, kh, kw, C))
    for p in range(kh):
        for q in range(kw):
            columns[:, :, :, p, q, :] = x[:, p : p + out_h, q : q + out_w, :]
    return columns.reshape(n * out_h * out_w, kh * kw * C)


def forward_im2col(x, K, b):
    """Every receptive field a row, the kernel a (kh·kw·C, F) matrix: one matrix product."""
    kh, kw, C, F = K.shape
    n, H, W, _ = x.shape
    return (_columns(x, kh, kw) @ K.reshape(-1, F) + b).reshape(n, H - kh + 1, W - kw + 1, F)


def backward_im2col(x, K, grad_y, need_grad_x=True):
    """As for a linear layer on the rows, then col2im: each row's gradient added back to the pixels it came from."""
    kh, kw, C, F = K.shape
    n, out_h, out_w, _ = grad_y.shape
    rows = grad_y.reshape(-1, F)
    grad_K = (_columns(x, kh, kw).T @ rows).reshape(K.shape)
    grad_b = rows.sum(axis=0)
    if not need_grad_x:
        return None, grad_K, grad_b
    grad_columns = (rows @ K.reshape(-1, F).T).reshape(n, out_h, out_w, kh, kw, C)
    grad_x = np.zeros(x.shape)
    for p in range(kh):
        for q in range(kw):
            grad_x[:, p : p + out_h, q : q + out_w, :] += grad_columns[:, :, :, p, q, :]
    return grad_x, grad_K, grad_b


def forward_einsum(x, K, b):
    """The windows of x as a (n, out_h, out_w, C, kh, kw) view, contracted with K by np.einsum."""
    kh, kw = K.shape[:2]
    windows = sliding_window_view(x, (kh, kw), axis=(1, 2))
    return np.einsum("nijcpq,pqcf->nijf", windows, K) + b


def backward_einsum(x, K, grad_y, need_grad_x=True):
    """∂L/∂x is a full convolution: ∂L/∂y padded by kh − 1 and kw − 1 on every side, cross-correlated with K flipped
    in both spatial axes and its channel axes exchanged."""
    kh, kw = K.shape[:2]
    grad_K = np.einsum("nijcpq,nijf->pqcf", sliding_window_view(x, (kh, kw), axis=(1, 2)), grad_y)
    grad_b = np.einsum("nijf->f", grad_y)
    if not need_grad_x:
        return None, grad_K, grad_b
    padded = np.pad(grad_y, ((0, 0), (kh - 1, kh - 1), (kw - 1, kw - 1), (0, 0)))
    flipped = K[::-1, ::-1]
    grad_x = np.einsum("naefpq,pqcf->naec", sliding_window_view(padded, (kh, kw), axis=(1, 2)), flipped)
    return grad_x, grad_K, grad_b


VARIANTS = {
    "pixel_by_pixel": {"conv2d_forward": forward_pixel_by_pixel, "conv2d_backward": backward_pixel_by_pixel},
    "im2col": {"conv2d_forward": forward_im2col, "conv2d_backward": backward_im2col},
    "einsum_full_convolution": {"conv2d_forward": forward_einsum, "conv2d_backward": backward_einsum},
}


def max_pool_backward_by_loops(x, size, grad_y):
    """Window by window with np.unravel_index, no reshapes."""
    n, H, W, C = x.shape
    grad_x = np.zeros(x.shape)
    for b in range(n):
        for i in range(H // size):
            for j in range(W // size):
                for c in range(C):
                    window = x[b, size * i : size * (i + 1), size * j : size * (j + 1), c]
                    p, q = np.unravel_index(np.argmax(window), window.shape)
                    grad_x[b, size * i + p, size * j + q, c] = grad_y[b, i, j, c]
    return grad_x


VARIANTS["max_pool_backward_by_loops"] = {"max_pool2d_backward": max_pool_backward_by_loops}
