"""Grading chapter 3: L^PG against its sum and finite differences; advantage normalisation and its edge cases."""

import _harness
import numpy as np
import pytest
from _harness import call_checking_inputs, check_array, check_close, check_scalar, numerical_gradient

student = _harness.student  # the fixture: the implementation under test (see _harness.py)
pytest_generate_tests = _harness.pytest_generate_tests  # one run per wrong variant under MINIPPO_IMPL=wrong
rng = _harness.rng  # a seeded NumPy Generator

pytestmark = pytest.mark.timeout(10)


@pytest.mark.parametrize("n", [1, 9])
def test_pg_objective_value_and_gradient(student, rng, n):
    logp, advantages = rng.normal(-1.5, 0.7, n), rng.normal(size=n)
    value, grad = call_checking_inputs(student.pg_objective, "pg_objective", logp, advantages)
    total = 0.0
    for t in range(n):
        total += logp[t] * advantages[t]
    check_close(check_scalar(value, "pg_objective"), total / n, "pg_objective", "the value Ê[log π · Â]")
    check_array(grad, "pg_objective", (n,), "the gradient")
    expected = numerical_gradient(lambda: float(student.pg_objective(logp, advantages)[0]), logp)
    check_close(grad, expected, "pg_objective", "∂L/∂ log π (checked by finite differences of the value)")
    check_close(grad, advantages / n, "pg_objective", "∂L/∂ log π (it should be Â_t / n)")


def test_pg_objective_with_very_negative_log_probs(student):
    logp = np.array([-700.0, -1200.0, -3.0])
    value, grad = student.pg_objective(logp, np.array([1.0, -2.0, 0.5]))
    check_close(check_scalar(value, "pg_objective"), (-700.0 + 2400.0 - 1.5) / 3, "pg_objective", "the value")
    check_array(grad, "pg_objective", (3,), "the gradient")


def test_normalize_advantages_gives_mean_zero_and_std_one(student, rng):
    advantages = rng.normal(3.0, 5.0, 12)
    normalized = call_checking_inputs(student.normalize_advantages, "normalize_advantages", advantages)
    check_array(normalized, "normalize_advantages", (12,))
    mean = sum(normalized) / 12
    std = np.sqrt(sum((x - mean) ** 2 for x in normalized) / 12)
    assert abs(mean) < 1e-9, f"normalize_advantages: the mean should be 0, not {mean:.3g} (subtract the mean)"
    hint = " (np.std is the population standard deviation, ddof = 0)" if abs(std - np.sqrt(11 / 12)) < 1e-6 else ""
    assert abs(std - 1.0) < 1e-6, f"normalize_advantages: the standard deviation should be 1, not {std:.6g}{hint}"
    assert np.all(np.argsort(normalized) == np.argsort(advantages)), "normalize_advantages: the order must not change"


def test_normalize_advantages_with_a_tiny_spread(student, rng):
    # std Â = 1e-4: (Â − mean)/(std + 1e-8) is still about ±1, while √(var + 1e-8) would shrink it by 1/√2
    advantages = rng.normal(size=6)
    advantages = 2.0 + 1e-4 * (advantages - advantages.mean()) / advantages.std()
    normalized = check_array(student.normalize_advantages(advantages), "normalize_advantages", (6,))
    centred = advantages - advantages.mean()
    expected = centred / (advantages.std() + 1e-8)
    if np.allclose(normalized, expected, rtol=1e-3, atol=1e-9):  # a guard against std = 0 in place of 1e-8 passes
        return
    in_root = centred / np.sqrt(advantages.var() + 1e-8)
    hint = (
        ": the 1e-8 is added to the variance inside the square root, √(var + 1e-8); the contract adds it to the "
        "standard deviation, std + 1e-8, which matters only when the spread is this small"
        if np.allclose(normalized, in_root, rtol=1e-3)
        else ""
    )
    worst = int(np.argmax(np.abs(normalized - expected)))
    raise AssertionError(
        f"normalize_advantages: for advantages with a tiny spread (std Â = 1e-4) the result should be "
        f"(Â − mean Â)/(std Â + 1e-8), about ±1, but at index {worst} it is {normalized[worst]:.6g}, not "
        f"{expected[worst]:.6g}{hint}"
    )


def test_normalize_advantages_ignores_shift_and_scale(student, rng):
    advantages = rng.normal(size=8)
    check_close(
        student.normalize_advantages(4.0 * advantages + 7.0),
        student.normalize_advantages(advantages),
        "normalize_advantages",
        "the result for 4Â + 7 (it should equal the result for Â)",
        1e-6,
        1e-7,
    )


def test_normalize_advantages_edge_cases(student):
    single = call_checking_inputs(student.normalize_advantages, "normalize_advantages", np.array([2.5]))
    check_array(single, "normalize_advantages", (1,), "the result for a single sample")
    check_close(single, [2.5], "normalize_advantages", "a single sample (it should be returned unchanged)")
    equal = student.normalize_advantages(np.full(5, 3.0))
    check_array(equal, "normalize_advantages", (5,), "the result for equal advantages (no NaN: add 1e-8 to std)")
    check_close(equal, np.zeros(5), "normalize_advantages", "equal advantages (they should become zeros)")


# the transfer task: the policy gradient of a linear softmax policy, in its parameters


@pytest.fixture
def linear_policy_case(rng):
    return rng.standard_normal((7, 3)), rng.normal(0, 0.8, (3, 4)), rng.integers(0, 4, 7), rng.standard_normal(7)


def test_linear_softmax_policy_gradient_with_one_sample(student):
    features, theta = np.array([[1.0, 2.0]]), np.zeros((2, 2))
    result = _harness.call_checking_inputs(
        student.linear_softmax_policy_gradient, "linear_softmax_policy_gradient", features, theta, np.array([0]),
        np.array([1.0]),
    )  # fmt: skip
    assert isinstance(result, tuple) and len(result) == 2, "linear_softmax_policy_gradient should return (value, grad)"
    _harness.expect_number(
        result[0], np.log(0.5), "linear_softmax_policy_gradient", "L^PG for one sample, θ = 0, two actions, Â = 1",
        "log π(a|s) Â with π uniform",
    )  # fmt: skip
    grad = _harness.check_array(result[1], "linear_softmax_policy_gradient", (2, 2), "the gradient")
    # ∂ log π(0|s)/∂θ[:, j] = s (1[j = 0] − ½)
    expected = np.array([[0.5, -0.5], [1.0, -1.0]])
    mistakes = {
        "the score without its −π term, as if log π(a|s) were s θ[:, a]": np.array([[1.0, 0.0], [2.0, 0.0]]),
        "the gradient of π instead of log π": expected * 0.5,
        "the outer product taken as (score Â)ᵀ x, the transpose of the (d, k) gradient": np.array(
            [[0.5, 1.0], [-0.5, -1.0]]
        ),
    }
    for words, value in mistakes.items():
        if np.allclose(grad, value):
            raise AssertionError(
                f"linear_softmax_policy_gradient: for one sample s = (1, 2), θ = 0, a = 0, Â = 1 the gradient should "
                f"be {expected.tolist()}, not {grad.tolist()}: {words}?"
            )
    _harness.check_close(grad, expected, "linear_softmax_policy_gradient", "the gradient for s = (1, 2), θ = 0, a = 0")


def test_linear_softmax_policy_gradient_matches_finite_differences(student, linear_policy_case):
    features, theta, actions, advantages = linear_policy_case
    value, grad = student.linear_softmax_policy_gradient(features, theta, actions, advantages)
    logits = features @ theta
    log_probs = logits - np.log(np.exp(logits).sum(axis=1, keepdims=True))
    _harness.check_close(
        _harness.check_scalar(value, "linear_softmax_policy_gradient"),
        float(np.mean(log_probs[np.arange(7), actions] * advantages)),
        "linear_softmax_policy_gradient",
        "L^PG, the mean of log π(a_t|s_t) Â_t",
    )
    _harness.check_array(grad, "linear_softmax_policy_gradient", (3, 4), "the gradient")
    t = theta.copy()
    numeric = _harness.numerical_gradient(
        lambda: float(student.linear_softmax_policy_gradient(features, t, actions, advantages)[0]), t, 1e-6
    )
    _harness.check_close(
        grad, numeric, "linear_softmax_policy_gradient", "∂L^PG/∂θ (finite differences)", 1e-5, 1e-7, n=len(actions)
    )
