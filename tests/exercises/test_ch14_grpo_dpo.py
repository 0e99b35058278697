"""Grading chapter 14: GRPO's group-relative advantages (by hand, within each group and not over the batch, a group
of equal scores, the population standard deviation), GRPO's objective (by hand, k3 and its gradient, which follows
1 − π_ref/π_θ and not the reverse ratio, the clip's two sides, the weights, finite differences) and the DPO loss
(against the likelihood written out, finite differences, β in both the value and the gradient, the reference's
log-probabilities, huge margins)."""

import _harness
import numpy as np
import pytest
from _harness import call_checking_inputs, check_array, check_close, check_scalar, expect_number, numerical_gradient

student = _harness.student  # the fixture: the implementation under test (see _harness.py)
pytest_generate_tests = _harness.pytest_generate_tests  # one run per wrong variant under MINIPPO_IMPL=wrong
rng = _harness.rng  # a seeded NumPy Generator

pytestmark = pytest.mark.timeout(10)


def test_group_advantages_by_hand(student):
    scores = np.array([[1.0, 2.0, 3.0, 6.0], [0.0, 4.0, 4.0, 0.0]])
    advantages = call_checking_inputs(student.group_advantages, "group_advantages", scores)
    check_array(advantages, "group_advantages", (2, 4))
    # group 1: mean 3, population std √3.5; group 2: mean 2, std 2
    expected = np.array([np.array([-2.0, -1.0, 0.0, 3.0]) / np.sqrt(3.5), [-1.0, 1.0, 1.0, -1.0]])
    check_close(
        advantages,
        expected,
        "group_advantages",
        "the advantages (score − its group's mean) / (its group's std + eps), the std with ddof = 0",
        1e-6,
        1e-7,
        where=lambda i: f"group {i[0]}, response {i[1]}: scores of its group {scores[i[0]].tolist()}",
    )


def test_group_advantages_are_measured_within_each_group(student, rng):
    """Two groups on very different scales: each must come out with mean 0 and std 1 on its own."""
    scores = np.stack([rng.normal(10.0, 1.0, 6), rng.normal(-50.0, 20.0, 6), rng.normal(0.0, 0.1, 6)])
    advantages = check_array(student.group_advantages(scores), "group_advantages", (3, 6))
    check_close(
        advantages.mean(axis=1),
        np.zeros(3),
        "group_advantages",
        "the mean advantage of each group (row): measure against the group's own mean, not the batch's",
        1e-6,
        1e-7,
    )
    check_close(
        advantages.std(axis=1),
        np.ones(3),
        "group_advantages",
        "the standard deviation of each group's advantages: divide by the group's own std, not the batch's",
        1e-5,
        1e-7,
    )


def test_group_advantages_of_a_group_that_all_scored_the_same_are_zero(student):
    scores = np.array([[2.5, 2.5, 2.5], [1.0, 2.0, 3.0]])
    advantages = check_array(student.group_advantages(scores), "group_advantages", (2, 3))
    check_close(
        advantages[0],
        np.zeros(3),
        "group_advantages",
        "the advantages of a group whose responses all scored 2.5 (its std is 0: add eps to it)",
    )


def test_group_advantages_of_one_group_with_eps(student):
    scores = np.array([[0.0, 1.0]])
    advantages = check_array(student.group_advantages(scores, eps=0.5), "group_advantages", (1, 2))
    check_close(advantages, [[-0.5, 0.5]], "group_advantages", "the advantages of scores [0, 1] with eps = 0.5")


def reference_grpo(logp, logp_old, logp_ref, advantages, weights, epsilon, beta):
    """J written token by token, with the clip and the min as cases."""
    total = 0.0
    for lp, old, ref, a, w in zip(logp, logp_old, logp_ref, advantages, weights):
        r = np.exp(lp - old)
        surrogate = min(r * a, min(max(r, 1 - epsilon), 1 + epsilon) * a)
        u = np.exp(ref - lp)  # π_ref/π_θ
        total += w * (surrogate - beta * (u - np.log(u) - 1))
    return float(total)


def test_grpo_objective_by_hand(student):
    """Three tokens with Â = 0 (the KL term alone), then the clip on each side."""
    log2 = np.log(2.0)
    # token 0: π_ref/π_θ = 2, k3 = 2 − log 2 − 1; token 1: π_ref/π_θ = ½, k3 = ½ + log 2 − 1; token 2: k3 = 0
    logp, logp_ref = np.array([-log2, -1.0, -0.5]), np.array([0.0, -1.0 - log2, -0.5])
    value, grad = call_checking_inputs(
        student.grpo_objective, "grpo_objective", logp, logp.copy(), logp_ref, np.zeros(3), np.full(3, 0.5), 0.2, 0.4
    )
    check_scalar(value, "grpo_objective", "J")
    check_array(grad, "grpo_objective", (3,), "∂J/∂ log π_θ")
    check_close(value, -0.5 * 0.4 * ((1 - log2) + (log2 - 0.5)), "grpo_objective",
                "J with Â = 0: −Σ w β k3, k3 = π_ref/π_θ − log(π_ref/π_θ) − 1 (β = 0.4, w = ½)")  # fmt: skip
    check_close(
        grad,
        [-0.5 * 0.4 * (1 - 2.0), -0.5 * 0.4 * (1 - 0.5), 0.0],
        "grpo_objective",
        "∂J/∂ log π_θ with Â = 0: −w β (1 − π_ref/π_θ), the derivative of k3 with respect to log π_θ "
        "(π_θ/π_ref − 1 or log(π_θ/π_ref) is the gradient of another KL)",
        where={"π_ref/π_θ": [2.0, 0.5, 1.0]},
    )
    # r = 1.5 and 0.5 with ε = 0.2: Â > 0 above the range and Â < 0 below it are clipped (no gradient), the others not
    ratios = np.array([1.5, 1.5, 0.5, 0.5])
    advantages = np.array([1.0, -1.0, 1.0, -1.0])
    logp_old = np.zeros(4)
    value, grad = student.grpo_objective(np.log(ratios), logp_old, np.log(ratios), advantages, np.ones(4), 0.2, 0.0)
    check_close(
        check_scalar(value, "grpo_objective", "J"),
        1.2 - 1.5 + 0.5 - 0.8,
        "grpo_objective",
        "J with β = 0, r = (1.5, 1.5, 0.5, 0.5), Â = (1, −1, 1, −1), ε = 0.2: Σ min(r Â, clip(r) Â)",
    )
    check_close(
        check_array(grad, "grpo_objective", (4,), "∂J/∂ log π_θ"),
        [0.0, -1.5, 0.5, 0.0],
        "grpo_objective",
        "∂J/∂ log π_θ with β = 0: r Â where the unclipped term is the smaller, 0 where the clipped one is "
        "(the derivative with respect to log π_θ, not to r)",
        where={"r": ratios, "Â": advantages},
    )


@pytest.fixture
def tokens(rng):
    n = 40
    logp_old = np.log(rng.uniform(0.05, 0.9, n))
    logp = logp_old + rng.choice([-1.0, 1.0], n) * rng.uniform(0.05, 0.6, n)  # some ratios outside [0.8, 1.2]
    logp_ref = np.log(rng.uniform(0.05, 0.9, n))
    return logp, logp_old, logp_ref, rng.normal(size=n), rng.uniform(0.01, 0.2, n)


def test_grpo_objective_value(student, tokens):
    value, _ = call_checking_inputs(student.grpo_objective, "grpo_objective", *tokens, 0.2, 0.3)
    check_close(
        check_scalar(value, "grpo_objective", "J"),
        reference_grpo(*tokens, 0.2, 0.3),
        "grpo_objective",
        "J = Σ w_t [min(r_t Â_t, clip(r_t, 1 − ε, 1 + ε) Â_t) − β k3_t], ε = 0.2, β = 0.3, on 40 tokens",
    )


def test_grpo_objective_weighs_each_token(student, tokens):
    logp, logp_old, logp_ref, advantages, _ = tokens
    weights = np.zeros(len(logp))
    weights[::3] = 1.0 / 7
    value, grad = student.grpo_objective(logp, logp_old, logp_ref, advantages, weights, 0.2, 0.3)
    check_close(
        check_scalar(value, "grpo_objective", "J"),
        reference_grpo(*tokens[:4], weights, 0.2, 0.3),
        "grpo_objective",
        "J when only every third token has a weight (1/7): both terms are weighted",
    )
    check_close(
        check_array(grad, "grpo_objective", (len(logp),), "∂J/∂ log π_θ")[weights == 0],
        np.zeros(int(np.sum(weights == 0))),
        "grpo_objective",
        "∂J/∂ log π_θ of the tokens whose weight is 0 (the KL term is weighted too)",
    )


def test_grpo_objective_gradient_matches_finite_differences(student, tokens):
    logp, logp_old, logp_ref, advantages, weights = tokens
    _, grad = student.grpo_objective(logp, logp_old, logp_ref, advantages, weights, 0.2, 0.3)
    check_close(
        check_array(grad, "grpo_objective", (len(logp),), "∂J/∂ log π_θ"),
        numerical_gradient(lambda: reference_grpo(logp, logp_old, logp_ref, advantages, weights, 0.2, 0.3), logp),
        "grpo_objective",
        "∂J/∂ log π_θ, ε = 0.2, β = 0.3 (checked by finite differences)",
        1e-5,
        1e-7,
        where={"r": np.exp(logp - logp_old), "Â": advantages, "π_ref/π_θ": np.exp(logp_ref - logp)},
    )


def reference_dpo(logp_w, logp_l, ref_w, ref_l, beta):
    """−(1/n) Σ log σ(Δ), with σ written out (fine for moderate margins)."""
    margin = beta * ((logp_w - ref_w) - (logp_l - ref_l))
    return float(np.mean(-np.log(1.0 / (1.0 + np.exp(-margin)))))


@pytest.fixture
def pairs(rng):
    return rng.normal(-8.0, 2.0, 7), rng.normal(-8.0, 2.0, 7), rng.normal(-8.0, 2.0, 7), rng.normal(-8.0, 2.0, 7)


def test_dpo_loss_value(student, pairs):
    result = call_checking_inputs(student.dpo_loss, "dpo_loss", *pairs, 0.3)
    assert isinstance(result, tuple) and len(result) == 3, "dpo_loss: return (loss, grad_preferred, grad_rejected)"
    loss = check_scalar(result[0], "dpo_loss", "the loss")
    check_close(
        loss,
        reference_dpo(*pairs, 0.3),
        "dpo_loss",
        "the loss −Ê[log σ(β (log π/π_ref of y_w − log π/π_ref of y_l))], with β = 0.3",
    )


def test_dpo_loss_uses_the_reference_and_beta(student, pairs):
    """The same pairs with β = 1.5, and with the reference's log-probabilities changed: the loss must follow both."""
    logp_w, logp_l, ref_w, ref_l = pairs
    for beta, refs, what in (
        (1.5, (ref_w, ref_l), "the loss with β = 1.5 (β multiplies the whole margin)"),
        (0.3, (ref_w + 1.0, ref_l - 0.5), "the loss after log π_ref(y_w) rose by 1 and log π_ref(y_l) fell by ½"),
    ):
        loss = check_scalar(student.dpo_loss(logp_w, logp_l, *refs, beta)[0], "dpo_loss", "the loss")
        check_close(loss, reference_dpo(logp_w, logp_l, *refs, beta), "dpo_loss", what)


def test_dpo_gradient_matches_finite_differences(student, pairs):
    logp_w, logp_l, ref_w, ref_l = pairs
    _, grad_w, grad_l = student.dpo_loss(logp_w, logp_l, ref_w, ref_l, 0.7)
    check_array(grad_w, "dpo_loss", (7,), "grad_preferred")
    check_array(grad_l, "dpo_loss", (7,), "grad_rejected")
    check_close(
        grad_w,
        numerical_gradient(lambda: reference_dpo(logp_w, logp_l, ref_w, ref_l, 0.7), logp_w),
        "dpo_loss",
        "∂L/∂ log π_θ(y_w|x), with β = 0.7 (checked by finite differences)",
        1e-5,
        1e-7,
        n=7,
    )
    check_close(
        grad_l,
        numerical_gradient(lambda: reference_dpo(logp_w, logp_l, ref_w, ref_l, 0.7), logp_l),
        "dpo_loss",
        "∂L/∂ log π_θ(y_l|x), with β = 0.7 (checked by finite differences; the rejected response is a variable too)",
        1e-5,
        1e-7,
        n=7,
    )


def test_dpo_loss_survives_huge_margins(student):
    zeros = np.zeros(2)
    loss, grad_w, grad_l = student.dpo_loss(np.array([1000.0, -1000.0]), zeros, zeros, zeros, 1.0)
    loss = check_scalar(loss, "dpo_loss", "the loss for margins of ±1000 (it must stay finite)")
    check_close(loss, 500.0, "dpo_loss", "the loss for margins of +1000 and −1000")
    check_close(grad_w, [0.0, -0.5], "dpo_loss", "grad_preferred for margins of ±1000")
    check_close(grad_l, [0.0, 0.5], "dpo_loss", "grad_rejected for margins of ±1000")


# the transfer task: IPO's loss


@pytest.fixture
def ipo_case(rng):
    return rng.normal(-20, 3, 6), rng.normal(-20, 3, 6), rng.normal(-20, 3, 6), rng.normal(-20, 3, 6)


def test_ipo_loss_of_one_pair(student):
    # h = (−1 − (−2)) − (−3 − (−3)) = 1, τ = 0.25: target 2, loss (1 − 2)² = 1, ∂/∂ log π(y_w) = 2 (h − 2) = −2
    args = (np.array([-1.0]), np.array([-3.0]), np.array([-2.0]), np.array([-3.0]))
    result = call_checking_inputs(student.ipo_loss, "ipo_loss", *args, 0.25)
    assert isinstance(result, tuple) and len(result) == 3, (
        "ipo_loss should return (loss, grad_preferred, grad_rejected)"
    )
    expect_number(
        result[0],
        1.0,
        "ipo_loss",
        "the loss for one pair with h = 1, τ = 0.25",
        "(h − 1/(2τ))² = (1 − 2)²",
        alternatives={"the target 1/τ where IPO's is 1/(2τ)": 9.0},
    )
    expect_number(
        check_array(result[1], "ipo_loss", (1,), "grad_preferred")[0], -2.0, "ipo_loss",
        "∂L/∂ log π(y_w|x) for h = 1, τ = 0.25", "2 (h − 1/(2τ))",
        alternatives={"the square's derivative without its factor 2": -1.0},
    )  # fmt: skip
    expect_number(
        check_array(result[2], "ipo_loss", (1,), "grad_rejected")[0], 2.0, "ipo_loss",
        "∂L/∂ log π(y_l|x) for h = 1, τ = 0.25", "−2 (h − 1/(2τ)): log π(y_l|x) enters h with a minus",
        alternatives={"the preferred response's gradient, with the same sign": -2.0},
    )  # fmt: skip


def test_ipo_loss_matches_finite_differences(student, ipo_case):
    logp_w, logp_l, ref_w, ref_l = ipo_case
    loss, grad_w, grad_l = student.ipo_loss(logp_w, logp_l, ref_w, ref_l, 0.1)
    h = (logp_w - ref_w) - (logp_l - ref_l)
    check_close(check_scalar(loss, "ipo_loss"), float(np.mean((h - 5.0) ** 2)), "ipo_loss", "the loss, τ = 0.1")
    for name, grad, variable in (("grad_preferred", grad_w, logp_w), ("grad_rejected", grad_l, logp_l)):
        x = variable.copy()
        others = (x, logp_l, ref_w, ref_l) if name == "grad_preferred" else (logp_w, x, ref_w, ref_l)
        numeric = numerical_gradient(lambda others=others: float(student.ipo_loss(*others, 0.1)[0]), x, 1e-6)
        check_close(check_array(grad, "ipo_loss", (6,), name), numeric, "ipo_loss", f"{name} (finite differences)",
                    1e-5, 1e-8)  # fmt: skip
