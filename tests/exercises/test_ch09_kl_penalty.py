"""Grading chapter 9: the KL between two categoricals (brute force, Monte Carlo, finite differences), the penalised
surrogate, and eq. 8's rule for β case by case, including its boundaries."""

import _harness
import numpy as np
import pytest
from _harness import (
    call_checking_inputs,
    check_array,
    check_close,
    check_scalar,
    expect_number,
    numerical_gradient,
)

student = _harness.student  # the fixture: the implementation under test (see _harness.py)
pytest_generate_tests = _harness.pytest_generate_tests  # one run per wrong variant under MINIPPO_IMPL=wrong
rng = _harness.rng  # a seeded NumPy Generator

pytestmark = pytest.mark.timeout(10)


def softmax(logits):
    e = np.exp(logits - logits.max(axis=-1, keepdims=True))
    return e / e.sum(axis=-1, keepdims=True)


def reference_kl(logits_old, logits):
    p, q = softmax(logits_old), softmax(logits)
    return np.array([sum(pj * np.log(pj / qj) for pj, qj in zip(prow, qrow)) for prow, qrow in zip(p, q)])


@pytest.fixture
def pair(rng):
    return rng.normal(0, 1.0, (6, 4)), rng.normal(0, 1.0, (6, 4))


def test_categorical_kl_matches_the_sum(student, pair):
    logits_old, logits = pair
    kl = call_checking_inputs(student.categorical_kl, "categorical_kl", logits_old, logits)
    check_array(kl, "categorical_kl", (6,))
    check_close(
        kl,
        reference_kl(logits_old, logits),
        "categorical_kl",
        "KL[π_old ‖ π] = Σ π_old (log π_old − log π) (the old policy comes first)",
    )


def test_categorical_kl_matches_monte_carlo(student, rng):
    logits_old, logits = np.array([[2.0, 0.0, -1.0]]), np.array([[0.0, 1.0, 0.5]])
    kl = check_scalar(student.categorical_kl(logits_old, logits)[0], "categorical_kl")
    p, q = softmax(logits_old)[0], softmax(logits)[0]
    actions = rng.choice(3, size=200_000, p=p)  # samples of the old policy, as in a rollout
    estimate = float(np.mean(np.log(p[actions]) - np.log(q[actions])))
    assert abs(kl - estimate) < 0.01, (
        f"categorical_kl: sampling actions from π_old gives E[log π_old − log π] ≈ {estimate:.4f}, but the KL "
        f"returned is {kl:.4f}"
    )


def test_categorical_kl_is_zero_only_for_equal_policies(student, pair):
    logits_old, logits = pair
    same = student.categorical_kl(logits_old, logits_old + 3.0)  # adding a constant leaves the softmax unchanged
    check_close(same, np.zeros(6), "categorical_kl", "KL between a policy and itself (it should be 0)", atol=1e-12)
    kl = student.categorical_kl(logits_old, logits)
    assert np.all(kl > 0), "categorical_kl: the KL between two different policies should be positive"


def test_categorical_kl_survives_extreme_logits(student):
    logits_old = np.array([[1000.0, 0.0, -1000.0], [0.0, 0.0, 0.0]])
    logits = np.array([[0.0, 1000.0, 0.0], [0.0, 0.0, 0.0]])
    kl = student.categorical_kl(logits_old, logits)
    check_array(kl, "categorical_kl", (2,), "the KL for logits of ±1000 (work with log-softmax, not log of softmax)")
    check_close(kl, [1000.0, 0.0], "categorical_kl", "the KL for logits of ±1000")


def test_categorical_kl_backward_matches_finite_differences(student, pair, rng):
    logits_old, logits = pair
    grad_kl = rng.normal(size=6)
    grad = call_checking_inputs(student.categorical_kl_backward, "categorical_kl_backward", logits_old, logits, grad_kl)
    check_array(grad, "categorical_kl_backward", (6, 4))
    numeric = numerical_gradient(lambda: float(grad_kl @ reference_kl(logits_old, logits)), logits)
    check_close(
        grad, numeric, "categorical_kl_backward", "∂L/∂z of the new logits (checked by finite differences)", 1e-5, 1e-7
    )


def test_categorical_kl_backward_at_extreme_logits(student):
    logits_old = np.array([[1000.0, 999.0, 0.0], [0.0, 0.0, 0.0], [-1000.0, 0.0, 1000.0]])
    logits = np.array([[998.0, 1000.0, -1000.0], [900.0, 899.0, 0.0], [0.0, 0.0, 0.0]])
    grad_kl = np.array([1.0, -2.0, 0.5])
    grad = student.categorical_kl_backward(logits_old, logits, grad_kl)
    check_array(grad, "categorical_kl_backward", (3, 3), "∂L/∂z for logits near ±1000 (subtract each row's max)")
    check_close(
        grad,
        (softmax(logits) - softmax(logits_old)) * grad_kl[:, None],
        "categorical_kl_backward",
        "∂L/∂z = (π − π_old) ∂L/∂KL for logits near ±1000 (softmax after subtracting each row's max)",
        where=lambda i: f"row {i[0]}, z_old = {logits_old[i[0]].tolist()}, z = {logits[i[0]].tolist()}",
    )


@pytest.mark.parametrize("n, beta", [(1, 3.0), (8, 3.0), (8, 0.25)])
def test_kl_penalty_objective_value_and_gradients(student, rng, n, beta):
    logp_old = rng.normal(-1.0, 0.5, n)
    logp = logp_old + rng.normal(0, 0.3, n)
    advantages, kl = rng.normal(size=n), rng.uniform(0, 0.05, n)

    def reference():
        return float(np.mean(np.exp(logp - logp_old) * advantages - beta * kl))

    value, grad_logp, grad_kl = call_checking_inputs(
        student.kl_penalty_objective, "kl_penalty_objective", logp, logp_old, advantages, kl, beta
    )
    ratio = np.exp(logp - logp_old)
    expect_number(
        value,
        reference(),
        "kl_penalty_objective",
        f"the value Ê[r Â − β KL] (β = {beta}, n = {n})",
        alternatives={
            "the penalty added (+β KL); it enters with a minus": float(np.mean(ratio * advantages + beta * kl)),
            "the KL summed over the batch, not averaged": float(np.mean(ratio * advantages)) - beta * float(np.sum(kl))
            if n > 1
            else None,
            "log r Â in place of r Â": float(np.mean((logp - logp_old) * advantages - beta * kl)),
            "the KL penalty missing": float(np.mean(ratio * advantages)),
        },
    )
    check_array(grad_logp, "kl_penalty_objective", (n,), "∂L/∂ log π")
    check_array(grad_kl, "kl_penalty_objective", (n,), "∂L/∂KL")
    check_close(
        grad_logp, numerical_gradient(reference, logp), "kl_penalty_objective", "∂L/∂ log π (finite differences)"
    )
    check_close(
        grad_kl, numerical_gradient(reference, kl), "kl_penalty_objective", f"∂L/∂KL (it should be −β/n, β = {beta})"
    )


@pytest.mark.parametrize(
    "kl, expected, why",
    [  # well inside each of the three ranges first, then just beside the thresholds, then exactly on them
        (0.5, 0.5, "d < d_targ/1.5: β is halved"),
        (30.0, 2.0, "d > 1.5·d_targ: β is doubled, once"),
        (3.0, 1.0, "d = d_targ: β stays"),
        (2.5, 1.0, "d_targ/1.5 < d < d_targ: β stays; it is halved only below d_targ/1.5"),
        (3.9, 1.0, "d_targ < d < 1.5·d_targ: β stays; it is doubled only above 1.5·d_targ"),
        (1.99, 0.5, "d just below d_targ/1.5: β is halved"),
        (4.51, 2.0, "d just above 1.5·d_targ: β is doubled"),
        (2.0, 1.0, "d exactly d_targ/1.5: β stays"),
        (4.5, 1.0, "d exactly 1.5·d_targ: β stays"),
    ],
)
def test_adaptive_beta_rule(student, kl, expected, why):
    # d_targ = 3 makes the thresholds d_targ/1.5 = 2 and 1.5·d_targ = 4.5 exact in floating point
    beta = check_scalar(student.adaptive_beta(1.0, kl, 3.0), "adaptive_beta", "the new β")
    assert beta == pytest.approx(expected), (
        f"adaptive_beta: with d = {kl} and d_targ = 3 ({why}), β = 1 should become {expected}, not {beta:.6g}"
    )


def test_adaptive_beta_scales_the_current_beta(student):
    for beta, kl, expected in [(0.4, 0.001, 0.2), (0.4, 0.1, 0.8), (0.4, 0.01, 0.4), (7.0, 0.0, 3.5)]:
        new = check_scalar(student.adaptive_beta(beta, kl, 0.01), "adaptive_beta", "the new β")
        assert new == pytest.approx(expected), (
            f"adaptive_beta: with β = {beta}, d = {kl} and d_targ = 0.01, the new β should be {expected}, not {new:.6g}"
        )


# the transfer task: the reverse KL, KL[π ‖ π_old], and its gradient


def test_reverse_kl_of_two_actions(student):
    # π_old = (½, ½), π = softmax(log 3, 0) = (¾, ¼): KL[π ‖ π_old] = ¾ log(3/2) + ¼ log(1/2)
    logits_old, logits = np.zeros((1, 2)), np.array([[np.log(3.0), 0.0]])
    result = _harness.call_checking_inputs(
        student.reverse_kl_backward, "reverse_kl_backward", logits_old, logits, np.ones(1)
    )
    assert isinstance(result, tuple) and len(result) == 2, "reverse_kl_backward should return (kl, grad_logits)"
    kl = check_array(result[0], "reverse_kl_backward", (1,), "the KL")
    expected = 0.75 * np.log(1.5) + 0.25 * np.log(0.5)
    forward = 0.5 * np.log(0.5 / 0.75) + 0.5 * np.log(0.5 / 0.25)
    expect_number(
        kl,
        expected,
        "reverse_kl_backward",
        "KL[π ‖ π_old] for π = (¾, ¼), π_old = (½, ½)",
        alternatives={"KL[π_old ‖ π], chapter 9's order (the old policy first)": forward},
    )
    grad = check_array(result[1], "reverse_kl_backward", (1, 2), "the gradient")
    forward_grad = np.array([[0.25, -0.25]])  # π − π_old: the forward KL's gradient
    if np.allclose(grad, forward_grad):
        raise AssertionError(
            "reverse_kl_backward: for π = (¾, ¼), π_old = (½, ½) the gradient is π − π_old, which is chapter 9's "
            "gradient of KL[π_old ‖ π], not of KL[π ‖ π_old]?"
        )
    gap = np.log([1.5, 0.5])
    missing_kl = np.array([[0.75, 0.25]]) * gap
    if np.allclose(grad, missing_kl):
        raise AssertionError(
            "reverse_kl_backward: the gradient is π_j (log π_j − log π_old,j) without subtracting KL: the dependence "
            "of the softmax's normaliser on every logit forgotten?"
        )
    check_close(
        grad,
        np.array([[0.75, 0.25]]) * (gap - expected),
        "reverse_kl_backward",
        "∂KL/∂z for π = (¾, ¼), π_old = (½, ½)",
    )


def test_reverse_kl_backward_matches_finite_differences(student, rng):
    logits_old, logits, upstream = rng.normal(0, 1.5, (5, 4)), rng.normal(0, 1.5, (5, 4)), rng.standard_normal(5)
    kl, grad = student.reverse_kl_backward(logits_old, logits, upstream)
    log_old = logits_old - np.log(np.exp(logits_old).sum(axis=1, keepdims=True))
    log_new = logits - np.log(np.exp(logits).sum(axis=1, keepdims=True))
    check_close(
        check_array(kl, "reverse_kl_backward", (5,), "the KL"),
        (np.exp(log_new) * (log_new - log_old)).sum(1),
        "reverse_kl_backward",
        "KL[π ‖ π_old] per row",
    )
    z = logits.copy()
    numeric = numerical_gradient(
        lambda: float(np.sum(upstream * student.reverse_kl_backward(logits_old, z, upstream)[0])), z, 1e-6
    )
    check_close(
        check_array(grad, "reverse_kl_backward", (5, 4), "the gradient"),
        numeric,
        "reverse_kl_backward",
        "∂L/∂z (finite differences of Σ ∂L/∂KL · KL)",
        1e-5,
        1e-8,
    )


def test_reverse_kl_survives_extreme_logits(student):
    logits_old, logits = np.array([[1000.0, -1000.0, 0.0]]), np.array([[-1000.0, 1000.0, 0.0]])
    kl, grad = student.reverse_kl_backward(logits_old, logits, np.ones(1))
    check_close(
        check_array(kl, "reverse_kl_backward", (1,), "the KL for logits of ±1000"),
        [2000.0],
        "reverse_kl_backward",
        "the KL for logits of ±1000 (use log-softmax, not the log of a softmax)",
    )
    check_array(grad, "reverse_kl_backward", (1, 3), "the gradient for logits of ±1000")
