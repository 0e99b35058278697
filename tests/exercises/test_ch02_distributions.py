"""Grading chapter 2: log-probabilities against densities written out, entropies against brute-force sums and Monte
Carlo, gradients against finite differences, and logits far from zero."""

import _harness
import numpy as np
import pytest
from _harness import call_checking_inputs, check_array, check_close, numerical_gradient

student = _harness.student  # the fixture: the implementation under test (see _harness.py)
pytest_generate_tests = _harness.pytest_generate_tests  # one run per wrong variant under MINIPPO_IMPL=wrong
rng = _harness.rng  # a seeded NumPy Generator

pytestmark = pytest.mark.timeout(15)


def reference_categorical_log_prob(logits, actions):
    """log(exp z_a / Σ_j exp z_j) written out, sample by sample (fine for moderate logits)."""
    return np.array([np.log(np.exp(row[a]) / np.sum(np.exp(row))) for row, a in zip(logits, actions)])


def reference_gaussian_log_prob(mean, log_std, actions):
    """The log of a product of one-dimensional normal densities."""
    std = np.exp(log_std)
    densities = np.exp(-0.5 * ((actions - mean) / std) ** 2) / (np.sqrt(2 * np.pi) * std)
    return np.log(np.prod(densities, axis=-1))


@pytest.fixture
def logits(rng):
    return rng.normal(0, 1.5, (6, 4))


@pytest.fixture
def actions(rng):
    return np.array([0, 3, 1, 2, 3, 0])


# categorical


def test_log_softmax_matches_the_definition(student, logits):
    result = call_checking_inputs(student.log_softmax, "log_softmax", logits)
    check_array(result, "log_softmax", (6, 4))
    expected = [[np.log(np.exp(z) / np.sum(np.exp(row))) for z in row] for row in logits]
    check_close(result, expected, "log_softmax", "log π_j = z_j − log Σ exp z")
    check_close(np.exp(result).sum(axis=1), np.ones(6), "log_softmax", "Σ_j exp(log π_j) (it should be 1 per row)")
    check_close(
        student.log_softmax(logits + 40.0),
        result,
        "log_softmax",
        "the result for z + 40 (it should not change: adding a constant to every logit leaves the softmax as it is)",
    )


def test_log_softmax_survives_extreme_logits(student):
    logits = np.array([[1000.0, 0.0, -1000.0], [-1000.0, -1000.0, -1000.0], [-1000.0, 1000.0, 0.0]])
    result = student.log_softmax(logits)
    check_array(result, "log_softmax", (3, 3), "the result for logits of ±1000 (subtract each row's max first)")
    expected = [[0.0, -1000.0, -2000.0], [-np.log(3.0)] * 3, [-2000.0, 0.0, -1000.0]]
    check_close(result, expected, "log_softmax", "log π for logits of ±1000")


def test_categorical_log_prob_matches_the_softmax(student, logits, actions):
    logp = call_checking_inputs(student.categorical_log_prob, "categorical_log_prob", logits, actions)
    check_array(logp, "categorical_log_prob", (6,))
    check_close(logp, reference_categorical_log_prob(logits, actions), "categorical_log_prob", "log π(a|s)")
    one = student.categorical_log_prob(logits[:1], actions[:1])
    check_array(one, "categorical_log_prob", (1,), "the result for a batch of one")


def test_categorical_probabilities_sum_to_one(student, logits):
    total = sum(np.exp(student.categorical_log_prob(logits, np.full(6, a))) for a in range(4))
    check_close(total, np.ones(6), "categorical_log_prob", "Σ_a π(a|s) (it should be 1 for every state)")


def test_categorical_log_prob_survives_extreme_logits(student):
    # log Σ exp of (1000, 0, −1000) is 1000 to double precision, so the log-probabilities are 0, −1000, −2000
    logits = np.array([[1000.0, 0.0, -1000.0]] * 3 + [[-1000.0, -1000.0, -1000.0]])
    logp = student.categorical_log_prob(logits, np.array([0, 1, 2, 1]))
    check_array(logp, "categorical_log_prob", (4,), "the log-probabilities for logits of ±1000 (subtract the max)")
    check_close(logp, [0.0, -1000.0, -2000.0, -np.log(3.0)], "categorical_log_prob", "log π for logits of ±1000")


@pytest.mark.parametrize("scale", [1.0, 30.0], ids=["moderate", "large-logits"])
def test_categorical_log_prob_backward_matches_finite_differences(student, rng, actions, scale):
    logits = rng.normal(0, scale, (6, 4))
    grad_logp = rng.normal(size=6)
    grad = call_checking_inputs(
        student.categorical_log_prob_backward, "categorical_log_prob_backward", logits, actions, grad_logp
    )
    check_array(grad, "categorical_log_prob_backward", (6, 4))
    shifted = lambda: logits - logits.max(axis=1, keepdims=True)  # noqa: E731 - keeps the reference finite
    expected = numerical_gradient(
        lambda: float(grad_logp @ reference_categorical_log_prob(shifted(), actions)), logits, 1e-5
    )
    check_close(grad, expected, "categorical_log_prob_backward", "∂L/∂z (checked by finite differences)", 1e-5, 1e-7)


EXTREME_LOGITS = np.array(
    [
        [1000.0, 999.0, 0.0, -1000.0],
        [800.0, 800.0, 800.0, 800.0],
        [-1000.0, -1000.0, 0.0, 0.5],
        [0.0, 30.0, 700.0, 699.0],
    ]
)


def stable_log_softmax(logits):
    shifted = logits - logits.max(axis=1, keepdims=True)
    return shifted - np.log(np.exp(shifted).sum(axis=1, keepdims=True))


def test_categorical_log_prob_backward_at_extreme_logits(student):
    actions, grad_logp = np.array([1, 2, 3, 0]), np.array([1.0, -2.0, 0.5, 3.0])
    grad = student.categorical_log_prob_backward(EXTREME_LOGITS, actions, grad_logp)
    check_array(grad, "categorical_log_prob_backward", (4, 4), "∂L/∂z for logits near ±1000 (subtract each row's max)")
    expected = -np.exp(stable_log_softmax(EXTREME_LOGITS)) * grad_logp[:, None]
    expected[np.arange(4), actions] += grad_logp
    check_close(
        grad,
        expected,
        "categorical_log_prob_backward",
        "∂L/∂z = ∂L/∂ log π · (onehot(a) − π) for logits near ±1000 (π from the max-shifted softmax)",
        where=lambda i: f"row {i[0]}, z = {EXTREME_LOGITS[i[0]].tolist()}",
    )


def test_categorical_entropy_matches_the_sum(student, logits):
    entropy = call_checking_inputs(student.categorical_entropy, "categorical_entropy", logits)
    check_array(entropy, "categorical_entropy", (6,))
    probs = np.exp(logits) / np.exp(logits).sum(axis=1, keepdims=True)
    expected = [-sum(p * np.log(p) for p in row) for row in probs]
    check_close(entropy, expected, "categorical_entropy", "S = −Σ π log π")


def test_categorical_entropy_limits(student):
    logits = np.array([[0.3, 0.3, 0.3, 0.3], [1000.0, 0.0, 0.0, -5.0], [-1000.0, 500.0, 500.0, 0.0]])
    entropy = student.categorical_entropy(logits)
    check_array(entropy, "categorical_entropy", (3,), "the entropy when some probabilities round to 0 (0·log 0 = 0)")
    check_close(
        entropy, [np.log(4.0), 0.0, np.log(2.0)], "categorical_entropy", "the entropy (uniform: log k; certain: 0)"
    )


def test_categorical_entropy_backward_matches_finite_differences(student, logits, rng):
    grad_entropy = rng.normal(size=6)
    grad = call_checking_inputs(
        student.categorical_entropy_backward, "categorical_entropy_backward", logits, grad_entropy
    )
    check_array(grad, "categorical_entropy_backward", (6, 4))

    def weighted_entropy():
        probs = np.exp(logits) / np.exp(logits).sum(axis=1, keepdims=True)
        return float(grad_entropy @ -(probs * np.log(probs)).sum(axis=1))

    expected = numerical_gradient(weighted_entropy, logits)
    check_close(grad, expected, "categorical_entropy_backward", "∂L/∂z (checked by finite differences)", 1e-5, 1e-7)


def test_categorical_entropy_backward_at_extreme_logits(student):
    grad_entropy = np.array([1.0, -2.0, 0.5, 3.0])
    grad = student.categorical_entropy_backward(EXTREME_LOGITS, grad_entropy)
    check_array(grad, "categorical_entropy_backward", (4, 4), "∂L/∂z for logits near ±1000 (subtract each row's max)")
    log_probs = stable_log_softmax(EXTREME_LOGITS)
    probs = np.exp(log_probs)
    entropy = -(probs * log_probs).sum(axis=1)
    expected = -probs * (log_probs + entropy[:, None]) * grad_entropy[:, None]
    check_close(
        grad,
        expected,
        "categorical_entropy_backward",
        "∂L/∂z = −π (log π + S) ∂L/∂S for logits near ±1000 (π and log π from the max-shifted log-softmax)",
        where=lambda i: f"row {i[0]}, z = {EXTREME_LOGITS[i[0]].tolist()}",
    )


# diagonal Gaussian


@pytest.fixture
def gaussian(rng):
    mean = rng.normal(size=(5, 3))
    log_std = np.array([-0.7, 0.0, 0.4])
    actions = mean + np.exp(log_std) * rng.normal(size=(5, 3)) * 1.5
    return mean, log_std, actions


def test_gaussian_log_prob_matches_the_density(student, gaussian):
    mean, log_std, actions = gaussian
    logp = call_checking_inputs(student.gaussian_log_prob, "gaussian_log_prob", mean, log_std, actions)
    check_array(logp, "gaussian_log_prob", (5,))
    expected = reference_gaussian_log_prob(mean, log_std, actions)
    offset = logp - expected
    assert not (np.allclose(offset, offset[0], rtol=0, atol=1e-9) and abs(offset[0]) > 1e-6), (
        f"gaussian_log_prob: log π(a|s) is off by the same {offset[0]:.6g} in every row (d = 3, Σ log σ_i = "
        f"{log_std.sum():.4g}): one of the terms that do not depend on a, −Σ log σ_i or −(d/2) log 2π = "
        f"{-1.5 * np.log(2 * np.pi):.6g}, is wrong"
    )
    check_close(logp, expected, "gaussian_log_prob", "log π(a|s)")
    one = student.gaussian_log_prob(mean[:1], log_std, actions[:1])
    check_array(one, "gaussian_log_prob", (1,), "the result for a batch of one")


@pytest.mark.parametrize("log_std", [np.log(0.3), 0.0, np.log(2.5)], ids=["narrow", "unit", "wide"])
def test_gaussian_density_integrates_to_one(student, log_std):
    # ∫ π(a) da over a fine grid: it is 1 only with both the log σ and the ½ log 2π terms
    grid = np.linspace(-12 * np.exp(log_std), 12 * np.exp(log_std), 40001)[:, None] + 0.4
    logp = student.gaussian_log_prob(np.full_like(grid, 0.4), np.array([log_std]), grid)
    check_array(logp, "gaussian_log_prob", (len(grid),))
    density = np.exp(logp)
    total = float(np.sum((density[1:] + density[:-1]) / 2 * np.diff(grid[:, 0])))
    assert abs(total - 1.0) < 1e-6, f"gaussian_log_prob: exp(log π) should integrate to 1 over a, but gives {total:.6g}"


def test_gaussian_log_prob_far_in_the_tail(student):
    logp = student.gaussian_log_prob(np.zeros((1, 2)), np.zeros(2), np.array([[1000.0, -1000.0]]))
    check_array(logp, "gaussian_log_prob", (1,), "the log-probability of an action 1000 σ away")
    check_close(logp, [-1_000_000.0 - np.log(2 * np.pi)], "gaussian_log_prob", "the log-probability 1000 σ away")


def test_gaussian_log_prob_backward_matches_finite_differences(student, gaussian, rng):
    mean, log_std, actions = gaussian
    grad_logp = rng.normal(size=5)
    grad_mean, grad_log_std = call_checking_inputs(
        student.gaussian_log_prob_backward, "gaussian_log_prob_backward", mean, log_std, actions, grad_logp
    )
    check_array(grad_mean, "gaussian_log_prob_backward", (5, 3), "∂L/∂μ")
    check_array(grad_log_std, "gaussian_log_prob_backward", (3,), "∂L/∂ log σ (summed over the batch)")

    def loss():
        return float(grad_logp @ reference_gaussian_log_prob(mean, log_std, actions))

    check_close(grad_mean, numerical_gradient(loss, mean), "gaussian_log_prob_backward", "∂L/∂μ", 1e-5, 1e-7)
    numeric = numerical_gradient(loss, log_std)
    check_close(grad_log_std, numeric, "gaussian_log_prob_backward", "∂L/∂ log σ", 1e-5, 1e-7, n=5)


def test_gaussian_entropy_matches_monte_carlo(student, rng):
    mean = rng.normal(size=(4, 3))
    log_std = np.array([-0.5, 0.3, 0.8])  # Σ log σ ≠ 0, so a wrong factor on it shows
    entropy = call_checking_inputs(student.gaussian_entropy, "gaussian_entropy", mean, log_std)
    check_array(entropy, "gaussian_entropy", (4,), "the entropy (one number per state)")
    samples = mean[0] + np.exp(log_std) * rng.normal(size=(200_000, 3))
    estimate = -np.mean(reference_gaussian_log_prob(mean[0], log_std, samples))  # S = E[−log π(a)]
    assert np.all(np.abs(entropy - estimate) < 0.02), (
        f"gaussian_entropy: a Monte Carlo estimate of E[−log π] is {estimate:.4f}, but the entropy returned is "
        f"{entropy[0]:.4f}"
    )


def test_gaussian_entropy_backward_matches_finite_differences(student, rng):
    mean, log_std, grad_entropy = rng.normal(size=(4, 2)), np.array([0.3, -0.5]), rng.normal(size=4)
    grad_mean, grad_log_std = call_checking_inputs(
        student.gaussian_entropy_backward, "gaussian_entropy_backward", mean, log_std, grad_entropy
    )
    check_array(grad_mean, "gaussian_entropy_backward", (4, 2), "∂L/∂μ")
    check_array(grad_log_std, "gaussian_entropy_backward", (2,), "∂L/∂ log σ (summed over the batch)")

    def loss():  # S = E[−log π], closed form per dimension: log σ + ½ log 2πe
        return float(np.sum(grad_entropy) * np.sum(log_std + 0.5 * np.log(2 * np.pi * np.e)))

    check_close(grad_mean, np.zeros((4, 2)), "gaussian_entropy_backward", "∂L/∂μ (the entropy does not depend on μ)")
    check_close(grad_log_std, numerical_gradient(loss, log_std), "gaussian_entropy_backward", "∂L/∂ log σ", n=4)


# the transfer task: a categorical with a temperature


@pytest.fixture
def tempered_case(rng):
    return rng.normal(0.0, 2.0, (6, 4)), rng.integers(0, 4, 6)


def test_tempered_categorical_at_temperature_one_is_the_categorical(student, tempered_case):
    logits, actions = tempered_case
    result = _harness.call_checking_inputs(
        student.tempered_categorical_log_prob, "tempered_categorical_log_prob", logits, 1.0, actions
    )
    assert isinstance(result, tuple) and len(result) == 3, (
        "tempered_categorical_log_prob should return (logp, grad_logits, grad_temperature)"
    )
    logp = _harness.check_array(result[0], "tempered_categorical_log_prob", (6,), "logp")
    log_probs = logits - np.log(np.exp(logits).sum(axis=1, keepdims=True))
    _harness.check_close(logp, log_probs[np.arange(6), actions], "tempered_categorical_log_prob", "logp at τ = 1")
    grad_logits = _harness.check_array(result[1], "tempered_categorical_log_prob", (6, 4), "grad_logits")
    score = -np.exp(log_probs)
    score[np.arange(6), actions] += 1.0
    _harness.check_close(grad_logits, score, "tempered_categorical_log_prob", "∂ log π/∂z at τ = 1 (chapter 2's score)")


def test_tempered_categorical_at_extreme_logits(student, rng):
    logits = np.array([[1000.0, -1000.0, 0.0]])
    logp, grad_logits, grad_temperature = student.tempered_categorical_log_prob(logits, 0.5, np.array([1]))
    _harness.check_array(logp, "tempered_categorical_log_prob", (1,), "logp for logits of ±1000 and τ = 0.5")
    _harness.check_close(logp, [-4000.0], "tempered_categorical_log_prob", "logp for logits of ±1000 and τ = 0.5")
    _harness.check_array(grad_logits, "tempered_categorical_log_prob", (1, 3), "grad_logits for logits of ±1000")
    _harness.check_array(grad_temperature, "tempered_categorical_log_prob", (1,), "grad_temperature, logits of ±1000")


@pytest.mark.parametrize("temperature", [0.5, 2.0])
def test_tempered_categorical_matches_finite_differences(student, tempered_case, temperature):
    logits, actions = tempered_case
    logp, grad_logits, grad_temperature = student.tempered_categorical_log_prob(logits, temperature, actions)
    name = "tempered_categorical_log_prob"
    _harness.check_array(grad_logits, name, (6, 4), "grad_logits")
    _harness.check_array(grad_temperature, name, (6,), "grad_temperature")

    def log_prob(z, tau):
        scaled = z / tau
        return (scaled - np.log(np.exp(scaled).sum(axis=1, keepdims=True)))[np.arange(6), actions]

    z = logits.copy()
    numeric = np.zeros((6, 4))
    for row in range(6):
        numeric[row] = _harness.numerical_gradient(lambda row=row: float(log_prob(z, temperature)[row]), z[row], 1e-6)
    _harness.check_close(
        grad_logits, numeric, name, f"∂ log π/∂z at τ = {temperature} (checked by finite differences)", 1e-5, 1e-7
    )
    tau = np.array([temperature])
    numeric_tau = np.array(
        [
            _harness.numerical_gradient(lambda row=row: float(log_prob(logits, tau[0])[row]), tau, 1e-6)[0]
            for row in range(6)
        ]
    )
    where = {"τ": temperature}
    if np.allclose(grad_temperature, -numeric_tau, rtol=1e-5, atol=1e-7):
        raise AssertionError(f"{name}: ∂ log π/∂τ has the opposite sign everywhere (τ divides the logits)")
    if np.allclose(grad_temperature, -logits[np.arange(6), actions] / temperature**2, rtol=1e-6, atol=1e-9):
        raise AssertionError(
            f"{name}: ∂ log π/∂τ at τ = {temperature} is −z_a/τ², the derivative of the chosen logit's term alone: the "
            "normaliser log Σ exp(z/τ) depends on τ too?"
        )
    _harness.check_close(
        grad_temperature, numeric_tau, name, f"∂ log π/∂τ at τ = {temperature} (checked by finite differences)",
        1e-5, 1e-7, where=where,
    )  # fmt: skip
