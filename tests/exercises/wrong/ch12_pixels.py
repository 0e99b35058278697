"""Plausible mistakes in chapter 12: the 2-D convolution, forward and backward."""

import numpy as np


def forward_flipped_kernel(x, K, b):
    """A true convolution, as signal processing defines it: the kernel flipped in both spatial axes."""
    kh, kw, _, F = K.shape
    n, H, W, _ = x.shape
    out_h, out_w = H - kh + 1, W - kw + 1
    y = np.zeros((n, out_h, out_w, F)) + b
    for p in range(kh):
        for q in range(kw):
            y += x[:, p : p + out_h, q : q + out_w, :] @ K[kh - 1 - p, kw - 1 - q]
    return y


def forward_channel_axes_swapped(x, K, b):
    """K read as (kh, kw, F, C), PyTorch's (out, in) order of the channel axes: K[p, q] transposed."""
    kh, kw, _, F = K.shape
    n, H, W, _ = x.shape
    out_h, out_w = H - kh + 1, W - kw + 1
    y = np.zeros((n, out_h, out_w, F)) + b
    for p in range(kh):
        for q in range(kw):
            y += x[:, p : p + out_h, q : q + out_w, :] @ K[p, q].T
    return y


def forward_output_one_too_small(x, K, b):
    """H − kh output rows where there are H − kh + 1 positions for the kernel (the +1 forgotten)."""
    kh, kw, _, F = K.shape
    n, H, W, _ = x.shape
    out_h, out_w = H - kh, W - kw
    y = np.zeros((n, out_h, out_w, F)) + b
    for p in range(kh):
        for q in range(kw):
            y += x[:, p : p + out_h, q : q + out_w, :] @ K[p, q]
    return y


def forward_output_the_size_of_the_image(x, K, b):
    """An output as large as the image ("same"), its last kh − 1 rows and kw − 1 columns the bias alone."""
    kh, kw, _, F = K.shape
    n, H, W, _ = x.shape
    out_h, out_w = H - kh + 1, W - kw + 1
    y = np.zeros((n, H, W, F)) + b
    for p in range(kh):
        for q in range(kw):
            y[:, :out_h, :out_w, :] += x[:, p : p + out_h, q : q + out_w, :] @ K[p, q]
    return y


def forward_nchw_output(x, K, b):
    """The right numbers returned in PyTorch's (n, F, height, width) order."""
    kh, kw, _, F = K.shape
    n, H, W, _ = x.shape
    out_h, out_w = H - kh + 1, W - kw + 1
    y = np.zeros((n, out_h, out_w, F)) + b
    for p in range(kh):
        for q in range(kw):
            y += x[:, p : p + out_h, q : q + out_w, :] @ K[p, q]
    return y.transpose(0, 3, 1, 2).copy()


def forward_without_bias(x, K, b):
    """The bias forgotten."""
    kh, kw, _, F = K.shape
    n, H, W, _ = x.shape
    out_h, out_w = H - kh + 1, W - kw + 1
    y = np.zeros((n, out_h, out_w, F))
    for p in range(kh):
        for q in range(kw):
            y += x[:, p : p + out_h, q : q + out_w, :] @ K[p, q]
    return y


def _backward(x, K, grad_y, need_grad_x=True, grad_x_step=None, grad_K_of=None, grad_b_of=None):
    """The right backward pass with one piece replaced (each a function of the pieces it needs)."""
    kh, kw, C, F = K.shape
    _, out_h, out_w, _ = grad_y.shape
    grad_K = np.zeros((kh, kw, C, F))
    grad_x = np.zeros(x.shape) if need_grad_x else None
    for p in range(kh):
        for q in range(kw):
            grad_K[p, q] = np.einsum("nijc,nijf->cf", x[:, p : p + out_h, q : q + out_w, :], grad_y)
            if need_grad_x:
                window = (slice(None), slice(p, p + out_h), slice(q, q + out_w), slice(None))
                if grad_x_step is None:
                    grad_x[window] += grad_y @ K[p, q].T
                else:
                    grad_x_step(grad_x, window, grad_y, K, p, q)
    if grad_K_of is not None:
        grad_K = grad_K_of(x, K, grad_y)
    grad_b = grad_y.sum(axis=(0, 1, 2)) if grad_b_of is None else grad_b_of(grad_y)
    return grad_x, grad_K, grad_b


def backward_grad_x_overwrites(x, K, grad_y, need_grad_x=True):
    """Each shifted patch assigned into grad_x (=) instead of added (+=): an input pixel keeps only the last
    receptive field's share of the gradient."""

    def assign(grad_x, window, grad_y, K, p, q):
        grad_x[window] = grad_y @ K[p, q].T

    return _backward(x, K, grad_y, need_grad_x, grad_x_step=assign)


def backward_grad_x_kernel_not_flipped(x, K, grad_y, need_grad_x=True):
    """∂L/∂y slid over the input the way the forward pass slides K over x: ∂L/∂y[a − p] paired with
    K[kh − 1 − p, kw − 1 − q] instead of K[p, q]."""
    kh, kw = K.shape[:2]

    def unflipped(grad_x, window, grad_y, K, p, q):
        grad_x[window] += grad_y @ K[kh - 1 - p, kw - 1 - q].T

    return _backward(x, K, grad_y, need_grad_x, grad_x_step=unflipped)


def backward_grad_b_mean(x, K, grad_y, need_grad_x=True):
    """The bias's gradient averaged over the batch and the positions instead of summed."""
    return _backward(x, K, grad_y, need_grad_x, grad_b_of=lambda g: g.mean(axis=(0, 1, 2)))


def backward_grad_b_per_position(x, K, grad_y, need_grad_x=True):
    """Summed over the batch only: one bias gradient per output position, as if each pixel had a bias of its own."""
    return _backward(x, K, grad_y, need_grad_x, grad_b_of=lambda g: g.sum(axis=0))


def _grad_K_transposed(x, K, grad_y):
    """∂L/∂yᵀ · patches, an (F, kh·kw·C) matrix, reshaped to K's shape without its transpose."""
    kh, kw, C, F = K.shape
    _, out_h, out_w, _ = grad_y.shape
    patches = np.concatenate(
        [x[:, p : p + out_h, q : q + out_w, :] for p in range(kh) for q in range(kw)], axis=-1
    ).reshape(-1, kh * kw * C)
    return (grad_y.reshape(-1, F).T @ patches).reshape(K.shape)


def backward_grad_K_transposed(x, K, grad_y, need_grad_x=True):
    return _backward(x, K, grad_y, need_grad_x, grad_K_of=_grad_K_transposed)


def backward_grad_K_mean_over_the_batch(x, K, grad_y, need_grad_x=True):
    """The kernel's gradient divided by the batch size (a mean where the loss, Σ over the batch, wants the sum)."""
    grad_x, grad_K, grad_b = _backward(x, K, grad_y, need_grad_x)
    return grad_x, grad_K / len(x), grad_b


def backward_always_grad_x(x, K, grad_y, need_grad_x=True):
    """need_grad_x ignored: grad_x computed and returned whatever the caller asked."""
    return _backward(x, K, grad_y, True)


VARIANTS = {
    "forward_flipped_kernel": {"conv2d_forward": forward_flipped_kernel},
    "forward_channel_axes_swapped": {"conv2d_forward": forward_channel_axes_swapped},
    "forward_output_one_too_small": {"conv2d_forward": forward_output_one_too_small},
    "forward_output_the_size_of_the_image": {"conv2d_forward": forward_output_the_size_of_the_image},
    "forward_nchw_output": {"conv2d_forward": forward_nchw_output},
    "forward_without_bias": {"conv2d_forward": forward_without_bias},
    "backward_grad_x_overwrites": {"conv2d_backward": backward_grad_x_overwrites},
    "backward_grad_x_kernel_not_flipped": {"conv2d_backward": backward_grad_x_kernel_not_flipped},
    "backward_grad_b_mean": {"conv2d_backward": backward_grad_b_mean},
    "backward_grad_b_per_position": {"conv2d_backward": backward_grad_b_per_position},
    "backward_grad_K_transposed": {"conv2d_backward": backward_grad_K_transposed},
    "backward_grad_K_mean_over_the_batch": {"conv2d_backward": backward_grad_K_mean_over_the_batch},
    "backward_always_grad_x": {"conv2d_backward": backward_always_grad_x},
}

# what the first failing test's message must say (a regular expression), so that the scoreboard names the mistake
FIRST_FAILURE = {
    "forward_flipped_kernel": r"the kernel is flipped, a true convolution",
    "forward_channel_axes_swapped": r"channel axes are read the wrong way round",
    "forward_output_one_too_small": r"one too small in height: a valid convolution",
    "forward_output_the_size_of_the_image": r"its height is the image's.*there is no padding",
    "forward_nchw_output": r"NCHW.*NHWC, channels last",
    "forward_without_bias": r"the bias is missing",
    "backward_grad_x_overwrites": r"add up \(\+=\), they do not overwrite",
    "backward_grad_x_kernel_not_flipped": r"grad_x .* uses the kernel flipped",
    "backward_grad_b_mean": r"grad_b .*n = 24 times too small everywhere: a mean where the sum belongs",
    "backward_grad_b_per_position": r"grad_b \(one entry per filter, summed over the batch and every position\)",
    "backward_grad_K_transposed": r"grad_K .* the right numbers in the wrong places",
    "backward_grad_K_mean_over_the_batch": r"grad_K .*n = 2 times too small everywhere",
    "backward_always_grad_x": r"need_grad_x=False, grad_x should be None",
}


# the transfer task


def _pool_windows(x, size):
    n, H, W, C = x.shape
    return x.reshape(n, H // size, size, W // size, size, C)


def pool_backward_average(x, size, grad_y):
    """The gradient spread evenly over each window, as an average pool's backward pass."""
    n, H, W, C = x.shape
    spread = np.repeat(np.repeat(grad_y, size, axis=1), size, axis=2)
    return spread / (size * size)


def pool_backward_every_tie(x, size, grad_y):
    """Every pixel equal to the window's maximum gets the gradient."""
    windows = _pool_windows(x, size)
    mask = windows == windows.max(axis=(2, 4), keepdims=True)
    return (mask * grad_y[:, :, None, :, None, :]).reshape(x.shape).astype(np.float64)


def pool_backward_transposed(x, size, grad_y):
    """The argmax's flat index read back as (q, p) instead of (p, q)."""
    n, H, W, C = x.shape
    grad_x = np.zeros(x.shape)
    for b in range(n):
        for i in range(H // size):
            for j in range(W // size):
                for c in range(C):
                    window = x[b, size * i : size * i + size, size * j : size * j + size, c]
                    q, p = divmod(int(np.argmax(window)), size)
                    grad_x[b, size * i + p, size * j + q, c] += grad_y[b, i, j, c]
    return grad_x


def pool_backward_last_tie(x, size, grad_y):
    """At a tie, the gradient sent to the last maximum in row-major order."""
    n, H, W, C = x.shape
    grad_x = np.zeros(x.shape)
    for b in range(n):
        for i in range(H // size):
            for j in range(W // size):
                for c in range(C):
                    window = x[b, size * i : size * i + size, size * j : size * j + size, c].reshape(-1)
                    last = len(window) - 1 - int(np.argmax(window[::-1]))
                    p, q = divmod(last, size)
                    grad_x[b, size * i + p, size * j + q, c] += grad_y[b, i, j, c]
    return grad_x


VARIANTS.update(
    {
        "pool_backward_average": {"max_pool2d_backward": pool_backward_average},
        "pool_backward_every_tie": {"max_pool2d_backward": pool_backward_every_tie},
        "pool_backward_transposed": {"max_pool2d_backward": pool_backward_transposed},
        "pool_backward_last_tie": {"max_pool2d_backward": pool_backward_last_tie},
    }
)
FIRST_FAILURE.update(
    {
        "pool_backward_average": r"spread evenly",
        "pool_backward_every_tie": r"every pixel that ties",
        "pool_backward_transposed": r"p and q swapped",
        "pool_backward_last_tie": r"to the last of them",
    }
)
