"""Grading chapter 5: the clipped term against a direct clip and finite differences; the clip fraction by counting."""

import _harness
import numpy as np
import pytest
from _harness import call_checking_inputs, check_array, check_close, check_scalar, numerical_gradient

student = _harness.student  # the fixture: the implementation under test (see _harness.py)
pytest_generate_tests = _harness.pytest_generate_tests  # one run per wrong variant under MINIPPO_IMPL=wrong
rng = _harness.rng  # a seeded NumPy Generator

pytestmark = pytest.mark.timeout(10)

# ratios across and beyond the band of every ε used here, away from its edges (where the gradient jumps)
RATIOS = np.array([0.4, 0.65, 0.75, 0.86, 0.95, 1.0, 1.04, 1.15, 1.26, 1.35, 1.7, 2.5])


@pytest.fixture
def batch(rng):
    logp_old = rng.normal(-1.0, 0.6, len(RATIOS))
    advantages = rng.choice([-1.0, 1.0], len(RATIOS)) * rng.uniform(0.2, 2.0, len(RATIOS))
    return np.log(RATIOS) + logp_old, logp_old, advantages


def clip(r, low, high):
    return low if r < low else high if r > high else r


@pytest.mark.parametrize("epsilon", [0.1, 0.2, 0.3])
def test_clipped_surrogate_value_and_gradient(student, batch, epsilon):
    logp, logp_old, advantages = batch
    value, grad = call_checking_inputs(
        student.clipped_surrogate, "clipped_surrogate", logp, logp_old, advantages, epsilon
    )
    expected = sum(clip(r, 1 - epsilon, 1 + epsilon) * a for r, a in zip(RATIOS, advantages)) / len(RATIOS)
    check_close(check_scalar(value, "clipped_surrogate"), expected, "clipped_surrogate", "the value Ê[clip(r) Â]")
    check_array(grad, "clipped_surrogate", (len(RATIOS),), "the gradient")
    numeric = numerical_gradient(
        lambda: float(student.clipped_surrogate(logp, logp_old, advantages, epsilon)[0]), logp, 1e-7
    )
    check_close(grad, numeric, "clipped_surrogate", "∂/∂ log π (checked by finite differences of the value)")


def test_clipped_surrogate_gradient_vanishes_outside_the_band(student, batch):
    logp, logp_old, advantages = batch
    _, grad = student.clipped_surrogate(logp, logp_old, advantages, 0.2)
    outside = np.abs(RATIOS - 1) > 0.2
    assert np.all(grad[outside] == 0), "clipped_surrogate: the gradient should be 0 where r is outside [1−ε, 1+ε]"
    check_close(
        grad[~outside],
        (RATIOS * advantages)[~outside] / len(RATIOS),
        "clipped_surrogate",
        "the gradient inside the band (it should be r_t Â_t / n)",
    )


def test_clipped_surrogate_single_sample(student):
    for ratio, expected_value, expected_grad in [(1.5, 1.2, 0.0), (0.9, 0.9, 0.9), (0.5, 0.8, 0.0)]:
        value, grad = student.clipped_surrogate(np.log([ratio]), np.zeros(1), np.ones(1), 0.2)
        check_close(
            check_scalar(value, "clipped_surrogate"),
            expected_value,
            "clipped_surrogate",
            f"the value for one sample with r = {ratio}, Â = 1",
        )
        check_close(grad, [expected_grad], "clipped_surrogate", f"the gradient for one sample with r = {ratio}, Â = 1")


def test_clip_fraction_counts_ratios_outside_the_band(student, batch):
    logp, logp_old, _ = batch
    for epsilon in (0.1, 0.2, 0.3):
        fraction = call_checking_inputs(student.clip_fraction, "clip_fraction", logp, logp_old, epsilon)
        count = sum(1 for r in RATIOS if r < 1 - epsilon or r > 1 + epsilon)
        check_close(
            check_scalar(fraction, "clip_fraction"),
            count / len(RATIOS),
            "clip_fraction",
            f"the fraction outside the band for ε = {epsilon}",
        )


def test_clip_fraction_extremes(student):
    check_close(
        check_scalar(student.clip_fraction(np.zeros(4), np.zeros(4), 0.2), "clip_fraction"),
        0.0,
        "clip_fraction",
        "the fraction at θ = θ_old (every r = 1)",
    )
    logp = np.log([0.5, 2.0, 0.1, 5.0])
    check_close(
        check_scalar(student.clip_fraction(logp, np.zeros(4), 0.2), "clip_fraction"),
        1.0,
        "clip_fraction",
        "the fraction when every ratio is far outside the band on either side",
    )
