"""Grading chapter 13: the Bradley–Terry loss (against the likelihood written out, finite differences, huge margins,
and the fact that it is minimised by the true preference probabilities), and the KL-shaped rewards (by hand, and
their sum over a sequence equal to R(x) − β Σ_t log π/π_ref)."""

import _harness
import numpy as np
import pytest
from _harness import call_checking_inputs, check_array, check_close, check_scalar, numerical_gradient

student = _harness.student  # the fixture: the implementation under test (see _harness.py)
pytest_generate_tests = _harness.pytest_generate_tests  # one run per wrong variant under MINIPPO_IMPL=wrong
rng = _harness.rng  # a seeded NumPy Generator

pytestmark = pytest.mark.timeout(10)


def reference_bt(preferred, rejected):
    """−(1/n) Σ log P(w ≻ l), with P = 1 / (1 + e^{−(r_w − r_l)}) written out (fine for moderate scores)."""
    return float(np.mean([-np.log(1.0 / (1.0 + np.exp(-(w - l)))) for w, l in zip(preferred, rejected)]))


@pytest.fixture
def scores(rng):
    return rng.normal(0, 2.0, 8), rng.normal(0, 2.0, 8)


def test_bradley_terry_loss_value(student, scores):
    preferred, rejected = scores
    result = call_checking_inputs(student.bradley_terry_loss, "bradley_terry_loss", preferred, rejected)
    assert isinstance(result, tuple) and len(result) == 3, (
        "bradley_terry_loss: return (loss, grad_preferred, grad_rejected)"
    )
    loss = check_scalar(result[0], "bradley_terry_loss", "the loss")
    check_close(
        loss,
        reference_bt(preferred, rejected),
        "bradley_terry_loss",
        "the loss −Ê[log σ(r_w − r_l)] (the preferred score comes first)",
    )


def test_bradley_terry_gradient_matches_finite_differences(student, scores):
    preferred, rejected = scores
    _, grad_w, grad_l = student.bradley_terry_loss(preferred, rejected)
    check_array(grad_w, "bradley_terry_loss", (8,), "grad_preferred")
    check_array(grad_l, "bradley_terry_loss", (8,), "grad_rejected")
    check_close(
        grad_w,
        numerical_gradient(lambda: reference_bt(preferred, rejected), preferred),
        "bradley_terry_loss",
        "∂L/∂r_w (checked by finite differences; it should be −σ(r_l − r_w)/n)",
        1e-5,
        1e-7,
    )
    check_close(
        grad_l,
        numerical_gradient(lambda: reference_bt(preferred, rejected), rejected),
        "bradley_terry_loss",
        "∂L/∂r_l (checked by finite differences; the rejected score is a variable too)",
        1e-5,
        1e-7,
    )


def test_bradley_terry_survives_huge_margins(student):
    loss, grad_w, grad_l = student.bradley_terry_loss(np.array([1000.0, -1000.0]), np.array([0.0, 0.0]))
    loss = check_scalar(loss, "bradley_terry_loss", "the loss for margins of ±1000 (use np.logaddexp, not log of σ)")
    check_close(loss, 500.0, "bradley_terry_loss", "the loss for margins of +1000 and −1000")
    check_close(grad_w, [0.0, -0.5], "bradley_terry_loss", "grad_preferred for margins of ±1000")
    check_close(grad_l, [0.0, 0.5], "bradley_terry_loss", "grad_rejected for margins of ±1000")


def test_bradley_terry_is_minimised_by_the_true_margin(student):
    """Pairs in which w won 3 times out of 4: the loss's gradient vanishes where σ(Δ) = 3/4, Δ = log 3."""
    margin = np.log(3.0)
    preferred = np.array([margin, margin, margin, 0.0])  # three pairs as observed, one the other way round
    rejected = np.array([0.0, 0.0, 0.0, margin])
    _, grad_w, grad_l = student.bradley_terry_loss(preferred, rejected)
    total = float(grad_w[:3].sum() + grad_l[3])  # ∂L/∂(r_A − r_B), A the winner of the first three pairs
    assert abs(total) < 1e-12, (
        f"bradley_terry_loss: for a pair won 3 times in 4, the gradient should vanish at Δ = log 3, not be {total:.3g}"
    )


@pytest.fixture
def sequences(rng):
    logp = np.log(rng.uniform(0.05, 1.0, (3, 5)))
    logp_ref = np.log(rng.uniform(0.05, 1.0, (3, 5)))
    return logp, logp_ref, np.array([2.0, -1.5, 0.7]), np.array([5, 2, 1])


def describe_token(index, lengths, logp, logp_ref, scores, beta):
    """check_close's ``where`` for a (sequence, token) entry: the token's place in its sequence and its inputs."""
    row, t = int(index[0]), int(index[1])
    length = int(lengths[row])
    place = (
        "its last token, t = length − 1"
        if t == length - 1
        else "inside the sequence"
        if t < length - 1
        else "padding after the end, t ≥ length"
    )
    return (
        f"sequence {row} of length {length}, token t = {t}: {place}; log π − log π_ref = "
        f"{logp[row, t] - logp_ref[row, t]:.4g}, R(x) = {scores[row]:g}, β = {beta:g}"
    )


def test_kl_shaped_rewards_by_hand(student):
    logp = np.log(np.array([[0.5, 0.5, 0.5], [0.2, 0.2, 0.2]]))
    logp_ref = np.log(np.array([[0.25, 0.5, 0.9], [0.4, 0.4, 0.4]]))
    rewards = call_checking_inputs(
        student.kl_shaped_rewards, "kl_shaped_rewards", logp, logp_ref, np.array([3.0, -1.0]), np.array([2, 3]), 0.5
    )
    check_array(rewards, "kl_shaped_rewards", (2, 3))
    half_log2 = 0.5 * np.log(2.0)
    expected = np.array([[-half_log2, 3.0, 0.0], [half_log2, half_log2, half_log2 - 1.0]])
    check_close(
        rewards,
        expected,
        "kl_shaped_rewards",
        "the rewards (−β log π/π_ref per token, R(x) added on the last token t = length − 1, 0 after)",
        where=lambda i: describe_token(i, np.array([2, 3]), logp, logp_ref, np.array([3.0, -1.0]), 0.5),
    )


def test_kl_shaped_rewards_sum_to_score_minus_beta_kl(student, sequences):
    logp, logp_ref, scores, lengths = sequences
    rewards = check_array(student.kl_shaped_rewards(logp, logp_ref, scores, lengths, 0.3), "kl_shaped_rewards", (3, 5))
    inside = np.arange(5)[None, :] < lengths[:, None]
    expected = scores - 0.3 * np.where(inside, logp - logp_ref, 0.0).sum(axis=1)
    check_close(
        rewards.sum(axis=1), expected, "kl_shaped_rewards", "the return of each sequence, R(x) − β Σ_t log π/π_ref"
    )
    check_close(
        np.where(inside, 0.0, rewards),
        np.zeros((3, 5)),
        "kl_shaped_rewards",
        "the rewards after the end of a sequence (they should be 0)",
    )


def test_kl_shaped_rewards_without_penalty_are_the_score_at_the_end(student, sequences):
    logp, logp_ref, scores, lengths = sequences
    rewards = check_array(student.kl_shaped_rewards(logp, logp_ref, scores, lengths, 0.0), "kl_shaped_rewards", (3, 5))
    expected = np.zeros((3, 5))
    expected[np.arange(3), lengths - 1] = scores
    check_close(rewards, expected, "kl_shaped_rewards", "the rewards with β = 0 (only R(x), on the last token)")


def test_kl_shaped_rewards_penalise_every_token_where_it_is_chosen(student, sequences):
    """Where the policy picks a token more likely than π_ref does, that token's reward falls by β log π/π_ref."""
    logp, logp_ref, scores, lengths = sequences
    rewards = student.kl_shaped_rewards(logp, logp_ref, np.zeros(3), lengths, 2.0)
    check_close(
        rewards[0],
        -2.0 * (logp[0] - logp_ref[0]),
        "kl_shaped_rewards",
        "the per-token rewards with R = 0 (each −β (log π − log π_ref), at its own token)",
    )


# the transfer task: the Plackett–Luce loss of a ranking


def plackett_luce_by_definition(scores):
    total = 0.0
    for row in scores:
        for i in range(len(row) - 1):
            total -= np.log(np.exp(row[i]) / np.sum(np.exp(row[i:])))
    return total / len(scores)


def test_plackett_luce_of_two_responses_is_bradley_terry(student, scores):
    preferred, rejected = scores
    result = call_checking_inputs(
        student.plackett_luce_loss, "plackett_luce_loss", np.stack([preferred, rejected], axis=1)
    )
    assert isinstance(result, tuple) and len(result) == 2, "plackett_luce_loss should return (loss, grad)"
    expected = reference_bt(preferred, rejected)
    check_close(
        check_scalar(result[0], "plackett_luce_loss"),
        expected,
        "plackett_luce_loss",
        "the loss for K = 2 (the Bradley–Terry loss)",
    )


def test_plackett_luce_of_three_responses(student):
    # one ranking of three scores (2, 1, 0): −log[e²/(e² + e + 1)] − log[e/(e + 1)]
    scores = np.array([[2.0, 1.0, 0.0]])
    loss, grad = student.plackett_luce_loss(scores)
    expected = plackett_luce_by_definition(scores)
    all_pairs = float(sum(np.logaddexp(0.0, -(scores[0, i] - scores[0, j])) for i in range(3) for j in range(i + 1, 3)))
    full_softmax = float(sum(np.logaddexp.reduce(scores[0]) - scores[0, i] for i in range(2)))
    _harness.expect_number(
        loss, expected, "plackett_luce_loss", "the loss of the ranking (2, 1, 0)", "each choice among those left",
        alternatives={
            "Bradley–Terry on every pair, not one choice after another": all_pairs,
            "each choice's softmax over all K responses, the ones already chosen included": full_softmax,
        },
    )  # fmt: skip
    check_array(grad, "plackett_luce_loss", (1, 3), "the gradient")


def test_plackett_luce_matches_finite_differences(student, rng):
    scores = rng.normal(0.0, 1.5, (4, 5))
    loss, grad = student.plackett_luce_loss(scores)
    check_close(
        check_scalar(loss, "plackett_luce_loss"),
        plackett_luce_by_definition(scores),
        "plackett_luce_loss",
        "the loss, the mean over 4 rankings of 5",
    )
    s = scores.copy()
    numeric = numerical_gradient(lambda: float(student.plackett_luce_loss(s)[0]), s, 1e-6)
    check_close(
        check_array(grad, "plackett_luce_loss", (4, 5), "the gradient"),
        numeric,
        "plackett_luce_loss",
        "∂loss/∂scores (finite differences)",
        1e-5,
        1e-8,
    )


def test_plackett_luce_survives_huge_scores(student):
    scores = np.array([[1000.0, 0.0, -1000.0], [-1000.0, 0.0, 1000.0]])
    loss, grad = student.plackett_luce_loss(scores)
    check_close(
        check_scalar(loss, "plackett_luce_loss", "the loss for scores of ±1000"),
        1500.0,
        "plackett_luce_loss",
        "the loss for scores of ±1000 (np.logaddexp keeps it finite)",
    )
    check_array(grad, "plackett_luce_loss", (2, 3), "the gradient for scores of ±1000")
