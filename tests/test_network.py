"""MLP and Adam: hand-derived backward passes against central finite differences, in float64."""

import numpy as np
import pytest
from conftest import assert_close, numerical_gradient

from minippo.network import MLP, orthogonal, tanh_forward
from minippo.optimizer import Adam, clip_grad_norm, linear_schedule


@pytest.mark.parametrize("activate_output", [False, True])
def test_mlp_backward_matches_finite_differences(rng, activate_output):
    net = MLP((5, 7, 6, 3), out_gain=1.0, activate_output=activate_output, rng=rng)
    x = rng.standard_normal((4, 5))
    weights = rng.standard_normal((4, 3))  # L = Σ w ⊙ f(x), so dL/dout = w

    def loss():
        return float((net(x) * weights).sum())

    _, cache = net.forward(x)
    grad_x = net.backward(cache, weights, need_grad_input=True)
    assert_close(net.grads, numerical_gradient(loss, net.params))
    assert_close(grad_x, numerical_gradient(loss, x))


def test_tanh_forward_is_tanh_everywhere():
    z = np.concatenate([np.linspace(-30, 30, 2001), [-800.0, 800.0, 0.0]])
    assert np.max(np.abs(tanh_forward(z) - np.tanh(z))) < 1e-15 * 4
    assert np.all(np.isfinite(tanh_forward(z)))


def test_orthogonal_init_is_orthogonal_and_scaled(rng):
    for shape in [(8, 64), (64, 64), (64, 3)]:
        W = orthogonal(shape, 2.0, rng)
        small = W @ W.T if shape[0] <= shape[1] else W.T @ W
        assert np.allclose(small, 4.0 * np.eye(min(shape)))


def test_mlp_init_gains_and_zero_biases(rng):
    net = MLP((4, 64, 64, 2), out_gain=0.01, rng=rng)
    assert all(np.all(b == 0) for b in net.b)
    assert np.allclose(net.W[-1].T @ net.W[-1], 1e-4 * np.eye(2))
    assert np.allclose(net.W[1].T @ net.W[1], 2.0 * np.eye(64))


def test_adam_matches_the_textbook_update(rng):
    params = rng.standard_normal(6)
    reference = params.copy()
    opt = Adam(params, lr=1e-2, eps=1e-8)
    m = np.zeros(6)
    v = np.zeros(6)
    for t in range(1, 6):
        g = rng.standard_normal(6)
        opt.step(g)
        m = 0.9 * m + 0.1 * g
        v = 0.999 * v + 0.001 * g * g
        reference -= 1e-2 * (m / (1 - 0.9**t)) / (np.sqrt(v / (1 - 0.999**t)) + 1e-8)
        assert np.allclose(params, reference, rtol=1e-12, atol=1e-14)


def test_adam_first_step_moves_each_parameter_by_about_lr():
    params = np.zeros(3)
    Adam(params, lr=0.1, eps=1e-12).step(np.array([5.0, -0.001, 300.0]))
    assert np.allclose(params, [-0.1, 0.1, -0.1])


def test_adam_fits_a_small_regression(rng):
    x = rng.uniform(-2, 2, (256, 1))
    y = np.sin(2 * x)
    net = MLP((1, 32, 32, 1), rng=rng)
    opt = Adam(net.params, lr=1e-2)

    def mse():
        return float(np.mean((net(x) - y) ** 2))

    start = mse()
    for _ in range(1500):
        out, cache = net.forward(x)
        net.backward(cache, 2 * (out - y) / len(x))
        opt.step(net.grads)
    assert mse() < 0.01 * start and mse() < 5e-3


def test_clip_grad_norm_scales_only_large_gradients():
    g = np.array([3.0, 4.0])
    assert clip_grad_norm(g, 10.0) == 5.0 and np.allclose(g, [3, 4])
    assert clip_grad_norm(g, 0.5) == 5.0 and np.isclose(np.linalg.norm(g), 0.5, atol=1e-6)


def test_linear_schedule_falls_to_zero():
    assert linear_schedule(3e-4, 1, 10) == 3e-4
    assert np.isclose(linear_schedule(3e-4, 10, 10), 3e-5)
    assert np.isclose(linear_schedule(3e-4, 11, 10), 0.0)
