"""Grading chapter 6: L^CLIP against a per-sample min, its pessimism, and where its gradient must and must not vanish.

A clipped term without the min, a max in its place, or a min over the ratios instead of the products all fail here.
"""

import _harness
import numpy as np
import pytest
from _harness import call_checking_inputs, check_array, check_close, check_scalar, numerical_gradient

student = _harness.student  # the fixture: the implementation under test (see _harness.py)
pytest_generate_tests = _harness.pytest_generate_tests  # one run per wrong variant under MINIPPO_IMPL=wrong
rng = _harness.rng  # a seeded NumPy Generator

pytestmark = pytest.mark.timeout(10)

RATIOS = np.array([0.4, 0.65, 0.75, 0.86, 0.95, 1.0, 1.04, 1.15, 1.26, 1.35, 1.7, 2.5])
SIGNS = np.array([1, -1, 1, -1, 1, -1, 1, -1, 1, -1, 1, -1, -1, 1, -1, 1, -1, 1, -1, 1, -1, 1, -1, 1])


@pytest.fixture
def batch(rng):
    # every ratio twice, once with Â > 0 and once with Â < 0
    ratios = np.concatenate([RATIOS, RATIOS])
    logp_old = rng.normal(-1.0, 0.6, len(ratios))
    advantages = SIGNS * rng.uniform(0.2, 2.0, len(ratios))
    return np.log(ratios) + logp_old, logp_old, advantages, ratios


def per_sample_min(ratio, advantage, epsilon):
    clipped = min(max(ratio, 1 - epsilon), 1 + epsilon)
    return min(ratio * advantage, clipped * advantage)


@pytest.mark.parametrize("epsilon", [0.1, 0.2, 0.3])
def test_clip_objective_value_and_gradient(student, batch, epsilon):
    logp, logp_old, advantages, ratios = batch
    value, grad = call_checking_inputs(student.clip_objective, "clip_objective", logp, logp_old, advantages, epsilon)
    expected = np.mean([per_sample_min(r, a, epsilon) for r, a in zip(ratios, advantages)])
    check_close(
        check_scalar(value, "clip_objective"), expected, "clip_objective", "the value Ê[min(r Â, clip(r, 1−ε, 1+ε) Â)]"
    )
    check_array(grad, "clip_objective", (len(ratios),), "the gradient")
    numeric = numerical_gradient(
        lambda: float(student.clip_objective(logp, logp_old, advantages, epsilon)[0]), logp, 1e-7
    )
    check_close(grad, numeric, "clip_objective", "∂L^CLIP/∂ log π (checked by finite differences of the value)")


def test_clip_objective_is_never_above_the_unclipped_objective(student):
    generator = np.random.default_rng(7)
    for trial in range(50):
        n = int(generator.integers(1, 30))
        logp_old = generator.normal(-1.0, 1.0, n)
        logp = logp_old + generator.normal(0, 0.5, n)
        advantages = generator.normal(size=n)
        value, _ = student.clip_objective(logp, logp_old, advantages, 0.2)
        unclipped = float(np.mean(np.exp(logp - logp_old) * advantages))
        assert check_scalar(value, "clip_objective") <= unclipped + 1e-12, (
            f"clip_objective: L^CLIP should never be above L^CPI = Ê[r Â] (a pessimistic bound), but on random batch "
            f"{trial} it is {value:.6g} > {unclipped:.6g}"
        )


def test_clip_gradient_is_zero_past_the_band_in_the_helped_direction(student, batch):
    logp, logp_old, advantages, ratios = batch
    _, grad = student.clip_objective(logp, logp_old, advantages, 0.2)
    check_array(grad, "clip_objective", (len(ratios),), "the gradient")
    too_high = (ratios > 1.2) & (advantages > 0)
    too_low = (ratios < 0.8) & (advantages < 0)
    assert np.all(grad[too_high] == 0), (
        "clip_objective: the gradient should be 0 where the ratio is above 1+ε and Â > 0 (nothing more to gain there)"
    )
    assert np.all(grad[too_low] == 0), (
        "clip_objective: the gradient should be 0 where the ratio is below 1−ε and Â < 0 (nothing more to gain there)"
    )


def test_clip_gradient_keeps_the_hurt_direction(student, batch):
    # past the band in the direction that makes things worse, the unclipped term is the min: its full gradient stays
    logp, logp_old, advantages, ratios = batch
    _, grad = student.clip_objective(logp, logp_old, advantages, 0.2)
    hurt = ((ratios > 1.2) & (advantages < 0)) | ((ratios < 0.8) & (advantages > 0))
    expected = ratios * advantages / len(ratios)
    assert np.all(grad[hurt] != 0), (
        "clip_objective: the gradient should not vanish where the ratio is above 1+ε with Â < 0 or below 1−ε with "
        "Â > 0: there the min picks the unclipped term, so a move that made things worse can be undone"
    )
    check_close(
        grad[hurt],
        expected[hurt],
        "clip_objective",
        "the gradient past the band in the hurt direction (it should be r_t Â_t / n)",
    )


def test_clip_objective_equals_cpi_inside_the_band(student, rng):
    logp_old = rng.normal(-1.0, 0.5, 8)
    ratios = rng.uniform(0.85, 1.15, 8)
    advantages = rng.normal(size=8)
    value, grad = student.clip_objective(np.log(ratios) + logp_old, logp_old, advantages, 0.2)
    check_close(
        check_scalar(value, "clip_objective"),
        np.mean(ratios * advantages),
        "clip_objective",
        "the value when every ratio is inside the band (it should equal Ê[r Â])",
    )
    check_close(grad, ratios * advantages / 8, "clip_objective", "the gradient inside the band (r_t Â_t / n)")


@pytest.mark.parametrize(
    "ratio, advantage, expected_value, expected_grad",
    [(1.5, 1.0, 1.2, 0.0), (1.5, -1.0, -1.5, -1.5), (0.5, -1.0, -0.8, 0.0), (0.5, 1.0, 0.5, 0.5), (1.1, 2.0, 2.2, 2.2)],
    ids=["above-helped", "above-hurt", "below-helped", "below-hurt", "inside"],
)
def test_clip_objective_single_sample(student, ratio, advantage, expected_value, expected_grad):
    value, grad = student.clip_objective(np.log([ratio]) - 900.0, np.array([-900.0]), np.array([advantage]), 0.2)
    where = f"one sample with r = {ratio}, Â = {advantage} (log-probabilities near −900)"
    check_close(check_scalar(value, "clip_objective"), expected_value, "clip_objective", f"the value for {where}")
    check_array(grad, "clip_objective", (1,), f"the gradient for {where}")
    check_close(grad, [expected_grad], "clip_objective", f"the gradient for {where}")
