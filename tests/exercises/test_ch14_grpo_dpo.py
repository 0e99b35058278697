"""Grading chapter 14: GRPO's group-relative advantages (by hand, within each group and not over the batch, a group
of equal scores, the population standard deviation) and the DPO loss (against the likelihood written out, finite
differences, β in both the value and the gradient, the reference's log-probabilities, huge margins)."""

import _harness
import numpy as np
import pytest
from _harness import call_checking_inputs, check_array, check_close, check_scalar, numerical_gradient

student = _harness.student  # the fixture: the implementation under test (see _harness.py)
pytest_generate_tests = _harness.pytest_generate_tests  # one run per wrong variant under MINIPPO_IMPL=wrong
rng = _harness.rng  # a seeded NumPy Generator

pytestmark = pytest.mark.timeout(10)


def test_grpo_advantages_by_hand(student):
    scores = np.array([[1.0, 2.0, 3.0, 6.0], [0.0, 4.0, 4.0, 0.0]])
    advantages = call_checking_inputs(student.grpo_advantages, "grpo_advantages", scores)
    check_array(advantages, "grpo_advantages", (2, 4))
    # group 1: mean 3, population std √3.5; group 2: mean 2, std 2
    expected = np.array([np.array([-2.0, -1.0, 0.0, 3.0]) / np.sqrt(3.5), [-1.0, 1.0, 1.0, -1.0]])
    check_close(
        advantages,
        expected,
        "grpo_advantages",
        "the advantages (score − its group's mean) / (its group's std + eps), the std with ddof = 0",
        1e-6,
        1e-7,
        where=lambda i: f"group {i[0]}, response {i[1]}: scores of its group {scores[i[0]].tolist()}",
    )


def test_grpo_advantages_are_measured_within_each_group(student, rng):
    """Two groups on very different scales: each must come out with mean 0 and std 1 on its own."""
    scores = np.stack([rng.normal(10.0, 1.0, 6), rng.normal(-50.0, 20.0, 6), rng.normal(0.0, 0.1, 6)])
    advantages = check_array(student.grpo_advantages(scores), "grpo_advantages", (3, 6))
    check_close(
        advantages.mean(axis=1),
        np.zeros(3),
        "grpo_advantages",
        "the mean advantage of each group (row): measure against the group's own mean, not the batch's",
        1e-6,
        1e-7,
    )
    check_close(
        advantages.std(axis=1),
        np.ones(3),
        "grpo_advantages",
        "the standard deviation of each group's advantages: divide by the group's own std, not the batch's",
        1e-5,
        1e-7,
    )


def test_grpo_advantages_of_a_group_that_all_scored_the_same_are_zero(student):
    scores = np.array([[2.5, 2.5, 2.5], [1.0, 2.0, 3.0]])
    advantages = check_array(student.grpo_advantages(scores), "grpo_advantages", (2, 3))
    check_close(
        advantages[0],
        np.zeros(3),
        "grpo_advantages",
        "the advantages of a group whose responses all scored 2.5 (its std is 0: add eps to it)",
    )


def test_grpo_advantages_of_one_group_with_eps(student):
    scores = np.array([[0.0, 1.0]])
    advantages = check_array(student.grpo_advantages(scores, eps=0.5), "grpo_advantages", (1, 2))
    check_close(advantages, [[-0.5, 0.5]], "grpo_advantages", "the advantages of scores [0, 1] with eps = 0.5")


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
