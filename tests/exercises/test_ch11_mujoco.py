"""Grading chapter 11: its transfer task, the log-likelihood of clipped actions under the Gaussian policy whose samples
were clipped (a density between the bounds, a probability mass on each bound), against the normal distribution's
cumulative function, probabilities that add up to one, and finite differences.

Tests run from the most specific to the most general, so the first failure names the mistake.
"""

import math

import _harness
import numpy as np
import pytest
from _harness import call_checking_inputs, check_array, check_close, expect_number, numerical_gradient

student = _harness.student  # the fixture: the implementation under test (see _harness.py)
pytest_generate_tests = _harness.pytest_generate_tests  # one run per wrong variant under MINIPPO_IMPL=wrong
rng = _harness.rng  # a seeded NumPy Generator

pytestmark = pytest.mark.timeout(10)

LOW, HIGH = np.array([-1.0]), np.array([1.0])


def normal_cdf(x: float) -> float:
    return 0.5 * math.erfc(-x / math.sqrt(2.0))


def test_clipped_gaussian_mass_on_each_bound(student):
    # μ = 0.5, σ = 1 in one dimension: the action 1 (the upper bound) carries P(u ≥ 1) = 1 − Φ(0.5)
    mean, log_std = np.array([[0.5], [0.5], [0.5]]), np.zeros(1)
    actions = np.array([[1.0], [-1.0], [0.2]])
    result = call_checking_inputs(
        student.clipped_gaussian_log_prob, "clipped_gaussian_log_prob", mean, log_std, actions, LOW, HIGH
    )
    assert isinstance(result, tuple) and len(result) == 3, (
        "clipped_gaussian_log_prob should return (logp, grad_mean, grad_log_std)"
    )
    logp = check_array(result[0], "clipped_gaussian_log_prob", (3,), "logp")
    density = [-0.5 * (a - 0.5) ** 2 - 0.5 * math.log(2 * math.pi) for a in (1.0, -1.0, 0.2)]
    cases = [
        ("the upper bound a = 1", math.log(1 - normal_cdf(0.5)), math.log(normal_cdf(0.5))),
        ("the lower bound a = −1", math.log(normal_cdf(-1.5)), math.log(1 - normal_cdf(-1.5))),
        ("a = 0.2, between the bounds", density[2], None),
    ]
    for row, (where, expected, other_tail) in enumerate(cases):
        expect_number(
            logp[row], expected, "clipped_gaussian_log_prob", f"log p of {where}, with μ = 0.5, σ = 1, bounds ±1",
            alternatives={
                "the Gaussian's density at the bound, as if the action had not been clipped": density[row]
                if other_tail is not None else None,
                "the mass of the other side, P(u ≤ bound) at the upper bound (or the reverse)": other_tail,
            },
        )  # fmt: skip


def test_clipped_gaussian_probabilities_add_up_to_one(student):
    # the two masses and the density integrated between the bounds (the trapezoid rule on a fine grid) sum to 1
    mean, log_std = np.array([[0.3]]), np.array([np.log(0.8)])
    inner = np.linspace(-1.0, 1.0, 4001)[1:-1]
    edges = np.array([[-1.0], [1.0]])
    logp_edges = student.clipped_gaussian_log_prob(np.repeat(mean, 2, axis=0), log_std, edges, LOW, HIGH)[0]
    logp_inner = student.clipped_gaussian_log_prob(np.repeat(mean, len(inner), axis=0), log_std, inner[:, None], LOW,
                                                   HIGH)[0]  # fmt: skip
    check_array(logp_inner, "clipped_gaussian_log_prob", (len(inner),), "logp between the bounds")
    density = np.exp(logp_inner)
    total = float(np.sum(np.exp(check_array(logp_edges, "clipped_gaussian_log_prob", (2,), "logp on the bounds"))))
    total += float(np.sum((density[1:] + density[:-1]) / 2) * (inner[1] - inner[0]))
    total += float((density[0] + density[-1]) * (inner[1] - inner[0]))  # the two end intervals, to the bounds
    assert abs(total - 1.0) < 2e-3, (
        f"clipped_gaussian_log_prob: the masses on the two bounds and the density between them should add up to 1 "
        f"(μ = 0.3, σ = 0.8, bounds ±1), not {total:.4f}"
    )


def test_clipped_gaussian_gradients_match_finite_differences(student, rng):
    mean = rng.normal(0.0, 0.8, (6, 2))
    log_std = np.array([-0.4, 0.3])
    low, high = np.array([-1.0, -0.5]), np.array([1.0, 1.5])
    actions = np.clip(mean + np.exp(log_std) * rng.normal(0.0, 1.6, (6, 2)), low, high)
    actions[0, 0], actions[1, 1], actions[2, 0] = 1.0, -0.5, -1.0  # every kind of entry, for certain
    logp, grad_mean, grad_log_std = student.clipped_gaussian_log_prob(mean, log_std, actions, low, high)
    check_array(logp, "clipped_gaussian_log_prob", (6,), "logp")
    kind = np.where(actions >= high, "on the upper bound", np.where(actions <= low, "on the lower bound", "inside"))
    m = mean.copy()
    numeric = numerical_gradient(
        lambda: float(np.sum(student.clipped_gaussian_log_prob(m, log_std, actions, low, high)[0])), m, 1e-6
    )
    check_array(grad_mean, "clipped_gaussian_log_prob", (6, 2), "grad_mean")
    off = ~np.isclose(grad_mean, numeric, rtol=1e-5, atol=1e-8)
    std = np.exp(log_std)[None, :] * np.ones((6, 1))
    if off.any() and np.allclose(grad_mean[off] / numeric[off], std[off], rtol=1e-4) and (kind[off] != "inside").all():
        raise AssertionError(
            "clipped_gaussian_log_prob: ∂ log p/∂μ on the bounds is σ times the finite differences': the chain rule's "
            "∂x/∂μ = −1/σ of the standardised bound x = (bound − μ)/σ forgotten?"
        )
    check_close(grad_mean, numeric,
                "clipped_gaussian_log_prob", "∂ log p/∂μ (finite differences)", 1e-5, 1e-8,
                where=lambda i: f"the action is {kind[i]}")  # fmt: skip
    s = log_std.copy()
    numeric = numerical_gradient(
        lambda: float(np.sum(student.clipped_gaussian_log_prob(mean, s, actions, low, high)[0])), s, 1e-6
    )
    check_close(
        check_array(grad_log_std, "clipped_gaussian_log_prob", (2,), "grad_log_std"),
        numeric,
        "clipped_gaussian_log_prob",
        "∂(Σ log p)/∂ log σ (finite differences)",
        1e-5,
        1e-8,
        n=6,
    )


def test_clipped_gaussian_far_in_the_tail(student):
    # the bound 25 standard deviations below the mean: its mass is about 3e-138, its log finite
    mean, log_std = np.array([[0.0]]), np.array([np.log(0.04)])
    logp, grad_mean, _ = student.clipped_gaussian_log_prob(mean, log_std, np.array([[-1.0]]), LOW, HIGH)
    expected = math.log(normal_cdf(-25.0))
    check_close(check_array(logp, "clipped_gaussian_log_prob", (1,), "logp far in the tail"), [expected],
                "clipped_gaussian_log_prob", "log P(u ≤ −1) with μ = 0, σ = 0.04 (25 σ away: take the log of a "
                "function that keeps its precision there, such as math.erfc)", rtol=1e-8)  # fmt: skip
    check_array(grad_mean, "clipped_gaussian_log_prob", (1, 1), "grad_mean far in the tail")
