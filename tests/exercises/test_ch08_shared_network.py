"""Grading chapter 8: the value loss (plain and clipped) and L^{CLIP+VF+S} against direct sums, finite differences
and the signs each term must have."""

import _harness
import numpy as np
import pytest
from _harness import call_checking_inputs, check_array, check_close, check_scalar, expect_number, numerical_gradient

student = _harness.student  # the fixture: the implementation under test (see _harness.py)
pytest_generate_tests = _harness.pytest_generate_tests  # one run per wrong variant under MINIPPO_IMPL=wrong
rng = _harness.rng  # a seeded NumPy Generator

pytestmark = pytest.mark.timeout(10)


# (V, V_old, V^targ, ε) for one sample, and what happens there
VALUE_CASES = [
    (-0.5, 0.0, 1.0, 0.2, "V moved 0.5 > ε away from the target: the unclipped error is larger"),
    (0.5, 0.0, 1.0, 0.2, "V moved 0.5 > ε toward the target: the clipped error is larger, and V^clip is flat there"),
    (0.1, 0.0, 1.0, 0.2, "V moved 0.1 < ε: V^clip = V, the two errors are equal"),
    (2.0, 1.0, 0.0, 0.4, "V moved 1 > ε away from the target: the unclipped error is larger"),
    # V outside [−ε, ε] with the target elsewhere than 0: clipping V itself and clipping V − V^targ part ways here
    (0.3, 1.0, 0.9, 0.1, "V moved 0.7 > ε, past the target: the unclipped error is larger"),
    (0.3, 1.0, 0.0, 0.4, "V moved 0.7 > ε toward the target: the clipped error is larger, and V^clip is flat there"),
]


@pytest.mark.parametrize("n", [1, 7])
def test_value_loss_value_and_gradient(student, rng, n):
    values, targets = rng.normal(size=n), rng.normal(size=n)
    loss, grad = call_checking_inputs(student.value_loss, "value_loss", values, targets)
    expected = sum(0.5 * (v - g) ** 2 for v, g in zip(values, targets)) / n
    check_close(check_scalar(loss, "value_loss"), expected, "value_loss", "the loss ½ Ê[(V − V^targ)²]")
    check_array(grad, "value_loss", (n,), "the gradient")
    numeric = numerical_gradient(lambda: float(student.value_loss(values, targets)[0]), values)
    check_close(grad, numeric, "value_loss", "∂L^VF/∂V (checked by finite differences; it should be (V − V^targ)/n)")


@pytest.mark.parametrize("v, v_old, target, epsilon, case", VALUE_CASES, ids=[str(i) for i in range(len(VALUE_CASES))])
def test_clipped_value_loss_one_sample(student, v, v_old, target, epsilon, case):
    loss, grad = student.clipped_value_loss(np.array([v]), np.array([target]), np.array([v_old]), epsilon)
    clipped = v_old + min(max(v - v_old, -epsilon), epsilon)
    error, clipped_error = v - target, clipped - target
    sample = f"one sample with V = {v}, V_old = {v_old}, V^targ = {target}, ε = {epsilon}"
    expected_loss = 0.5 * max(error**2, clipped_error**2)
    loss_mistakes = {  # the mistakes computed exactly first; the min, which the plain loss also gives here, after
        "V clipped around V^targ instead of around V_old (V^clip = V_old + clip(V − V_old, −ε, ε))": 0.5
        * max(error**2, min(max(error, -epsilon), epsilon) ** 2),
        "V itself clipped to [−ε, ε] instead of its change V − V_old": 0.5
        * max(error**2, (min(max(v, -epsilon), epsilon) - target) ** 2),
        "the smaller of the two errors (min): the clipped loss is pessimistic, it takes the max": 0.5
        * min(error**2, clipped_error**2),
        "ε fixed at 0.2 (the epsilon argument ignored)": None
        if epsilon == 0.2
        else 0.5 * max(error**2, (v_old + min(max(v - v_old, -0.2), 0.2) - target) ** 2),
        "the plain loss ½ (V − V^targ)², as if nothing were clipped": 0.5 * error**2,
    }
    expect_number(loss, expected_loss, "clipped_value_loss", f"the loss for {sample}", case, alternatives=loss_mistakes)
    check_array(grad, "clipped_value_loss", (1,), f"the gradient for {sample}")
    use_clipped = clipped_error**2 > error**2
    expected_grad = 0.0 if use_clipped else error
    grad_mistakes = {"the clipped branch's error passed on outside the band, where V^clip is a constant": clipped_error}
    expect_number(
        grad, expected_grad, "clipped_value_loss", f"the gradient for {sample}", case, alternatives=grad_mistakes
    )


def reference_clipped_value_loss(values, targets, values_old, epsilon):
    total = 0.0
    for v, g, old in zip(values, targets, values_old):
        clipped = old + min(max(v - old, -epsilon), epsilon)
        total += 0.5 * max((v - g) ** 2, (clipped - g) ** 2)
    return total / len(values)


@pytest.fixture
def value_batch(rng):
    # V moved by 0.05 … 0.9 from V_old, in both directions; ε = 0.2 with no sample near the edges of the band
    values_old = rng.normal(size=12)
    moves = np.array([0.05, -0.1, 0.15, -0.05, 0.5, -0.6, 0.9, -0.3, 0.35, -0.45, 0.12, -0.7])  # clear of ±0.2, ±0.4
    targets = values_old + rng.normal(0, 0.6, 12)
    return values_old + moves, targets, values_old


@pytest.mark.parametrize("epsilon", [0.2, 0.4])
def test_clipped_value_loss_value_and_gradient(student, value_batch, epsilon):
    values, targets, values_old = value_batch
    loss, grad = call_checking_inputs(
        student.clipped_value_loss, "clipped_value_loss", values, targets, values_old, epsilon
    )
    expected = reference_clipped_value_loss(values, targets, values_old, epsilon)
    check_close(
        check_scalar(loss, "clipped_value_loss"),
        expected,
        "clipped_value_loss",
        f"the loss ½ Ê[max((V − V^targ)², (V^clip − V^targ)²)], ε = {epsilon}",
    )
    check_array(grad, "clipped_value_loss", (12,), "the gradient")
    numeric = numerical_gradient(lambda: reference_clipped_value_loss(values, targets, values_old, epsilon), values)
    moves = values - values_old
    check_close(
        grad,
        numeric,
        "clipped_value_loss",
        f"∂L/∂V (checked by finite differences), ε = {epsilon}",
        where=lambda i: f"V − V_old = {moves[i]:.3g}, V − V^targ = {values[i] - targets[i]:.3g}",
    )


def test_clipped_value_loss_is_never_below_the_plain_loss(student, value_batch):
    values, targets, values_old = value_batch
    clipped, _ = student.clipped_value_loss(values, targets, values_old, 0.2)
    plain = 0.5 * float(np.mean((values - targets) ** 2))
    assert check_scalar(clipped, "clipped_value_loss") >= plain - 1e-12, (
        f"clipped_value_loss: the clipped loss takes the larger error, so it is never below ½ Ê[(V − V^targ)²] = "
        f"{plain:.6g}, but it is {clipped:.6g}"
    )


def test_clipped_value_loss_inside_the_band_is_the_plain_loss(student, rng):
    values_old, targets = rng.normal(size=6), rng.normal(size=6)
    values = values_old + rng.uniform(-0.15, 0.15, 6)
    loss, grad = student.clipped_value_loss(values, targets, values_old, 0.2)
    check_close(
        check_scalar(loss, "clipped_value_loss"),
        0.5 * np.mean((values - targets) ** 2),
        "clipped_value_loss",
        "the loss when every V is within ε of V_old (it is the plain loss)",
    )
    check_close(grad, (values - targets) / 6, "clipped_value_loss", "the gradient within the band ((V − V^targ)/n)")


def reference_objective(logp, logp_old, advantages, values, targets, entropy, epsilon, c1, c2):
    ratio = np.exp(logp - logp_old)
    clip_term = np.mean(np.minimum(ratio * advantages, np.clip(ratio, 1 - epsilon, 1 + epsilon) * advantages))
    return clip_term - c1 * 0.5 * np.mean((values - targets) ** 2) + c2 * np.mean(entropy)


@pytest.fixture
def objective_batch(rng):
    n = 9
    logp_old = rng.normal(-1.2, 0.4, n)
    ratios = np.array([0.5, 0.7, 0.9, 1.0, 1.1, 1.3, 1.6, 1.21, 0.81])  # 1.21 and 0.81: between 1 ± ε and e^±ε
    return (
        np.log(ratios) + logp_old,
        logp_old,
        rng.normal(size=n),
        rng.normal(size=n),
        rng.normal(size=n),
        rng.uniform(0.1, 1.0, n),
    )


def test_clip_vf_s_objective_signs(student):
    # a better value fit and a more random policy must both raise the objective
    logp = np.zeros(2)
    base = student.clip_vf_s_objective(logp, logp, np.ones(2), np.zeros(2), np.ones(2), np.full(2, 0.5), 0.2, 0.5, 0.1)
    closer = student.clip_vf_s_objective(
        logp, logp, np.ones(2), np.full(2, 0.5), np.ones(2), np.full(2, 0.5), 0.2, 0.5, 0.1
    )
    wider = student.clip_vf_s_objective(logp, logp, np.ones(2), np.zeros(2), np.ones(2), np.full(2, 0.9), 0.2, 0.5, 0.1)
    assert check_scalar(closer[0], "clip_vf_s_objective") > check_scalar(base[0], "clip_vf_s_objective"), (
        "clip_vf_s_objective: moving V toward V^targ should raise the objective (the value loss enters with −c1)"
    )
    assert check_scalar(wider[0], "clip_vf_s_objective") > check_scalar(base[0], "clip_vf_s_objective"), (
        "clip_vf_s_objective: a higher entropy should raise the objective (the bonus enters with +c2)"
    )


@pytest.mark.parametrize("c1, c2, epsilon", [(0.5, 0.01, 0.2), (1.0, 0.0, 0.2), (2.0, 0.5, 0.2), (0.5, 0.01, 0.35)])
def test_clip_vf_s_objective_value_and_gradients(student, objective_batch, c1, c2, epsilon):
    logp, logp_old, advantages, values, targets, entropy = objective_batch
    args = (logp, logp_old, advantages, values, targets, entropy, epsilon, c1, c2)
    value, grad_logp, grad_values, grad_entropy = call_checking_inputs(
        student.clip_vf_s_objective, "clip_vf_s_objective", *args
    )
    logp, logp_old, advantages, values, targets, entropy = objective_batch
    mistakes = {
        "ε fixed at 0.2 (the epsilon argument ignored)": None
        if epsilon == 0.2
        else reference_objective(*args[:6], 0.2, c1, c2),
        "the value loss added (+c1 L^VF); it enters with a minus": reference_objective(*args[:7], -c1, c2),
        "the entropy bonus subtracted (−c2 S); it enters with a plus": reference_objective(*args[:7], c1, -c2),
        "c1 and c2 swapped": reference_objective(*args[:7], c2, c1),
        "the value loss without its ½": reference_objective(*args[:7], 2 * c1, c2),
        "the entropy summed over the batch, not averaged": reference_objective(*args[:7], c1, c2 * len(logp)),
        "the value error summed over the batch, not averaged": reference_objective(*args[:7], c1 * len(logp), c2),
    }
    expect_number(
        value,
        reference_objective(*args),
        "clip_vf_s_objective",
        f"the value L^CLIP − c1 L^VF + c2 S (c1 = {c1}, c2 = {c2}, ε = {epsilon})",
        alternatives=mistakes,
    )
    for grad, variable, what in [
        (grad_logp, logp, "∂L/∂ log π"),
        (grad_values, values, "∂L/∂V"),
        (grad_entropy, entropy, "∂L/∂S"),
    ]:
        check_array(grad, "clip_vf_s_objective", (9,), what)
        check_close(
            grad,
            numerical_gradient(lambda: float(reference_objective(*args)), variable, 1e-7),
            "clip_vf_s_objective",
            f"{what} (checked by finite differences, c1 = {c1}, c2 = {c2}, ε = {epsilon})",
        )


# the transfer task: the Huber value loss


def test_huber_value_loss_of_single_errors(student):
    # δ = 1: errors 0.5 (quadratic part), 3 and −3 (linear part)
    for error, loss, slope in [(0.5, 0.125, 0.5), (3.0, 2.5, 1.0), (-3.0, 2.5, -1.0)]:
        result = _harness.call_checking_inputs(
            student.huber_value_loss, "huber_value_loss", np.array([error]), np.array([0.0]), 1.0
        )
        assert isinstance(result, tuple) and len(result) == 2, "huber_value_loss should return (loss, grad)"
        expect_number(
            result[0], loss, "huber_value_loss", f"the loss for one error e = {error} with δ = 1",
            alternatives={"δ |e| without the −½δ² that joins the line to the parabola": abs(error),
                          "½ e², the squared error everywhere": 0.5 * error * error},
        )  # fmt: skip
        expect_number(
            check_array(result[1], "huber_value_loss", (1,), "the gradient")[0], slope, "huber_value_loss",
            f"the gradient for one error e = {error} with δ = 1",
            alternatives={"the squared error's gradient e, unclipped": error if abs(error) > 1 else None},
        )  # fmt: skip


def test_huber_value_loss_matches_finite_differences(student, rng):
    values, targets = rng.normal(0.0, 3.0, 9), rng.normal(0.0, 1.0, 9)
    loss, grad = student.huber_value_loss(values, targets, 1.5)
    error = values - targets
    expected = np.mean(np.where(np.abs(error) <= 1.5, 0.5 * error**2, 1.5 * (np.abs(error) - 0.75)))
    check_close(check_scalar(loss, "huber_value_loss"), expected, "huber_value_loss", "the mean Huber loss, δ = 1.5")
    v = values.copy()
    numeric = numerical_gradient(lambda: float(student.huber_value_loss(v, targets, 1.5)[0]), v, 1e-6)
    sign_only = np.where(np.abs(error) <= 1.5, error, np.sign(error)) / 9
    if np.allclose(grad, sign_only) and not np.allclose(sign_only, numeric):
        raise AssertionError(
            "huber_value_loss: beyond δ = 1.5 the gradient is sign(e) / n, without the line's slope δ: the linear "
            "part is δ (|e| − ½ δ), whose derivative is δ sign(e)?"
        )
    check_close(
        check_array(grad, "huber_value_loss", (9,), "the gradient"),
        numeric,
        "huber_value_loss",
        "∂loss/∂V (finite differences), δ = 1.5",
        1e-5,
        1e-8,
        where={"e_t": error},
    )
