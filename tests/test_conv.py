"""The hand-written convolution: against its definition (a direct loop) and against central finite differences."""

import numpy as np
import pytest
from conftest import assert_close, numerical_gradient

from minippo.conv import ConvTrunk, conv2d_backward, conv2d_forward, patches, relu_backward, relu_forward
from minippo.gradcheck import conv2d_by_definition


@pytest.mark.parametrize("shape, kernel", [((2, 5, 6, 3), (3, 3, 3, 4)), ((1, 4, 4, 1), (2, 3, 1, 2))])
def test_conv2d_forward_matches_the_definition(rng, shape, kernel):
    x, K, b = rng.standard_normal(shape), rng.standard_normal(kernel), rng.standard_normal(kernel[-1])
    y = conv2d_forward(x, K, b)
    assert y.shape == (shape[0], shape[1] - kernel[0] + 1, shape[2] - kernel[1] + 1, kernel[3])
    assert np.max(np.abs(y - conv2d_by_definition(x, K, b))) < 1e-12


def test_conv2d_of_a_single_pixel_is_the_kernel_flipped():
    # one lit pixel in the middle of a 5×5 image: a cross-correlation writes the kernel there upside down
    x = np.zeros((1, 5, 5, 1))
    x[0, 2, 2, 0] = 1.0
    K = np.arange(9.0).reshape(3, 3, 1, 1)
    y = conv2d_forward(x, K, np.zeros(1))
    assert np.array_equal(y[0, :, :, 0], K[::-1, ::-1, 0, 0])


def test_patches_rows_are_receptive_fields(rng):
    x = rng.standard_normal((2, 4, 5, 3))
    cols = patches(x, 3, 2)
    assert cols.shape == (2, 2, 4, 3 * 2 * 3)
    assert np.array_equal(cols[1, 1, 2], x[1, 1:4, 2:4, :].reshape(-1))


@pytest.mark.parametrize("kernel", [(3, 3, 2, 4), (2, 3, 2, 1)])
def test_conv2d_backward_matches_finite_differences(rng, kernel):
    x, K, b = rng.standard_normal((2, 5, 4, 2)), rng.standard_normal(kernel), rng.standard_normal(kernel[-1])
    weights = rng.standard_normal(conv2d_forward(x, K, b).shape)  # L = Σ w ⊙ y, so dL/dy = w

    def loss():
        return float((conv2d_forward(x, K, b) * weights).sum())

    grad_x, grad_K, grad_b = conv2d_backward(x, K, weights)
    assert_close(grad_x, numerical_gradient(loss, x))
    assert_close(grad_K, numerical_gradient(loss, K))
    assert_close(grad_b, numerical_gradient(loss, b))
    none, grad_K_again, _ = conv2d_backward(x, K, weights, need_grad_x=False)
    assert none is None and np.array_equal(grad_K_again, grad_K)


def test_conv2d_input_gradient_adds_overlaps():
    # with a kernel and an upstream gradient of ones, each input pixel's gradient counts the output pixels that see it
    x = np.zeros((1, 4, 4, 1))
    grad_x, _, _ = conv2d_backward(x, np.ones((3, 3, 1, 1)), np.ones((1, 2, 2, 1)))
    counts = np.array([[1, 2, 2, 1], [2, 4, 4, 2], [2, 4, 4, 2], [1, 2, 2, 1]])
    assert np.array_equal(grad_x[0, :, :, 0], counts)


def test_relu_backward_matches_finite_differences(rng):
    z = rng.standard_normal((3, 7))
    z[np.abs(z) < 1e-3] = 0.5  # away from the kink, where the derivative is not defined
    weights = rng.standard_normal(z.shape)
    assert_close(
        relu_backward(relu_forward(z), weights), numerical_gradient(lambda: float((relu_forward(z) * weights).sum()), z)
    )


def test_conv_trunk_backward_matches_finite_differences(rng):
    trunk = ConvTrunk((5, 5, 2), channels=3, kernel=3, hidden=6)
    trunk.init(rng, np.sqrt(2.0), np.sqrt(2.0))
    trunk.conv_b[...] = rng.standard_normal(3) * 0.1  # biases that are not zero, so they are checked too
    trunk.b[...] = rng.standard_normal(6) * 0.1
    x = rng.standard_normal((3, 5 * 5 * 2))
    weights = rng.standard_normal((3, 6))

    def loss():
        return float((trunk(x) * weights).sum())

    _, cache = trunk.forward(x)
    grad_x = trunk.backward(cache, weights, need_grad_input=True)
    assert_close(trunk.grads, numerical_gradient(loss, trunk.params))
    assert_close(grad_x, numerical_gradient(loss, x))


def test_conv_trunk_init_is_orthogonal_with_zero_biases(rng):
    trunk = ConvTrunk((10, 10, 4))
    trunk.init(rng, np.sqrt(2.0), np.sqrt(2.0))
    kernel = trunk.K.reshape(-1, 16)
    assert np.allclose(kernel.T @ kernel, 2.0 * np.eye(16))
    assert trunk.dense_shape == (8 * 8 * 16, 128)
    assert np.all(trunk.conv_b == 0) and np.all(trunk.b == 0)


def test_conv_trunk_refuses_an_image_smaller_than_its_kernel():
    with pytest.raises(ValueError, match="does not fit"):
        ConvTrunk((2, 5, 1))
