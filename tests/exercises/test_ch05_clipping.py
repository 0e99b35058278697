"""Grading chapter 5: the clipped term one sample at a time (inside, above and below the band, and in the narrow
windows between 1 ± ε and e^±ε where a band on |log r| goes wrong), then against a direct clip and finite differences
on whole batches; the clip fraction by counting.

Tests run from the most specific to the most general, so the first failure names the mistake.
"""

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
    where_is_ratio,
)

student = _harness.student  # the fixture: the implementation under test (see _harness.py)
pytest_generate_tests = _harness.pytest_generate_tests  # one run per wrong variant under MINIPPO_IMPL=wrong
rng = _harness.rng  # a seeded NumPy Generator

pytestmark = pytest.mark.timeout(10)

# ratios across and beyond the band of every ε used here, away from its edges (where the gradient jumps), with one
# ratio in each window between 1 + ε and e^ε and between e^−ε and 1 − ε, for ε = 0.1, 0.2 and 0.3
RATIOS = np.array([0.4, 0.65, 0.72, 0.75, 0.81, 0.86, 0.902, 0.95, 1.0, 1.04, 1.103, 1.15, 1.21, 1.26, 1.32, 1.7, 2.5])
# (r, Â, ε): single samples, the windows included
SINGLE = [
    (0.9, 1.0, 0.2),
    (1.1, -2.0, 0.2),
    (1.5, 1.0, 0.2),
    (0.5, 1.0, 0.2),
    (1.5, -1.0, 0.2),
    (1.15, 1.0, 0.1),
    (1.25, -1.0, 0.3),
    (1.21, 1.0, 0.2),
    (0.81, 1.5, 0.2),
    (1.103, -1.0, 0.1),
    (0.902, 1.0, 0.1),
    (1.32, 2.0, 0.3),
    (0.72, -1.0, 0.3),
]

# (r, ε) for the clip fraction of one sample: plain cases first, then r = 0.83, inside the band although 1/r is not,
# then the windows
FRACTION_CASES = [(1.5, 0.2), (0.5, 0.2), (1.0, 0.2), (1.15, 0.1), (1.25, 0.3), (0.83, 0.2)] + [
    (1.21, 0.2),
    (0.81, 0.2),
    (1.103, 0.1),
    (0.902, 0.1),
    (1.32, 0.3),
    (0.72, 0.3),
]


def clip(r, low, high):
    return low if r < low else high if r > high else r


def gives_the_answer_of_epsilon_02(student, epsilon) -> bool:
    """Whether clipped_surrogate, called with ``epsilon`` on ratios across the band, returns the values that ε = 0.2
    gives (and that ``epsilon`` does not): ε written into the code."""
    ratios, advantages = np.array([0.5, 0.75, 0.85, 1.15, 1.25, 1.5]), np.arange(1.0, 7.0)  # no symmetry to cancel
    try:
        value, _ = student.clipped_surrogate(np.log(ratios), np.zeros(6), advantages, epsilon)
    except Exception:  # noqa: BLE001 - a probe only: the test's own call reports what raised
        return False
    at_02 = np.mean(np.clip(ratios, 0.8, 1.2) * advantages)
    at_epsilon = np.mean(np.clip(ratios, 1 - epsilon, 1 + epsilon) * advantages)
    return abs(float(value) - at_02) < 1e-9 and abs(at_02 - at_epsilon) > 1e-6


@pytest.mark.parametrize("ratio, advantage, epsilon", SINGLE, ids=[f"r={r}-A={a}-eps={e}" for r, a, e in SINGLE])
def test_clipped_surrogate_one_sample(student, ratio, advantage, epsilon):
    logp_old = np.array([-1.3])
    value, grad = student.clipped_surrogate(np.log([ratio]) + logp_old, logp_old, np.array([advantage]), epsilon)
    sample = f"one sample with r = {ratio}, Â = {advantage}, ε = {epsilon}"
    place = where_is_ratio(ratio, epsilon)
    inside = abs(ratio - 1) < epsilon
    inverse = 1 / ratio
    swapped = "r computed as π_old/π (log π and log π_old swapped)"
    fixed = "ε fixed at 0.2 (the epsilon argument ignored)"
    the_min = "the min's asymmetric value and gradient: that is chapter 6's L^CLIP, not the clipped term alone"
    helps = (advantage > 0 and ratio <= 1 + epsilon) or (advantage < 0 and ratio >= 1 - epsilon)
    log_band = abs(np.log(ratio)) < epsilon
    # ε fixed is named only where the student's code, probed on other ratios, gives ε = 0.2's answer for this ε; the
    # other mistakes in the order the grader's own wrong variants reach this case: a case that tells two of them apart
    # comes earlier in SINGLE, so the one still standing here is named first
    ignores_epsilon = epsilon != 0.2 and gives_the_answer_of_epsilon_02(student, epsilon)
    value_mistakes = {
        fixed: clip(ratio, 0.8, 1.2) * advantage if ignores_epsilon else None,
        the_min: min(ratio * advantage, clip(ratio, 1 - epsilon, 1 + epsilon) * advantage),
        "r Â, the ratio unclipped": ratio * advantage,
        swapped: clip(inverse, 1 - epsilon, 1 + epsilon) * advantage,
    }
    expected_value = clip(ratio, 1 - epsilon, 1 + epsilon) * advantage
    why = f"clip(r, 1 − ε, 1 + ε) Â, r is {place}"
    expect_number(
        value, expected_value, "clipped_surrogate", f"the value for {sample}", why, alternatives=value_mistakes
    )
    check_array(grad, "clipped_surrogate", (1,), f"the gradient for {sample}")
    grad_mistakes = {
        fixed: (ratio * advantage if abs(ratio - 1) < 0.2 else 0.0) if ignores_epsilon else None,
        "the gradient's band tested on |log r| < ε instead of |r − 1| ≤ ε": ratio * advantage if log_band else 0.0,
        the_min: ratio * advantage if helps else 0.0,
        "the gradient of the unclipped r Â, as if the clip were not there": None if inside else ratio * advantage,
        swapped: inverse * advantage if abs(inverse - 1) < epsilon else 0.0,
    }
    why = f"r Â, since r is {place}" if inside else f"clip(r) is a constant there: r is {place}"
    expected_grad = ratio * advantage if inside else 0.0
    expect_number(
        grad, expected_grad, "clipped_surrogate", f"the gradient for {sample}", why, alternatives=grad_mistakes
    )


@pytest.mark.parametrize("ratio, epsilon", FRACTION_CASES)
def test_clip_fraction_of_one_sample(student, ratio, epsilon):
    fraction = check_scalar(student.clip_fraction(np.log([ratio]), np.zeros(1), epsilon), "clip_fraction")
    expected = float(abs(ratio - 1) > epsilon)
    mistakes = {  # the window cases that tell these two apart come first; r = 0.83 is there for the swap alone
        "a band on |log r|": float(abs(np.log(ratio)) > epsilon),
        "r computed as π_old/π (log π and log π_old swapped)": float(abs(1 / ratio - 1) > epsilon),
    }
    named = [words for words, value in mistakes.items() if value == fraction]
    assert fraction == expected, (
        f"clip_fraction: for one sample with r = {ratio} and ε = {epsilon}, the fraction should be {expected:g}, not "
        f"{fraction:.6g} (r is {where_is_ratio(ratio, epsilon)})"
        + (": " + " Or ".join(f"{w}?" for w in named) if named else "")
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
        "the fraction when every ratio is far outside the band on either side (a fraction of the batch, in [0, 1])",
    )


def exact_log_ratio(ratio: float) -> float:
    """A log-ratio x with np.exp(x) == ratio exactly, so that |r − 1| = ε holds exactly in floating point."""
    x = float(np.log(ratio))
    for _ in range(64):
        if np.exp(x) == ratio:
            return x
        x = float(np.nextafter(x, np.inf if np.exp(x) < ratio else -np.inf))
    raise RuntimeError(f"no float x has exp(x) == {ratio}")


def test_clip_fraction_at_the_edges_of_the_band(student):
    # ε = 0.25 and r = 1.25 or 0.75 exactly: |r − 1| = ε is on the edge, not outside (|r − 1| > ε)
    logp = np.array([exact_log_ratio(1.25), exact_log_ratio(0.75), np.log(1.5), 0.0])
    fraction = check_scalar(student.clip_fraction(logp, np.zeros(4), 0.25), "clip_fraction")
    assert fraction == 0.25, (
        f"clip_fraction: for r = 1.25, 0.75, 1.5 and 1 with ε = 0.25 the fraction should be 0.25 (only r = 1.5 is "
        f"outside; r = 1.25 and 0.75 lie exactly on the edges, |r − 1| = ε, which is not > ε), not {fraction:.6g}"
        + (": |r − 1| ≥ ε where the contract says > ε?" if fraction == 0.75 else "")
    )


def test_clipped_surrogate_on_the_edges_of_the_band(student):
    # ε = 0.25 and r = 1.25 or 0.75 exactly: the contract's band is closed, so a ratio on an edge is inside it and
    # keeps its gradient r Â / n (the derivative does not exist there; the contract picks this side, as clip_fraction
    # does when it does not count such a ratio)
    logp = np.array([exact_log_ratio(1.25), exact_log_ratio(0.75)])
    advantages = np.array([1.0, -1.0])
    _, grad = student.clipped_surrogate(logp, np.zeros(2), advantages, 0.25)
    check_array(grad, "clipped_surrogate", (2,), "the gradient")
    expected = np.array([1.25, -0.75]) / 2
    what = "the gradient for r = 1.25 and 0.75, exactly on the edges of the band (ε = 0.25, Â = 1 and −1)"
    assert not np.all(grad == 0), (
        f"clipped_surrogate: {what} should be r Â / n = {expected.tolist()} (the band is closed: |r − 1| = ε is "
        f"inside), not {grad.tolist()}: the open band 1 − ε < r < 1 + ε where the contract says ≤?"
    )
    check_close(grad, expected, "clipped_surrogate", f"{what}, r Â / n")


@pytest.fixture
def batch(rng):
    logp_old = rng.normal(-1.0, 0.6, len(RATIOS))
    advantages = rng.choice([-1.0, 1.0], len(RATIOS)) * rng.uniform(0.2, 2.0, len(RATIOS))
    return np.log(RATIOS) + logp_old, logp_old, advantages


def test_clipped_surrogate_gradient_vanishes_outside_the_band(student, batch):
    logp, logp_old, advantages = batch
    _, grad = student.clipped_surrogate(logp, logp_old, advantages, 0.2)
    check_array(grad, "clipped_surrogate", (len(RATIOS),), "the gradient")
    outside = np.abs(RATIOS - 1) > 0.2
    expected = np.where(outside, 0.0, RATIOS * advantages) / len(RATIOS)
    check_close(
        grad,
        expected,
        "clipped_surrogate",
        "the gradient (r_t Â_t / n inside the band, 0 outside, with ε = 0.2)",
        where=lambda i: f"r_t = {RATIOS[i]}, Â_t = {advantages[i]:.4g}: {where_is_ratio(RATIOS[i], 0.2)}",
    )


@pytest.mark.parametrize("epsilon", [0.1, 0.2, 0.3])
def test_clipped_surrogate_value_and_gradient(student, batch, epsilon):
    logp, logp_old, advantages = batch
    value, grad = call_checking_inputs(
        student.clipped_surrogate, "clipped_surrogate", logp, logp_old, advantages, epsilon
    )
    expected = sum(clip(r, 1 - epsilon, 1 + epsilon) * a for r, a in zip(RATIOS, advantages)) / len(RATIOS)
    check_close(
        check_scalar(value, "clipped_surrogate"),
        expected,
        "clipped_surrogate",
        f"the value Ê[clip(r) Â], ε = {epsilon}",
    )
    check_array(grad, "clipped_surrogate", (len(RATIOS),), "the gradient")
    numeric = numerical_gradient(
        lambda: float(student.clipped_surrogate(logp, logp_old, advantages, epsilon)[0]), logp, 1e-7
    )
    check_close(
        grad,
        numeric,
        "clipped_surrogate",
        f"∂/∂ log π (checked by finite differences of the value), ε = {epsilon}",
        where=lambda i: f"r_t = {RATIOS[i]}, Â_t = {advantages[i]:.4g}: {where_is_ratio(RATIOS[i], epsilon)}",
    )


def test_clip_fraction_counts_ratios_outside_the_band(student, batch):
    logp, logp_old, _ = batch
    for epsilon in (0.1, 0.2, 0.3):
        fraction = call_checking_inputs(student.clip_fraction, "clip_fraction", logp, logp_old, epsilon)
        count = sum(1 for r in RATIOS if r < 1 - epsilon or r > 1 + epsilon)
        check_close(
            check_scalar(fraction, "clip_fraction"),
            count / len(RATIOS),
            "clip_fraction",
            f"the fraction outside the band for ε = {epsilon} ({count} of {len(RATIOS)} ratios: {RATIOS.tolist()})",
        )


# the transfer task: dual-clip PPO's lower bound for negative advantages

DUAL = [  # (r, Â): the bound c = 3 binds for Â < 0 and r > 3 only
    (0.5, 1.0), (1.1, 1.0), (1.5, 1.0), (4.0, 1.0),
    (0.5, -1.0), (1.1, -1.0), (2.0, -1.0), (4.0, -1.0), (6.0, -2.0),
]  # fmt: skip


def dual_clip_term(r, a, epsilon=0.2, c=3.0):
    term = min(r * a, clip(r, 1 - epsilon, 1 + epsilon) * a)
    return max(term, c * a) if a < 0 else term


@pytest.mark.parametrize("ratio, advantage", DUAL, ids=[f"r={r}-A={a}" for r, a in DUAL])
def test_dual_clip_surrogate_one_sample(student, ratio, advantage):
    logp_old = np.array([-1.1])
    result = _harness.call_checking_inputs(
        student.dual_clip_surrogate, "dual_clip_surrogate", np.log([ratio]) + logp_old, logp_old,
        np.array([advantage]), 0.2, 3.0,
    )  # fmt: skip
    assert isinstance(result, tuple) and len(result) == 2, "dual_clip_surrogate should return (value, grad)"
    value, grad = result
    sample = f"one sample with r = {ratio}, Â = {advantage}, ε = 0.2, c = 3"
    clip_term = min(ratio * advantage, clip(ratio, 0.8, 1.2) * advantage)
    expected = dual_clip_term(ratio, advantage)
    bound_everywhere = max(clip_term, 3.0 * advantage)
    expect_number(
        value, expected, "dual_clip_surrogate", f"the value for {sample}", alternatives={
            "L^CLIP's term without the bound c Â (the bound binds for Â < 0 and r > c)": clip_term,
            "the bound c Â applied to a positive advantage too": bound_everywhere,
            "min(·, c Â) where the bound is a max, a floor for Â < 0": min(clip_term, 3.0 * advantage),
        },
    )  # fmt: skip
    bound_binds = advantage < 0 and ratio > 3.0
    helps = (advantage > 0 and ratio <= 1.2) or (advantage < 0 and ratio >= 0.8)
    expected_grad = 0.0 if bound_binds or not helps else ratio * advantage
    expect_number(
        check_array(grad, "dual_clip_surrogate", (1,), f"the gradient for {sample}"), expected_grad,
        "dual_clip_surrogate", f"the gradient for {sample}", alternatives={
            "L^CLIP's gradient where the bound c Â binds (c Â is a constant there)": ratio * advantage
            if bound_binds else None,
        },
    )  # fmt: skip


def test_dual_clip_surrogate_matches_finite_differences(student, rng):
    ratios = np.array([0.4, 0.7, 0.9, 1.1, 1.3, 2.0, 2.6, 3.4, 5.0, 0.5, 0.95, 1.5, 2.9, 3.3, 4.5, 8.0])
    advantages = np.where(np.arange(len(ratios)) < 9, -1.0, 1.0) * rng.uniform(0.3, 2.0, len(ratios))
    logp_old = rng.normal(-1.0, 0.5, len(ratios))
    logp = np.log(ratios) + logp_old
    value, grad = student.dual_clip_surrogate(logp, logp_old, advantages, 0.2, 3.0)
    expected = np.mean([dual_clip_term(r, a) for r, a in zip(ratios, advantages)])
    check_close(check_scalar(value, "dual_clip_surrogate"), expected, "dual_clip_surrogate", "the value (c = 3)")
    check_array(grad, "dual_clip_surrogate", (len(ratios),), "the gradient")
    numeric = numerical_gradient(
        lambda: float(student.dual_clip_surrogate(logp, logp_old, advantages, 0.2, 3.0)[0]), logp, 1e-7
    )
    check_close(
        grad, numeric, "dual_clip_surrogate", "∂/∂ log π (finite differences), ε = 0.2, c = 3",
        where=lambda i: f"r_t = {ratios[i]}, Â_t = {advantages[i]:.4g}",
    )  # fmt: skip
