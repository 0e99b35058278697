"""Both distributions: values against closed forms / SciPy-free references, gradients against finite differences."""

import numpy as np
import pytest
from conftest import assert_close, numerical_gradient

from minippo.distributions import Categorical, DiagGaussian


def categorical_case(rng):
    logits = rng.standard_normal((5, 4)) * 2
    actions = rng.integers(0, 4, 5)
    return logits, actions, rng.standard_normal(5)


def test_categorical_values(rng):
    logits, actions, _ = categorical_case(rng)
    probs = np.exp(logits) / np.exp(logits).sum(axis=1, keepdims=True)
    dist = Categorical(logits)
    assert np.allclose(dist.log_prob(actions), np.log(probs[np.arange(5), actions]))
    assert np.allclose(dist.entropy(), -(probs * np.log(probs)).sum(axis=1))
    assert np.allclose(dist.kl(dist), 0.0)


def test_categorical_is_stable_for_huge_logits():
    dist = Categorical(np.array([[1000.0, 0.0, -1000.0]]))
    assert np.isfinite(dist.log_prob(np.array([2]))).all() and np.isclose(dist.log_prob(np.array([0]))[0], 0.0)


@pytest.mark.parametrize("quantity", ["log_prob", "entropy", "kl"])
def test_categorical_gradients(rng, quantity):
    logits, actions, weights = categorical_case(rng)
    old = Categorical(rng.standard_normal((5, 4)))

    def value():
        dist = Categorical(logits)
        out = {"log_prob": lambda: dist.log_prob(actions), "entropy": dist.entropy, "kl": lambda: dist.kl(old)}
        return float((out[quantity]() * weights).sum())

    dist = Categorical(logits)
    if quantity == "log_prob":
        (grad,) = dist.log_prob_backward(actions, weights)
    elif quantity == "entropy":
        (grad,) = dist.entropy_backward(weights)
    else:
        (grad,) = dist.kl_backward(old, weights)
    assert_close(grad, numerical_gradient(value, logits))


def test_gaussian_values_match_the_density(rng):
    mean, log_std = rng.standard_normal((3, 2)), rng.standard_normal(2) * 0.3
    actions = rng.standard_normal((3, 2))
    dist = DiagGaussian(mean, log_std)
    std = np.exp(log_std)
    density = np.prod(np.exp(-0.5 * ((actions - mean) / std) ** 2) / (std * np.sqrt(2 * np.pi)), axis=1)
    assert np.allclose(dist.log_prob(actions), np.log(density))
    assert np.allclose(dist.entropy(), np.sum(0.5 * np.log(2 * np.pi * np.e * std**2)))


def test_gaussian_entropy_and_kl_by_monte_carlo(rng):
    mean, log_std = np.array([[0.3, -1.0]]), np.array([0.2, -0.5])
    old = DiagGaussian(np.array([[0.0, -0.7]]), np.array([0.0, -0.3]))
    new = DiagGaussian(mean, log_std)
    samples = old.mean + old.std * rng.standard_normal((200_000, 2))
    logp_old = DiagGaussian(np.repeat(old.mean, len(samples), 0), old.log_std).log_prob(samples)
    logp_new = DiagGaussian(np.repeat(mean, len(samples), 0), log_std).log_prob(samples)
    assert abs(np.mean(logp_old - logp_new) - new.kl(old)[0]) < 0.01
    assert abs(-np.mean(logp_old) - old.entropy()[0]) < 0.01


@pytest.mark.parametrize("quantity", ["log_prob", "entropy", "kl"])
def test_gaussian_gradients(rng, quantity):
    mean, log_std = rng.standard_normal((4, 3)), rng.standard_normal(3) * 0.5
    actions, weights = rng.standard_normal((4, 3)), rng.standard_normal(4)
    old = DiagGaussian(rng.standard_normal((4, 3)), rng.standard_normal(3) * 0.5)

    def value():
        dist = DiagGaussian(mean, log_std)
        out = {"log_prob": lambda: dist.log_prob(actions), "entropy": dist.entropy, "kl": lambda: dist.kl(old)}
        return float((out[quantity]() * weights).sum())

    dist = DiagGaussian(mean, log_std)
    backward = {
        "log_prob": lambda: dist.log_prob_backward(actions, weights),
        "entropy": lambda: dist.entropy_backward(weights),
        "kl": lambda: dist.kl_backward(old, weights),
    }[quantity]
    grad_mean, grad_log_std = backward()
    assert_close(grad_mean, numerical_gradient(value, mean))
    assert_close(grad_log_std, numerical_gradient(value, log_std))


def test_sampling_has_the_right_moments(rng):
    dist = DiagGaussian(np.full((100_000, 1), 2.0), np.array([np.log(0.5)]))
    s = dist.sample(rng)
    assert abs(s.mean() - 2.0) < 0.01 and abs(s.std() - 0.5) < 0.01
    cat = Categorical(np.log(np.tile([[0.2, 0.5, 0.3]], (100_000, 1))))
    counts = np.bincount(cat.sample(rng), minlength=3) / 100_000
    assert np.allclose(counts, [0.2, 0.5, 0.3], atol=0.01)
