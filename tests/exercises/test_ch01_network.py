"""Grading chapter 1: the MLP's forward and backward passes against finite differences, and Adam against its sums."""

import _harness
import numpy as np
import pytest
from _harness import call_checking_inputs, check_array, check_close, numerical_gradient

student = _harness.student  # the fixture: the implementation under test (see _harness.py)
pytest_generate_tests = _harness.pytest_generate_tests  # one run per wrong variant under MINIPPO_IMPL=wrong
rng = _harness.rng  # a seeded NumPy Generator

pytestmark = pytest.mark.timeout(15)


def reference_forward(layers, x):
    """Row by row with einsum: the same function as mlp_forward, computed another way."""
    cache, h = [], x
    for i, (W, b) in enumerate(layers):
        cache.append(h)
        z = np.einsum("ni,io->no", h, W) + b[None, :]
        h = np.tanh(z) if i < len(layers) - 1 else z
    return h, cache


def random_layers(rng, sizes):
    return [(rng.normal(0, 0.7, (i, o)), rng.normal(0, 0.3, o)) for i, o in zip(sizes[:-1], sizes[1:])]


# linear and tanh layers


@pytest.mark.parametrize("n", [1, 5])
def test_linear_backward_matches_finite_differences(student, rng, n):
    x, W, b = rng.normal(size=(n, 3)), rng.normal(size=(3, 4)), rng.normal(size=4)
    grad_y = rng.normal(size=(n, 4))

    def loss():
        return float(np.sum(grad_y * (x @ W + b)))

    grad_x, grad_W, grad_b = call_checking_inputs(student.linear_backward, "linear_backward", x, W, grad_y)
    check_array(grad_x, "linear_backward", (n, 3), "grad_x")
    check_array(grad_W, "linear_backward", (3, 4), "grad_W")
    check_array(grad_b, "linear_backward", (4,), "grad_b (one entry per output, summed over the batch)")
    check_close(grad_x, numerical_gradient(loss, x), "linear_backward", "grad_x (checked by finite differences)")
    check_close(grad_W, numerical_gradient(loss, W), "linear_backward", "grad_W (checked by finite differences)", n=n)
    check_close(grad_b, numerical_gradient(loss, b), "linear_backward", "grad_b (checked by finite differences)", n=n)


def test_tanh_backward_matches_finite_differences(student, rng):
    z = np.concatenate([rng.normal(0, 1.5, 12), [0.0, 25.0, -25.0]]).reshape(3, 5)
    grad_h = rng.normal(size=(3, 5))
    h = np.tanh(z)
    grad_z = call_checking_inputs(student.tanh_backward, "tanh_backward", h, grad_h)
    check_array(grad_z, "tanh_backward", (3, 5))
    assert not np.allclose(grad_z, grad_h * (1 - np.tanh(h) ** 2)), (
        "tanh_backward: the result is ∂L/∂h · (1 − tanh(h)²), but h is already tanh(z): ∂L/∂z = ∂L/∂h · (1 − h²)"
    )
    expected = numerical_gradient(lambda: float(np.sum(grad_h * np.tanh(z))), z)
    check_close(
        grad_z, expected, "tanh_backward", "∂L/∂z (checked by finite differences)", where={"h": h, "∂L/∂h": grad_h}
    )


def test_tanh_backward_is_zero_where_tanh_is_flat(student):
    h = np.array([1.0, -1.0, 0.0])
    grad_z = student.tanh_backward(h, np.array([2.0, 3.0, 4.0]))
    check_close(grad_z, [0.0, 0.0, 4.0], "tanh_backward", "the gradient where tanh is saturated (h = ±1) or at 0")


# the whole network


@pytest.mark.parametrize("sizes", [(3, 5, 2), (4, 6, 6, 3), (2, 1)], ids=["one-hidden", "two-hidden", "linear"])
def test_mlp_forward_matches_the_definition(student, rng, sizes):
    layers = random_layers(rng, sizes)
    x = rng.normal(size=(7, sizes[0]))
    out, cache = call_checking_inputs(student.mlp_forward, "mlp_forward", layers, x, may_alias=(1,))
    expected_out, expected_cache = reference_forward(layers, x)
    check_array(out, "mlp_forward", (7, sizes[-1]), "the output")
    check_close(out, expected_out, "mlp_forward", "the output (tanh between layers, none after the last)")
    assert len(cache) == len(layers), (
        f"mlp_forward: the cache should hold the input of each of the {len(layers)} layers, not {len(cache)} arrays"
    )
    for i, (got, want) in enumerate(zip(cache, expected_cache)):
        check_close(got, want, "mlp_forward", f"cache[{i}] (the input of layer {i + 1})")


def test_mlp_forward_takes_a_single_sample(student, rng):
    layers = random_layers(rng, (3, 4, 2))
    x = rng.normal(size=(1, 3))
    out, _ = student.mlp_forward(layers, x)
    check_array(out, "mlp_forward", (1, 2), "the output for a batch of one")
    check_close(out, reference_forward(layers, x)[0], "mlp_forward", "the output for a batch of one")


@pytest.mark.parametrize("sizes", [(3, 5, 2), (4, 6, 6, 3), (2, 1)], ids=["one-hidden", "two-hidden", "linear"])
def test_mlp_backward_matches_finite_differences(student, rng, sizes):
    layers = random_layers(rng, sizes)
    x = rng.normal(size=(6, sizes[0]))
    grad_out = rng.normal(size=(6, sizes[-1]))

    def loss():
        return float(np.sum(grad_out * reference_forward(layers, x)[0]))

    _, cache = reference_forward(layers, x)
    grads, grad_x = call_checking_inputs(student.mlp_backward, "mlp_backward", layers, cache, grad_out)
    assert len(grads) == len(layers), f"mlp_backward: return one (grad_W, grad_b) per layer ({len(layers)})"
    for i, ((W, b), (grad_W, grad_b)) in enumerate(zip(layers, grads)):
        check_array(grad_W, "mlp_backward", W.shape, f"∂L/∂W of layer {i + 1}")
        check_array(grad_b, "mlp_backward", b.shape, f"∂L/∂b of layer {i + 1}")
        check_close(grad_W, numerical_gradient(loss, W), "mlp_backward", f"∂L/∂W of layer {i + 1}", 1e-5, 1e-7, n=6)
        check_close(grad_b, numerical_gradient(loss, b), "mlp_backward", f"∂L/∂b of layer {i + 1}", 1e-5, 1e-7, n=6)
    check_array(grad_x, "mlp_backward", x.shape, "∂L/∂x")
    check_close(grad_x, numerical_gradient(loss, x), "mlp_backward", "∂L/∂x", 1e-5, 1e-7)


# Adam


@pytest.mark.parametrize("t", [1, 2, 5])
def test_adam_bias_correction_uses_the_step_number(student, t):
    # m and v as they stand before step t under a constant gradient g: m̂ = g and v̂ = g² exactly, so the step is lr
    g, beta1, beta2 = np.array([0.5, -2.0]), 0.9, 0.999
    m, v = (1 - beta1 ** (t - 1)) * g, (1 - beta2 ** (t - 1)) * g * g
    new_params, _, _ = student.adam_step(np.zeros(2), g, m, v, t, lr=0.05)
    check_array(new_params, "adam_step", (2,), f"the new parameters at step t = {t}")
    check_close(
        -new_params,
        0.05 * g / (np.abs(g) + 1e-8),
        "adam_step",
        f"the step at t = {t} under a constant gradient (with bias correction by 1 − β1ᵗ and 1 − β2ᵗ, t the number of "
        "this step, it is lr · g/(|g| + eps))",
    )


def test_adam_first_step_moves_each_parameter_by_about_lr(student, rng):
    # after bias correction m̂ = g and v̂ = g², so the first step is lr · g / (|g| + eps): about lr, whatever |g|
    params = rng.normal(size=6)
    grads = np.array([3.0, -0.02, 1e-3, -50.0, 0.5, 2.0])
    zeros = np.zeros(6)
    new_params, new_m, new_v = call_checking_inputs(
        student.adam_step, "adam_step", params, grads, zeros, zeros, 1, lr=0.01, eps=1e-8
    )
    check_array(new_params, "adam_step", (6,), "the new parameters")
    check_close(
        params - new_params,
        0.01 * grads / (np.abs(grads) + 1e-8),
        "adam_step",
        "the first step (with bias correction it should be lr · g/(|g| + eps), about lr against the gradient)",
    )
    check_close(new_m, 0.1 * grads, "adam_step", "the first moment after one step")
    check_close(new_v, 0.001 * grads**2, "adam_step", "the second moment after one step")


def test_adam_matches_the_sums_it_stands_for(student, rng):
    # m_t = (1 − β1) Σ_i β1^{t−i} g_i and v_t = (1 − β2) Σ_i β2^{t−i} g_i², summed directly; gradients of the
    # order of eps make where eps goes matter
    beta1, beta2, eps, lr = 0.8, 0.95, 1e-3, 0.05
    gradients = [rng.normal(0, 1e-3, 5) for _ in range(7)]
    params = rng.normal(size=5)
    expected = params.copy()
    m, v = np.zeros(5), np.zeros(5)
    for t in range(1, 8):
        params, m, v = student.adam_step(params, gradients[t - 1], m, v, t, lr, beta1, beta2, eps)
        check_array(params, "adam_step", (5,), f"the parameters after step {t}")
        m_sum = (1 - beta1) * sum(beta1 ** (t - i) * gradients[i - 1] for i in range(1, t + 1))
        v_sum = (1 - beta2) * sum(beta2 ** (t - i) * gradients[i - 1] ** 2 for i in range(1, t + 1))
        check_close(m, m_sum, "adam_step", f"the first moment m after step {t}")
        check_close(v, v_sum, "adam_step", f"the second moment v after step {t}")
        expected = expected - lr * (m_sum / (1 - beta1**t)) / (np.sqrt(v_sum / (1 - beta2**t)) + eps)
        check_close(params, expected, "adam_step", f"the parameters after step {t} (θ − lr·m̂/(√v̂ + eps))")


def test_adam_steps_by_lr_under_a_constant_gradient(student):
    # with a constant g, m̂ = g and v̂ = g² at every step, so every step is exactly lr · g/(|g| + eps)
    params, m, v = np.zeros(3), np.zeros(3), np.zeros(3)
    grads = np.array([2.0, -0.5, 10.0])
    for t in range(1, 31):
        previous = params
        params, m, v = student.adam_step(params, grads, m, v, t, lr=0.1, eps=1e-8)
        check_close(previous - params, 0.1 * grads / (np.abs(grads) + 1e-8), "adam_step", f"step {t} size")


def test_adam_minimises_a_quadratic(student, rng):
    target = rng.normal(size=4)
    params, m, v = np.zeros(4), np.zeros(4), np.zeros(4)
    for t in range(1, 1501):
        params, m, v = student.adam_step(params, params - target, m, v, t, lr=0.02)
    assert np.all(np.isfinite(params)), "adam_step: the parameters became NaN or infinite"
    assert np.abs(params - target).max() < 1e-2, (
        f"adam_step: 1500 steps on ½‖θ − c‖² should reach c, but are {np.abs(params - target).max():.3g} away "
        "(does the step go against the gradient?)"
    )


def test_adam_leaves_its_inputs_unchanged(student, rng):
    params, grads, m, v = rng.normal(size=(2, 3)), rng.normal(size=(2, 3)), rng.normal(size=(2, 3)), rng.random((2, 3))
    new_params, new_m, new_v = call_checking_inputs(student.adam_step, "adam_step", params, grads, m, v, 4)
    for value, what in [(new_params, "new_params"), (new_m, "new_m"), (new_v, "new_v")]:
        check_array(value, "adam_step", (2, 3), what)


# the transfer task: layer normalisation's backward pass


def layer_norm_forward(x, gain):
    centred = x - x.mean(axis=1, keepdims=True)
    return gain * centred / np.sqrt((centred * centred).mean(axis=1, keepdims=True) + 1e-5)


@pytest.fixture
def layer_norm_case(rng):
    return rng.normal(0.5, 2.0, (5, 4)), rng.uniform(0.5, 2.0, 4), rng.standard_normal((5, 4))


def test_layer_norm_backward_gain_gradient_sums_over_the_batch(student, layer_norm_case):
    x, gain, grad_y = layer_norm_case
    result = _harness.call_checking_inputs(student.layer_norm_backward, "layer_norm_backward", x, gain, grad_y)
    assert isinstance(result, tuple) and len(result) == 2, "layer_norm_backward should return (grad_x, grad_gain)"
    grad_gain = _harness.check_array(result[1], "layer_norm_backward", (4,), "grad_gain")
    g = gain.copy()
    expected = _harness.numerical_gradient(lambda: float(np.sum(grad_y * layer_norm_forward(x, g))), g, 1e-6)
    _harness.check_close(
        grad_gain, expected, "layer_norm_backward", "∂L/∂gain (the gain scales every row: it sums over the batch)",
        rtol=1e-5, atol=1e-7, n=5,
    )  # fmt: skip


def test_layer_norm_backward_rows_of_grad_x_sum_to_zero(student, layer_norm_case):
    # adding a constant to a row of x leaves y unchanged, so each row of ∂L/∂x sums to 0
    x, gain, grad_y = layer_norm_case
    grad_x = _harness.check_array(
        student.layer_norm_backward(x, gain, grad_y)[0], "layer_norm_backward", (5, 4), "grad_x"
    )
    sums = grad_x.sum(axis=1)
    worst = int(np.argmax(np.abs(sums)))
    assert np.all(np.abs(sums) < 1e-8), (
        f"layer_norm_backward: row {worst} of ∂L/∂x sums to {sums[worst]:.6g}, not 0 (adding a constant to a row of x "
        "leaves the layer's output unchanged, so the gradient can have no component along (1, …, 1)): the row's mean "
        "treated as a constant, though it depends on every entry of the row?"
    )


def test_layer_norm_backward_matches_finite_differences(student, layer_norm_case):
    x, gain, grad_y = layer_norm_case
    grad_x = _harness.check_array(
        student.layer_norm_backward(x, gain, grad_y)[0], "layer_norm_backward", (5, 4), "grad_x"
    )
    xx = x.copy()
    expected = _harness.numerical_gradient(lambda: float(np.sum(grad_y * layer_norm_forward(xx, gain))), xx, 1e-6)
    centred = x - x.mean(axis=1, keepdims=True)
    inv_std = 1.0 / np.sqrt((centred * centred).mean(axis=1, keepdims=True) + 1e-5)
    g = grad_y * gain
    variance_constant = inv_std * (g - g.mean(axis=1, keepdims=True))
    x_hat = centred * inv_std
    without_gain = inv_std * (
        grad_y - grad_y.mean(axis=1, keepdims=True) - x_hat * (grad_y * x_hat).mean(axis=1, keepdims=True)
    )
    if np.allclose(grad_x, without_gain, rtol=1e-6, atol=1e-9):
        raise AssertionError(
            "layer_norm_backward: ∂L/∂x is what it would be with every gain 1: ∂L/∂y carried back without the gain's "
            "factor (y = gain · x̂)?"
        )
    if np.allclose(grad_x, variance_constant, rtol=1e-6, atol=1e-9) and not np.allclose(grad_x, expected, 1e-5, 1e-7):
        raise AssertionError(
            "layer_norm_backward: ∂L/∂x is (g − mean g)/σ row by row, with g = ∂L/∂y · gain: the variance treated as a "
            "constant, though it depends on every entry of the row too?"
        )
    _harness.check_close(grad_x, expected, "layer_norm_backward", "∂L/∂x (checked by finite differences)", 1e-5, 1e-7)
