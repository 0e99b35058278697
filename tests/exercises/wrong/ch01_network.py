"""Plausible mistakes in chapter 1: the backward passes and Adam."""

import numpy as np

from solutions.ch01_network import linear_backward as correct_linear_backward


def linear_backward_mean_bias(x, W, grad_y):
    """The bias gradient averaged over the batch instead of summed."""
    return grad_y @ W.T, x.T @ grad_y, grad_y.mean(axis=0)


def linear_backward_bias_per_row(x, W, grad_y):
    """The bias gradient left per row, shape (n, out)."""
    return grad_y @ W.T, x.T @ grad_y, grad_y.copy()


def linear_backward_transposed_weight_gradient(x, W, grad_y):
    """∂L/∂W as ∂L/∂yᵀ x, the transpose of the right answer."""
    return grad_y @ W.T, grad_y.T @ x, grad_y.sum(axis=0)


def tanh_backward_tanh_again(h, grad_h):
    """1 − tanh(h)², as if h were the input of tanh rather than its output."""
    return grad_h * (1.0 - np.tanh(h) ** 2)


def tanh_backward_no_square(h, grad_h):
    """1 − h instead of 1 − h²."""
    return grad_h * (1.0 - h)


def mlp_forward_tanh_on_output(layers, x):
    """tanh after the last layer as well."""
    cache, h = [], x
    for W, b in layers:
        cache.append(h)
        h = np.tanh(h @ W + b)
    return h, cache


def mlp_forward_caches_outputs(layers, x):
    """The cache holds each layer's output rather than its input."""
    cache, h = [], x
    for i, (W, b) in enumerate(layers):
        z = h @ W + b
        h = np.tanh(z) if i < len(layers) - 1 else z
        cache.append(h)
    return h, cache


def mlp_backward_skips_tanh(layers, cache, grad_out):
    """The chain rule through the linear layers only, forgetting the tanh between them."""
    grads, grad = [None] * len(layers), grad_out
    for i in range(len(layers) - 1, -1, -1):
        grad, grad_W, grad_b = correct_linear_backward(cache[i], layers[i][0], grad)
        grads[i] = (grad_W, grad_b)
    return grads, grad


def mlp_backward_tanh_on_input_too(layers, cache, grad_out):
    """Also goes back through a tanh at the network's input, which never had one."""
    grads, grad = [None] * len(layers), grad_out
    for i in range(len(layers) - 1, -1, -1):
        grad_x, grad_W, grad_b = correct_linear_backward(cache[i], layers[i][0], grad)
        grads[i] = (grad_W, grad_b)
        grad = grad_x * (1.0 - cache[i] ** 2)
    return grads, grad


def mlp_backward_reversed_order(layers, cache, grad_out):
    """Right gradients, returned last layer first."""
    grads, grad = [], grad_out
    for i in range(len(layers) - 1, -1, -1):
        grad_x, grad_W, grad_b = correct_linear_backward(cache[i], layers[i][0], grad)
        grads.append((grad_W, grad_b))
        grad = grad_x * (1.0 - cache[i] ** 2) if i > 0 else grad_x
    return grads, grad


def adam_no_bias_correction(params, grads, m, v, t, lr=3e-4, beta1=0.9, beta2=0.999, eps=1e-8):
    """m and v used as they are: the first steps are too large by √(1 − β2)/(1 − β1) ≈ 0.32/0.1."""
    m = beta1 * m + (1 - beta1) * grads
    v = beta2 * v + (1 - beta2) * grads**2
    return params - lr * m / (np.sqrt(v) + eps), m, v


def adam_eps_inside_the_root(params, grads, m, v, t, lr=3e-4, beta1=0.9, beta2=0.999, eps=1e-8):
    """θ − lr m̂ / √(v̂ + eps)."""
    m = beta1 * m + (1 - beta1) * grads
    v = beta2 * v + (1 - beta2) * grads**2
    return params - lr * (m / (1 - beta1**t)) / np.sqrt(v / (1 - beta2**t) + eps), m, v


def adam_ascends(params, grads, m, v, t, lr=3e-4, beta1=0.9, beta2=0.999, eps=1e-8):
    """A step along the gradient instead of against it."""
    m = beta1 * m + (1 - beta1) * grads
    v = beta2 * v + (1 - beta2) * grads**2
    return params + lr * (m / (1 - beta1**t)) / (np.sqrt(v / (1 - beta2**t)) + eps), m, v


def adam_in_place(params, grads, m, v, t, lr=3e-4, beta1=0.9, beta2=0.999, eps=1e-8):
    """Right numbers, but params, m and v are overwritten in place (the contract asks for new arrays)."""
    m *= beta1
    m += (1 - beta1) * grads
    v *= beta2
    v += (1 - beta2) * grads**2
    params -= lr * (m / (1 - beta1**t)) / (np.sqrt(v / (1 - beta2**t)) + eps)
    return params, m, v


def adam_abs_instead_of_square(params, grads, m, v, t, lr=3e-4, beta1=0.9, beta2=0.999, eps=1e-8):
    """The second moment tracks |g| instead of g²."""
    m = beta1 * m + (1 - beta1) * grads
    v = beta2 * v + (1 - beta2) * np.abs(grads)
    return params - lr * (m / (1 - beta1**t)) / (np.sqrt(v / (1 - beta2**t)) + eps), m, v


VARIANTS = {
    "linear_backward_mean_bias": {"linear_backward": linear_backward_mean_bias},
    "linear_backward_bias_per_row": {"linear_backward": linear_backward_bias_per_row},
    "linear_backward_transposed_weight_gradient": {"linear_backward": linear_backward_transposed_weight_gradient},
    "tanh_backward_tanh_again": {"tanh_backward": tanh_backward_tanh_again},
    "tanh_backward_no_square": {"tanh_backward": tanh_backward_no_square},
    "mlp_forward_tanh_on_output": {"mlp_forward": mlp_forward_tanh_on_output},
    "mlp_forward_caches_outputs": {"mlp_forward": mlp_forward_caches_outputs},
    "mlp_backward_skips_tanh": {"mlp_backward": mlp_backward_skips_tanh},
    "mlp_backward_tanh_on_input_too": {"mlp_backward": mlp_backward_tanh_on_input_too},
    "mlp_backward_reversed_order": {"mlp_backward": mlp_backward_reversed_order},
    "adam_no_bias_correction": {"adam_step": adam_no_bias_correction},
    "adam_eps_inside_the_root": {"adam_step": adam_eps_inside_the_root},
    "adam_ascends": {"adam_step": adam_ascends},
    "adam_in_place": {"adam_step": adam_in_place},
    "adam_abs_instead_of_square": {"adam_step": adam_abs_instead_of_square},
}


def adam_step_count_from_zero(params, grads, m, v, t, lr=3e-4, beta1=0.9, beta2=0.999, eps=1e-8):
    """Bias correction with t + 1, as if the first step were number 0."""
    m = beta1 * m + (1 - beta1) * grads
    v = beta2 * v + (1 - beta2) * grads**2
    return params - lr * (m / (1 - beta1 ** (t + 1))) / (np.sqrt(v / (1 - beta2 ** (t + 1))) + eps), m, v


def adam_default_lr(params, grads, m, v, t, lr=3e-4, beta1=0.9, beta2=0.999, eps=1e-8):
    """Uses the default learning rate 3e-4 whatever lr is passed."""
    m = beta1 * m + (1 - beta1) * grads
    v = beta2 * v + (1 - beta2) * grads**2
    return params - 3e-4 * (m / (1 - beta1**t)) / (np.sqrt(v / (1 - beta2**t)) + eps), m, v


def linear_backward_float32(x, W, grad_y):
    """Right gradients, returned in float32."""
    return tuple(g.astype(np.float32) for g in correct_linear_backward(x, W, grad_y))


def tanh_backward_returns_input(h, grad_h):
    """Writes the result into grad_h and returns it: the caller's gradient changes."""
    grad_h *= 1.0 - h * h
    return grad_h


VARIANTS.update(
    {
        "adam_step_count_from_zero": {"adam_step": adam_step_count_from_zero},
        "adam_default_lr": {"adam_step": adam_default_lr},
        "linear_backward_float32": {"linear_backward": linear_backward_float32},
        "tanh_backward_returns_input": {"tanh_backward": tanh_backward_returns_input},
    }
)

FIRST_FAILURE = {
    "adam_step_count_from_zero": r"the step at t = 1",
    "adam_no_bias_correction": r"the step at t = 1",
    "adam_default_lr": r"lr",
    "linear_backward_float32": r"float64.*not float32",
    "tanh_backward_returns_input": r"tanh_backward (changed its input|returned one of its inputs)",
    "adam_in_place": r"changed its input",
    "tanh_backward_tanh_again": r"h is already tanh\(z\)",
    "linear_backward_mean_bias": r"grad_b .*n = \d+ times too small everywhere: a mean where the sum belongs",
}


# the transfer task


def _layer_norm_parts(x, gain, grad_y):
    centred = x - x.mean(axis=1, keepdims=True)
    inv_std = 1.0 / np.sqrt((centred * centred).mean(axis=1, keepdims=True) + 1e-5)
    return centred * inv_std, inv_std, grad_y * gain


def ln_statistics_constant(x, gain, grad_y):
    """The row's mean and variance treated as constants: ∂L/∂x = gain · ∂L/∂y / σ."""
    x_hat, inv_std, g = _layer_norm_parts(x, gain, grad_y)
    return g * inv_std, (grad_y * x_hat).sum(axis=0)


def ln_variance_constant(x, gain, grad_y):
    """The mean's dependence on the row kept, the variance's forgotten."""
    x_hat, inv_std, g = _layer_norm_parts(x, gain, grad_y)
    return inv_std * (g - g.mean(axis=1, keepdims=True)), (grad_y * x_hat).sum(axis=0)


def ln_gain_gradient_mean(x, gain, grad_y):
    """∂L/∂gain averaged over the batch instead of summed."""
    x_hat, inv_std, g = _layer_norm_parts(x, gain, grad_y)
    grad_x = inv_std * (g - g.mean(axis=1, keepdims=True) - x_hat * (g * x_hat).mean(axis=1, keepdims=True))
    return grad_x, (grad_y * x_hat).mean(axis=0)


def ln_gain_forgotten_in_grad_x(x, gain, grad_y):
    """∂L/∂x carried back from ∂L/∂y without the gain's factor."""
    x_hat, inv_std, _ = _layer_norm_parts(x, gain, grad_y)
    g = grad_y
    grad_x = inv_std * (g - g.mean(axis=1, keepdims=True) - x_hat * (g * x_hat).mean(axis=1, keepdims=True))
    return grad_x, (grad_y * x_hat).sum(axis=0)


VARIANTS.update(
    {
        "ln_statistics_constant": {"layer_norm_backward": ln_statistics_constant},
        "ln_variance_constant": {"layer_norm_backward": ln_variance_constant},
        "ln_gain_gradient_mean": {"layer_norm_backward": ln_gain_gradient_mean},
        "ln_gain_forgotten_in_grad_x": {"layer_norm_backward": ln_gain_forgotten_in_grad_x},
    }
)
FIRST_FAILURE.update(
    {
        "ln_statistics_constant": r"mean treated as a constant",
        "ln_variance_constant": r"variance treated as a constant",
        "ln_gain_gradient_mean": r"n = 5 times too small everywhere: a mean where the sum belongs",
        "ln_gain_forgotten_in_grad_x": r"without the gain's factor",
    }
)
