"""Grading chapter 12: the 2-D convolution, forward (a 1×1 kernel over the channels, a small case by hand, one lit
pixel, then the definition written as loops at several shapes: batches, channels in and out, non-square kernels and
images, a kernel as large as the image) and backward (the bias's sum, the overlaps an input pixel collects, then all
three gradients against float64 central finite differences, the first layer's shortcut, and minippo's own layer at
the MinAtar network's size).

Tests run from the most specific to the most general, so the first failure names the mistake: the output's size
(valid, no padding), the order of its axes (NHWC), a flipped kernel (a true convolution instead of deep learning's
cross-correlation), the kernel's channel axes read the wrong way round, overlapping receptive fields that overwrite
instead of adding up, a bias gradient not summed, a kernel gradient in the wrong order."""

import _harness
import numpy as np
import pytest
from _harness import call_checking_inputs, check_array, check_close, numerical_gradient

from minippo import conv
from minippo.gradcheck import conv2d_by_definition

student = _harness.student  # the fixture: the implementation under test (see _harness.py)
pytest_generate_tests = _harness.pytest_generate_tests  # one run per wrong variant under MINIPPO_IMPL=wrong
rng = _harness.rng  # a seeded NumPy Generator

pytestmark = pytest.mark.timeout(20)


def grad_x_by_definition(K, grad_y, image_shape):
    """∂L/∂x[n, a, e, c] = Σ_{p, q, f} ∂L/∂y[n, a − p, e − q, f] K[p, q, c, f], over the (a − p, e − q) inside y."""
    kh, kw, _, _ = K.shape
    _, out_h, out_w, _ = grad_y.shape
    grad_x = np.zeros(image_shape)
    for i in range(out_h):
        for j in range(out_w):
            grad_x[:, i : i + kh, j : j + kw, :] += np.einsum("nf,pqcf->npqc", grad_y[:, i, j, :], K)
    return grad_x


def output_shape(x_shape, K_shape):
    return (x_shape[0], x_shape[1] - K_shape[0] + 1, x_shape[2] - K_shape[1] + 1, K_shape[3])


def shape_mistake(got: tuple, x_shape: tuple, K_shape: tuple) -> str:
    """What a wrong output shape says about the code that made it, in words."""
    n, H, W, _ = x_shape
    kh, kw, _, F = K_shape
    expected = output_shape(x_shape, K_shape)
    if len(got) != 4:
        return f"one (n, H − kh + 1, W − kw + 1, F) array, with n = {n} images and F = {F} filters"
    if got == (n, F, expected[1], expected[2]):
        return "its axes are in PyTorch's NCHW order (n, F, height, width); here images are NHWC, channels last"
    words = []
    for axis, size, k, side, sizes in ((1, H, kh, "height", "H − kh + 1"), (2, W, kw, "width", "W − kw + 1")):
        extra = got[axis] - expected[axis]
        if extra == 0:
            continue
        valid = f"a valid convolution of an image of {side} {size} with a kernel of {side} {k} has {side} {sizes}"
        if got[axis] == size:
            words.append(f"its {side} is the image's, {size}: there is no padding, and {valid} = {expected[axis]}")
        elif abs(extra) == 1:
            too = "large" if extra > 0 else "small"
            fits = f"the {expected[axis]} positions where the kernel fits"
            words.append(f"the output is one too {too} in {side}: {valid} = {expected[axis]}, {fits}")
    if got[0] != n:
        words.append(f"one output per image: the batch has n = {n}")
    if got[3] != F:
        words.append(f"one output channel per filter: K is (kh, kw, C, F) with F = {F}")
    return "; ".join(words) or "it should be (n, H − kh + 1, W − kw + 1, F)"


def check_output(y, x, K, what: str = "the output") -> np.ndarray:
    """y is a finite float64 array of the valid convolution's shape, or the test fails saying what the shape shows."""
    expected = output_shape(x.shape, K.shape)
    if isinstance(y, np.ndarray) and y.shape != expected:
        raise AssertionError(
            f"conv2d_forward: {what} should have shape {expected} for x {x.shape} and K {K.shape}, not {y.shape}: "
            f"{shape_mistake(y.shape, x.shape, K.shape)}"
        )
    return check_array(y, "conv2d_forward", expected, what)


def forward_mistakes(x, K, b) -> dict:
    """{a plausible mistake in words: the output it gives}, for naming what a wrong output is."""
    kh, kw, C, F = K.shape
    mistakes = {
        "the kernel is flipped, a true convolution (x[i − p, j − q], or K[kh − 1 − p, kw − 1 − q]): the convolution "
        "of deep learning is a cross-correlation, y[i, j] = b + Σ x[i + p, j + q] K[p, q], the kernel as it is": (
            conv2d_by_definition(x, K[::-1, ::-1], b)
        ),
        "the bias is missing: b[f] is added to every output pixel of filter f": conv2d_by_definition(x, K, 0 * b),
    }
    if kh == kw:
        mistakes["the kernel's two spatial axes are swapped: K[p, q] weighs x[i + p, j + q], p down and q across"] = (
            conv2d_by_definition(x, K.transpose(1, 0, 2, 3), b)
        )
    if C == F:
        mistakes[
            "the kernel's channel axes are read the wrong way round: K is (kh, kw, C, F), and K[p, q, c, f] weighs "
            "input channel c in output channel f"
        ] = conv2d_by_definition(x, K.transpose(0, 1, 3, 2), b)
    return mistakes


def named(got, mistakes: dict) -> str | None:
    for words, value in mistakes.items():
        if value.shape == got.shape and np.allclose(got, value, rtol=1e-6, atol=1e-9):
            return words
    return None


def check_forward(y, x, K, b, what: str) -> None:
    check_output(y, x, K, what)
    expected = conv2d_by_definition(x, K, b)
    if not np.allclose(y, expected, rtol=1e-6, atol=1e-9):
        words = named(y, forward_mistakes(x, K, b))
        assert words is None, f"conv2d_forward: {what} is wrong: {words}"
    check_close(
        y,
        expected,
        "conv2d_forward",
        what,
        where=lambda i: f"image {i[0]}, output pixel ({i[1]}, {i[2]}), filter {i[3]}",
    )


# the forward pass


def test_conv2d_forward_with_a_one_by_one_kernel_mixes_the_channels(student, rng):
    # a 1×1 kernel sees one pixel: at every pixel, the C input channels times the (C, F) matrix K[0, 0], plus b
    x, K, b = rng.normal(size=(2, 3, 4, 3)), rng.normal(size=(1, 1, 3, 3)), rng.normal(size=3)
    y = call_checking_inputs(student.conv2d_forward, "conv2d_forward", x, K, b)
    check_forward(y, x, K, b, "the output of a 1×1 kernel (y[n, i, j, :] = x[n, i, j, :] K[0, 0] + b at every pixel)")


def test_conv2d_forward_by_hand(student):
    x = np.array([[1.0, 2.0, 0.0, 1.0], [0.0, 1.0, 3.0, 1.0], [2.0, 0.0, 1.0, 0.0]]).reshape(1, 3, 4, 1)
    K = np.array([[1.0, 0.0], [2.0, -1.0]]).reshape(2, 2, 1, 1)
    b = np.array([0.5])
    y = student.conv2d_forward(x, K, b)
    check_output(y, x, K, "the output of a 3×4 image and a 2×2 kernel")
    # y[i, j] = x[i, j] + 2 x[i + 1, j] − x[i + 1, j + 1] + 0.5
    expected = np.array([[0.5, 1.5, 5.5], [4.5, 0.5, 5.5]]).reshape(1, 2, 3, 1)
    if not np.allclose(y, expected):
        words = named(y, forward_mistakes(x, K, b))
        assert words is None, f"conv2d_forward: the output of a 3×4 image and a 2×2 kernel is wrong: {words}"
    check_close(
        y,
        expected,
        "conv2d_forward",
        "the output of the image [[1, 2, 0, 1], [0, 1, 3, 1], [2, 0, 1, 0]] and the kernel [[1, 0], [2, −1]], b = 0.5",
        where=lambda i: f"output pixel ({i[1]}, {i[2]}), which sees x[{i[1]}:{i[1] + 2}, {i[2]}:{i[2] + 2}]",
    )


def test_conv2d_forward_of_one_lit_pixel_writes_the_kernel_rotated(student):
    # a cross-correlation around one lit pixel: the output pixel (i, j) sees it at offset (2 − i, 2 − j)
    x = np.zeros((1, 5, 5, 1))
    x[0, 2, 2, 0] = 1.0
    K = np.arange(1.0, 10.0).reshape(3, 3, 1, 1)
    y = student.conv2d_forward(x, K, np.zeros(1))
    check_forward(
        y, x, K, np.zeros(1), "the output around one lit pixel (K rotated by 180°, as y[i, j] = K[2 − i, 2 − j])"
    )


SHAPES = [
    ((3, 7, 9, 2), (2, 3, 2, 4)),  # a batch of non-square images, a non-square kernel, C ≠ F
    ((2, 5, 5, 3), (3, 3, 3, 1)),  # one filter
    ((1, 4, 6, 1), (4, 6, 1, 2)),  # the kernel as large as the image: one output pixel
    ((2, 6, 4, 4), (1, 1, 4, 3)),  # a 1×1 kernel
    ((2, 10, 10, 4), (3, 3, 4, 16)),  # MinAtar's frame and the network's first layer
]


@pytest.mark.parametrize("x_shape, K_shape", SHAPES, ids=lambda s: "x".join(map(str, s)))
def test_conv2d_forward_matches_the_definition(student, rng, x_shape, K_shape):
    x, K, b = rng.normal(size=x_shape), rng.normal(size=K_shape), rng.normal(size=K_shape[-1])
    y = call_checking_inputs(student.conv2d_forward, "conv2d_forward", x, K, b)
    check_forward(y, x, K, b, f"the output for x {x_shape} and K {K_shape}")


# the backward pass


def backward_result(result, x, K, grad_y, need_grad_x=True):
    """The three gradients, each checked for its shape and dtype."""
    assert isinstance(result, tuple) and len(result) == 3, "conv2d_backward: return (grad_x, grad_K, grad_b)"
    grad_x, grad_K, grad_b = result
    if need_grad_x:
        check_array(grad_x, "conv2d_backward", x.shape, "grad_x (one entry per input number)")
    check_array(grad_K, "conv2d_backward", K.shape, "grad_K (one entry per kernel weight)")
    F = K.shape[-1]
    check_array(
        grad_b, "conv2d_backward", (F,), "grad_b (one entry per filter, summed over the batch and every position)"
    )
    return grad_x, grad_K, grad_b


def test_conv2d_backward_sums_the_bias_gradient_over_the_batch_and_the_positions(student, rng):
    x, K = rng.normal(size=(2, 4, 5, 3)), rng.normal(size=(2, 2, 3, 4))
    grad_y = rng.normal(size=(2, 3, 4, 4))
    result = call_checking_inputs(student.conv2d_backward, "conv2d_backward", x, K, grad_y)
    _, _, grad_b = backward_result(result, x, K, grad_y)
    check_close(
        grad_b,
        np.array([grad_y[..., f].sum() for f in range(4)]),
        "conv2d_backward",
        "grad_b (b[f] is added at each of the 2 × 3 × 4 output pixels of filter f, so its gradient sums all 24)",
        n=24,
    )


def test_conv2d_backward_input_gradient_adds_overlaps(student):
    # kernel and ∂L/∂y all ones: each input pixel's gradient counts the output pixels whose receptive field holds it
    x, K, grad_y = np.zeros((1, 4, 4, 1)), np.ones((3, 3, 1, 1)), np.ones((1, 2, 2, 1))
    grad_x, _, _ = backward_result(student.conv2d_backward(x, K, grad_y), x, K, grad_y)
    counts = np.array([[1.0, 2.0, 2.0, 1.0], [2.0, 4.0, 4.0, 2.0], [2.0, 4.0, 4.0, 2.0], [1.0, 2.0, 2.0, 1.0]])
    assert not np.allclose(grad_x[0, :, :, 0], np.ones((4, 4))), (
        "conv2d_backward: with a 3×3 kernel of ones and ∂L/∂y of ones, grad_x is 1 everywhere, where it should count "
        "the output pixels that see each input pixel (4 at the centre): an input pixel in several receptive fields "
        "collects the gradient of each, so overlapping patches add up (+=), they do not overwrite each other (=)"
    )
    check_close(
        grad_x[0, :, :, 0],
        counts,
        "conv2d_backward",
        "grad_x with a 3×3 kernel of ones and ∂L/∂y of ones (at each input pixel, the number of output pixels that "
        "see it)",
    )


def wrong_places(got, expected) -> bool:
    """The right numbers in the wrong order: a transpose or a reshape in the wrong order."""
    return not np.allclose(got, expected, rtol=1e-5, atol=1e-7) and np.allclose(
        np.sort(got, axis=None), np.sort(expected, axis=None), rtol=1e-5, atol=1e-7
    )


FD_SHAPES = [
    ((2, 5, 4, 2), (3, 3, 2, 4)),
    ((3, 4, 5, 2), (2, 3, 2, 3)),  # non-square image and kernel
    ((1, 3, 3, 1), (3, 3, 1, 2)),  # one output pixel
]


@pytest.mark.parametrize("x_shape, K_shape", FD_SHAPES, ids=lambda s: "x".join(map(str, s)))
def test_conv2d_backward_matches_finite_differences(student, rng, x_shape, K_shape):
    x, K, b = rng.normal(size=x_shape), rng.normal(size=K_shape), rng.normal(size=K_shape[-1])
    weights = rng.normal(size=output_shape(x_shape, K_shape))  # L = Σ weights ⊙ y, so ∂L/∂y = weights
    n, out_pixels = x_shape[0], weights[..., 0].size

    def loss():
        return float(np.sum(weights * conv2d_by_definition(x, K, b)))

    result = call_checking_inputs(student.conv2d_backward, "conv2d_backward", x, K, weights)
    grad_x, grad_K, grad_b = backward_result(result, x, K, weights)
    shapes = f"x {x_shape} and K {K_shape}"

    check_close(
        grad_b, numerical_gradient(loss, b), "conv2d_backward", f"grad_b for {shapes}", 1e-5, 1e-7, n=out_pixels
    )

    expected_K = numerical_gradient(loss, K)
    assert not wrong_places(grad_K, expected_K), (
        f"conv2d_backward: grad_K for {shapes} holds the right numbers in the wrong places: ∂L/∂K[p, q, c, f] = "
        "Σ x[n, i + p, j + q, c] ∂L/∂y[n, i, j, f] has K's own axes (kh, kw, C, F); a (kh·kw·C, F) matrix reshapes "
        "to K's shape as it is, an (F, kh·kw·C) one must be transposed first"
    )
    check_close(
        grad_K,
        expected_K,
        "conv2d_backward",
        f"grad_K for {shapes} (checked by finite differences; it sums over the batch and every output pixel)",
        1e-5,
        1e-7,
        where=lambda i: f"kernel offset (p, q) = ({i[0]}, {i[1]}), input channel {i[2]}, filter {i[3]}",
        n=n,
    )

    expected_x = numerical_gradient(loss, x)
    flipped = grad_x_by_definition(K[::-1, ::-1], weights, x.shape)
    assert np.allclose(grad_x, expected_x, rtol=1e-5, atol=1e-7) or not np.allclose(grad_x, flipped), (
        f"conv2d_backward: grad_x for {shapes} uses the kernel flipped: ∂L/∂x[a, e] = Σ ∂L/∂y[a − p, e − q] K[p, q], "
        "the output pixel that sees x[a, e] through the kernel's weight K[p, q] is (a − p, e − q); sliding K over "
        "∂L/∂y as the forward pass slides it over x pairs ∂L/∂y[a − p] with K[kh − 1 − p]"
    )
    check_close(
        grad_x,
        expected_x,
        "conv2d_backward",
        f"grad_x for {shapes} (checked by finite differences)",
        1e-5,
        1e-7,
        where=lambda i: f"image {i[0]}, input pixel ({i[1]}, {i[2]}), channel {i[3]}",
    )


def test_conv2d_backward_without_the_input_gradient(student, rng):
    # the first layer's input is the observation, which needs no gradient: need_grad_x=False skips it
    x, K, grad_y = rng.normal(size=(2, 5, 4, 2)), rng.normal(size=(2, 2, 2, 3)), rng.normal(size=(2, 4, 3, 3))
    grad_x, grad_K, grad_b = backward_result(
        student.conv2d_backward(x, K, grad_y, need_grad_x=False), x, K, grad_y, False
    )
    assert grad_x is None, (
        "conv2d_backward: with need_grad_x=False, grad_x should be None (the contract), not "
        + _harness.describe_value(grad_x)
    )
    _, full_K, full_b = conv.conv2d_backward(x, K, grad_y)
    check_close(grad_K, full_K, "conv2d_backward", "grad_K with need_grad_x=False (the same as with it)", 1e-9, 1e-12)
    check_close(grad_b, full_b, "conv2d_backward", "grad_b with need_grad_x=False (the same as with it)", 1e-9, 1e-12)


def test_conv2d_matches_minippo_at_the_minatar_network_size(student, rng):
    # two 10×10 MinAtar frames with 4 channels of 0s and 1s, the network's 16 filters of 3×3
    x = (rng.random((2, 10, 10, 4)) < 0.2).astype(np.float64)
    K, b, grad_y = rng.normal(size=(3, 3, 4, 16)), rng.normal(size=16), rng.normal(size=(2, 8, 8, 16))
    what = "for two 10×10 frames with 4 channels and 16 filters of 3×3 (checked against minippo.conv)"
    y = check_output(student.conv2d_forward(x, K, b), x, K, f"the output {what}")
    check_close(y, conv.conv2d_forward(x, K, b), "conv2d_forward", f"the output {what}", 1e-9, 1e-12)
    grads = backward_result(student.conv2d_backward(x, K, grad_y), x, K, grad_y)
    for got, expected, name in zip(grads, conv.conv2d_backward(x, K, grad_y), ("grad_x", "grad_K", "grad_b")):
        check_close(got, expected, "conv2d_backward", f"{name} {what}", 1e-9, 1e-12)


# the transfer task: max pooling's backward pass


def max_pool(x, size):
    n, H, W, C = x.shape
    return x.reshape(n, H // size, size, W // size, size, C).max(axis=(2, 4))


def test_max_pool2d_backward_of_one_window(student):
    x = np.array([[1.0, 5.0], [3.0, 2.0]]).reshape(1, 2, 2, 1)
    grad_y = np.array([7.0]).reshape(1, 1, 1, 1)
    grad_x = call_checking_inputs(student.max_pool2d_backward, "max_pool2d_backward", x, 2, grad_y)
    grad_x = check_array(grad_x, "max_pool2d_backward", (1, 2, 2, 1), "∂L/∂x")
    got = grad_x[0, :, :, 0]
    mistakes = {
        "the gradient spread evenly over the window, as an average pool's": np.full((2, 2), 7.0 / 4),
        "the gradient copied to every pixel of the window": np.full((2, 2), 7.0),
        "the window read transposed (p and q swapped)": np.array([[0.0, 0.0], [7.0, 0.0]]),
    }
    for words, wrong in mistakes.items():
        if np.allclose(got, wrong):
            raise AssertionError(
                f"max_pool2d_backward: for one 2 × 2 window [[1, 5], [3, 2]] with ∂L/∂y = 7 the gradient should be "
                f"[[0, 7], [0, 0]] (only the maximum, 5, reaches y), not {got.tolist()}: {words}?"
            )
    check_close(got, [[0.0, 7.0], [0.0, 0.0]], "max_pool2d_backward", "∂L/∂x for the window [[1, 5], [3, 2]]")


def test_max_pool2d_backward_at_a_tie(student):
    x = np.array([[4.0, 1.0], [4.0, 4.0]]).reshape(1, 2, 2, 1)
    grad_x = student.max_pool2d_backward(x, 2, np.array([3.0]).reshape(1, 1, 1, 1))
    got = check_array(grad_x, "max_pool2d_backward", (1, 2, 2, 1), "∂L/∂x at a tie")[0, :, :, 0]
    assert np.allclose(got, [[3.0, 0.0], [0.0, 0.0]]), (
        f"max_pool2d_backward: for the window [[4, 1], [4, 4]], whose maximum 4 is reached three times, the gradient 3 "
        f"should go to the first in row-major order only, [[3, 0], [0, 0]], not {got.tolist()}"
        + (": to every pixel that ties for the maximum?" if np.allclose(got, [[3.0, 0.0], [3.0, 3.0]]) else "")
        + (": to the last of them, not the first?" if np.allclose(got, [[0.0, 0.0], [0.0, 3.0]]) else "")
    )


def test_max_pool2d_backward_matches_finite_differences(student, rng):
    x = rng.standard_normal((2, 4, 6, 3))
    grad_y = rng.standard_normal((2, 2, 3, 3))
    grad_x = check_array(student.max_pool2d_backward(x, 2, grad_y), "max_pool2d_backward", x.shape, "∂L/∂x")
    xx = x.copy()
    numeric = numerical_gradient(lambda: float(np.sum(grad_y * max_pool(xx, 2))), xx, 1e-6)
    check_close(grad_x, numeric, "max_pool2d_backward", "∂L/∂x (finite differences), 2 × 2 windows", 1e-5, 1e-8)
    x3 = rng.standard_normal((1, 6, 3, 2))
    grad_y3 = rng.standard_normal((1, 2, 1, 2))
    numeric = numerical_gradient(lambda: float(np.sum(grad_y3 * max_pool(x3, 3))), x3, 1e-6)
    check_close(check_array(student.max_pool2d_backward(x3, 3, grad_y3), "max_pool2d_backward", x3.shape, "∂L/∂x"),
                numeric, "max_pool2d_backward", "∂L/∂x (finite differences), 3 × 3 windows on a 6 × 3 image",
                1e-5, 1e-8)  # fmt: skip
