"""Every surrogate and loss: values against direct formulas, gradients against finite differences in float64."""

import numpy as np
import pytest
from conftest import assert_close, numerical_gradient

from minippo import losses


@pytest.fixture
def batch(rng):
    n = 12
    logp_old = rng.normal(-1.5, 0.5, n)
    # ratios spread across and beyond the band [0.8, 1.2], away from its edges (where the gradient jumps)
    ratios = np.array([0.5, 0.72, 0.85, 0.95, 1.05, 1.15, 1.35, 1.6, 0.6, 0.88, 1.12, 1.45])
    advantages = np.array([1.0, -1.0, 0.5, -0.3, 2.0, -2.0, 1.0, -1.0, 1.0, 1.0, -1.0, 3.0])
    return np.log(ratios) + logp_old, logp_old, advantages


def check_surrogate(function, logp, *args):
    value, grad = function(logp, *args)
    assert_close(grad, numerical_gradient(lambda: function(logp, *args)[0], logp))
    return value


def test_pg_and_cpi(batch):
    logp, logp_old, adv = batch
    assert np.isclose(check_surrogate(losses.pg_objective, logp, adv), np.mean(logp * adv))
    cpi = check_surrogate(losses.cpi_objective, logp, logp_old, adv)
    assert np.isclose(cpi, np.mean(np.exp(logp - logp_old) * adv))


def test_cpi_gradient_at_the_snapshot_equals_the_policy_gradient(batch):
    _, logp_old, adv = batch
    _, grad_cpi = losses.cpi_objective(logp_old, logp_old, adv)
    _, grad_pg = losses.pg_objective(logp_old, adv)
    assert np.allclose(grad_cpi, grad_pg)


@pytest.mark.parametrize("epsilon", [0.1, 0.2, 0.3])
def test_clip_value_gradient_and_bound(batch, epsilon):
    logp, logp_old, adv = batch
    ratio = np.exp(logp - logp_old)
    value = check_surrogate(losses.clip_objective, logp, logp_old, adv, epsilon)
    per_sample = [min(r * a, min(max(r, 1 - epsilon), 1 + epsilon) * a) for r, a in zip(ratio, adv)]
    assert np.isclose(value, np.mean(per_sample))
    assert value <= losses.cpi_objective(logp, logp_old, adv)[0] + 1e-12  # a pessimistic (lower) bound


def test_clip_gradient_is_zero_only_in_the_helped_direction(batch):
    logp, logp_old, adv = batch
    ratio = np.exp(logp - logp_old)
    _, grad = losses.clip_objective(logp, logp_old, adv, 0.2)
    helped_past_band = ((adv > 0) & (ratio > 1.2)) | ((adv < 0) & (ratio < 0.8))
    assert np.all(grad[helped_past_band] == 0)
    assert np.all(grad[~helped_past_band] != 0)


def test_kl_penalty_and_adaptive_beta(batch, rng):
    logp, logp_old, adv = batch
    kl = rng.uniform(0, 0.05, len(logp))
    value, grad_logp, grad_kl = losses.kl_penalty_objective(logp, logp_old, adv, kl, 3.0)
    assert np.isclose(value, np.mean(np.exp(logp - logp_old) * adv) - 3.0 * kl.mean())

    def objective():
        return losses.kl_penalty_objective(logp, logp_old, adv, kl, 3.0)[0]

    assert_close(grad_logp, numerical_gradient(objective, logp))
    assert_close(grad_kl, numerical_gradient(objective, kl))
    assert losses.adaptive_beta(1.0, 0.001, 0.01) == 0.5
    assert losses.adaptive_beta(1.0, 0.02, 0.01) == 2.0
    assert losses.adaptive_beta(1.0, 0.01, 0.01) == 1.0
    assert losses.adaptive_beta(1.0, 0.0067, 0.01) == 1.0  # inside [d/1.5, 1.5 d]: unchanged


@pytest.mark.parametrize("clip", [None, 0.2])
def test_value_loss(rng, clip):
    values, targets = rng.standard_normal(10), rng.standard_normal(10)
    values_old = values + rng.uniform(-0.5, 0.5, 10)
    value, grad = losses.value_loss(values, targets, values_old, clip)
    assert_close(grad, numerical_gradient(lambda: losses.value_loss(values, targets, values_old, clip)[0], values))
    if clip is None:
        assert np.isclose(value, 0.5 * np.mean((values - targets) ** 2))
    else:
        assert value >= 0.5 * np.mean((values - targets) ** 2) - 1e-12


def test_entropy_bonus_and_diagnostics(rng):
    entropy = rng.uniform(0, 2, 7)
    value, grad = losses.entropy_bonus(entropy)
    assert np.isclose(value, entropy.mean()) and np.allclose(grad, 1 / 7)
    logp_old = rng.normal(size=1000)
    assert losses.approx_kl(logp_old, logp_old) == 0.0
    assert losses.approx_kl(logp_old + rng.normal(0, 0.1, 1000), logp_old) > 0
    assert losses.clip_fraction(logp_old + np.log(1.3), logp_old, 0.2) == 1.0
    y = rng.normal(size=100)
    assert losses.explained_variance(y, y) == 1.0
    assert abs(losses.explained_variance(np.zeros(100) + y.mean(), y)) < 1e-12
