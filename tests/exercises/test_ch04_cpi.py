"""Grading chapter 4: the ratio from log-probabilities, and L^CPI against its sum and finite differences."""

import _harness
import numpy as np
import pytest
from _harness import call_checking_inputs, check_array, check_close, check_scalar, numerical_gradient

student = _harness.student  # the fixture: the implementation under test (see _harness.py)
pytest_generate_tests = _harness.pytest_generate_tests  # one run per wrong variant under MINIPPO_IMPL=wrong
rng = _harness.rng  # a seeded NumPy Generator

pytestmark = pytest.mark.timeout(10)


@pytest.fixture
def batch(rng):
    logp_old = rng.normal(-2.0, 0.5, 10)
    ratios = np.array([0.3, 0.6, 0.9, 1.0, 1.1, 1.5, 2.2, 0.75, 1.3, 3.0])
    return np.log(ratios) + logp_old, logp_old, rng.normal(size=10), ratios


def test_importance_ratio_is_the_probability_ratio(student, batch):
    logp, logp_old, _, _ = batch
    ratio = call_checking_inputs(student.importance_ratio, "importance_ratio", logp, logp_old)
    check_array(ratio, "importance_ratio", (10,))
    for mistake, value in [
        ("π_θold / π_θ, the inverse (log π and log π_old swapped?)", np.exp(logp_old - logp)),
        ("1 + (log π − log π_old), the first-order approximation of exp", 1.0 + (logp - logp_old)),
    ]:
        assert not np.allclose(ratio, value, rtol=1e-6), (
            f"importance_ratio: r = π_θ / π_θold = exp(log π − log π_old), but the result is {mistake}"
        )
    check_close(
        ratio,
        np.exp(logp) / np.exp(logp_old),
        "importance_ratio",
        "r = π_θ / π_θold",
        where={"log π − log π_old": logp - logp_old},
    )


def test_importance_ratio_with_very_negative_log_probs(student):
    ratio = student.importance_ratio(np.array([-800.0, -1500.0, -2.0]), np.array([-801.0, -1500.0, -2.0]))
    check_array(ratio, "importance_ratio", (3,), "the ratio when exp(log π) underflows (use exp of the difference)")
    check_close(ratio, [np.e, 1.0, 1.0], "importance_ratio", "the ratio for log-probabilities near −800")


@pytest.mark.parametrize("n", [1, 10])
def test_cpi_objective_value_and_gradient(student, batch, n):
    logp, logp_old, advantages, ratios = (x[:n] for x in batch)
    value, grad = call_checking_inputs(student.cpi_objective, "cpi_objective", logp, logp_old, advantages)
    expected_value = sum(r * a for r, a in zip(ratios, advantages)) / n
    check_close(check_scalar(value, "cpi_objective"), expected_value, "cpi_objective", "the value Ê[r Â]")
    check_array(grad, "cpi_objective", (n,), "the gradient")
    expected = numerical_gradient(lambda: float(student.cpi_objective(logp, logp_old, advantages)[0]), logp)
    check_close(
        grad,
        expected,
        "cpi_objective",
        "∂L/∂ log π (checked by finite differences of the value)",
        where={"r_t": ratios, "Â_t": advantages, "n": n},
    )
    check_close(
        grad,
        ratios * advantages / n,
        "cpi_objective",
        "∂L/∂ log π (it should be r_t Â_t / n)",
        where={"r_t": ratios, "Â_t": advantages, "n": n},
    )


def test_cpi_gradient_at_the_snapshot_is_the_policy_gradient(student, batch):
    _, logp_old, advantages, _ = batch
    _, grad = student.cpi_objective(logp_old, logp_old, advantages)
    check_close(grad, advantages / 10, "cpi_objective", "the gradient at θ = θ_old (it should be Â_t / n, like L^PG)")


def test_cpi_objective_with_very_negative_log_probs(student):
    value, grad = student.cpi_objective(np.array([-900.0, -901.0]), np.array([-901.0, -900.0]), np.array([1.0, 2.0]))
    check_close(check_scalar(value, "cpi_objective"), (np.e + 2 / np.e) / 2, "cpi_objective", "the value near −900")
    check_array(grad, "cpi_objective", (2,), "the gradient for log-probabilities near −900")


# the transfer task: self-normalised importance weights


@pytest.fixture
def weighted_case(rng):
    logp_old = rng.normal(-1.0, 0.5, 6)
    return logp_old + rng.normal(0.0, 0.4, 6), logp_old, rng.standard_normal(6)


def test_weighted_cpi_objective_value(student, weighted_case):
    logp, logp_old, advantages = weighted_case
    result = _harness.call_checking_inputs(
        student.weighted_cpi_objective, "weighted_cpi_objective", logp, logp_old, advantages
    )
    assert isinstance(result, tuple) and len(result) == 2, "weighted_cpi_objective should return (value, grad)"
    ratio = np.exp(logp - logp_old)
    _harness.expect_number(
        result[0], float(np.sum(ratio * advantages) / np.sum(ratio)), "weighted_cpi_objective", "the value",
        "Σ r Â / Σ r", alternatives={"L^CPI's mean of r Â": float(np.mean(ratio * advantages))},
    )  # fmt: skip


def test_weighted_cpi_gradient_sums_to_zero(student, weighted_case):
    # adding the same constant to every log π scales every r_t alike and leaves the value unchanged
    logp, logp_old, advantages = weighted_case
    _, grad = student.weighted_cpi_objective(logp, logp_old, advantages)
    grad = _harness.check_array(grad, "weighted_cpi_objective", (6,), "the gradient")
    ratio = np.exp(logp - logp_old)
    value = float(np.sum(ratio * advantages) / ratio.sum())
    mistakes = {
        "the denominator Σ r treated as a constant, though every r_t is in it": ratio * advantages / ratio.sum(),
        "L^CPI's gradient r Â / n, the weights' normalisation forgotten": ratio * advantages / len(ratio),
        "the quotient rule's second term added instead of subtracted": ratio / ratio.sum() * (advantages + value),
    }
    named = "".join(f": {words}?" for words, wrong in mistakes.items() if np.allclose(grad, wrong))
    assert abs(grad.sum()) < 1e-9, (
        f"weighted_cpi_objective: the gradient should sum to 0 over the batch (adding one constant to every log π "
        f"multiplies every r_t alike and leaves Σ r Â / Σ r unchanged), not to {grad.sum():.6g}{named}"
    )


def test_weighted_cpi_objective_matches_finite_differences(student, weighted_case):
    logp, logp_old, advantages = weighted_case
    _, grad = student.weighted_cpi_objective(logp, logp_old, advantages)
    x = logp.copy()
    numeric = _harness.numerical_gradient(
        lambda: float(student.weighted_cpi_objective(x, logp_old, advantages)[0]), x, 1e-6
    )
    _harness.check_close(grad, numeric, "weighted_cpi_objective", "∂/∂ log π (finite differences)", 1e-5, 1e-8)


def test_weighted_cpi_objective_with_very_negative_log_probs(student, weighted_case):
    logp, logp_old, advantages = weighted_case
    value, grad = student.weighted_cpi_objective(logp - 800.0, logp_old - 800.0, advantages)
    expected_value, expected_grad = student.weighted_cpi_objective(logp, logp_old, advantages)
    name = "weighted_cpi_objective"
    _harness.check_close(_harness.check_scalar(value, name), expected_value, name, "the value with log π near −800")
    _harness.check_close(_harness.check_array(grad, name, (6,)), expected_grad, name, "the gradient, log π near −800")
