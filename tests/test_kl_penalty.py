"""The KL penalty (eq. 8) compares the new policy with the whole old policy π_θold, its σ included.

The old policy of a batch is what collected it: for a Gaussian, its means and its log σ at that moment. The update
moves log σ, so an "old" policy rebuilt from the stored means and the live log σ would see (and resist) no change of
σ at all. These tests hold π_θold fixed, as the math does, and so can see that error."""

import math

import numpy as np
import pytest
from conftest import assert_close, numerical_gradient

from minippo import Config, losses
from minippo.agent import ActorCritic, AgentSpec
from minippo.distributions import Categorical, DiagGaussian
from minippo.ppo import Trainer, loss_and_grad, old_policy


def closed_form_gaussian_kl(mean_old, log_std_old, mean, log_std):
    """KL[N(μ', σ'²) ‖ N(μ, σ²)] per sample, summed over the action's dimensions, written out in full."""
    var_old, var = np.exp(2 * log_std_old), np.exp(2 * log_std)
    terms = 0.5 * (var_old / var + (mean - mean_old) ** 2 / var - 1.0 + 2 * (log_std - log_std_old))
    return terms.sum(axis=-1)


def gaussian_minibatch(agent, rng, n=16):
    """A minibatch whose old policy is the agent itself: same means, same log σ (as right after collecting it)."""
    obs = rng.standard_normal((n, agent.obs_dim))
    out, values, _ = agent.forward(obs)
    actions = out + np.exp(agent.log_std) * rng.standard_normal(out.shape)
    return {
        "obs": obs,
        "actions": actions,
        "logp": agent.distribution(out).log_prob(actions),
        "policy_out": out.copy(),
        "policy_log_std": np.tile(agent.log_std, (n, 1)),
        "values": values.copy(),
        "advantages": rng.standard_normal(n),
        "returns": values + rng.standard_normal(n),
    }


def test_the_penalty_sees_a_change_of_sigma_alone(rng):
    agent = ActorCritic(AgentSpec(3, "continuous", 2, hidden_sizes=(8,), log_std_init=-0.5), rng)
    mb = gaussian_minibatch(agent, rng)
    agent.log_std[...] += np.array([0.25, -0.1])  # θ moved only in log σ: the means are unchanged
    config = Config(objective="klpen", entropy_coef=0.0, value_coef=0.0)

    expected = closed_form_gaussian_kl(mb["policy_out"], mb["policy_log_std"], mb["policy_out"], agent.log_std)
    assert expected.min() > 0.01  # a real change, well above rounding
    out, _, _ = agent.forward(mb["obs"])
    seen = agent.distribution(out).kl(old_policy(agent, mb))
    assert np.allclose(seen, expected, rtol=1e-12, atol=0)

    # the objective the loss reports is L^CPI − β·KL: with the ratio's part known, the KL it used can be read off
    beta = 2.0
    _, stats = loss_and_grad(agent, mb, config, kl_beta=beta)
    ratio = np.exp(agent.distribution(out).log_prob(mb["actions"]) - mb["logp"])
    advantages = (mb["advantages"] - mb["advantages"].mean()) / (mb["advantages"].std() + 1e-8)
    kl_in_loss = (np.mean(ratio * advantages) - stats["policy_objective"]) / beta
    assert kl_in_loss == pytest.approx(expected.mean(), rel=1e-9)


def test_penalty_gradient_in_log_sigma_holds_the_old_policy_fixed(rng):
    agent = ActorCritic(AgentSpec(3, "continuous", 2, hidden_sizes=(8,), log_std_init=-0.5), rng)
    agent.params[...] += 0.2 * rng.standard_normal(agent.params.shape)
    mb = gaussian_minibatch(agent, rng)
    agent.log_std[...] += np.array([0.3, -0.2])
    agent.params[:-2] += 0.05 * rng.standard_normal(agent.params.size - 2)  # the means move a little too
    config = Config(objective="klpen", entropy_coef=0.0, value_coef=0.0)

    loss_and_grad(agent, mb, config, kl_beta=3.0)
    analytic = agent.grads[-2:].copy()  # ∂loss/∂ log σ
    # mb holds π_θold's log σ as its own array, so moving agent.log_std here leaves the old policy where it was
    numeric = numerical_gradient(lambda: loss_and_grad(agent, mb, config, kl_beta=3.0)[0], agent.log_std)
    assert_close(analytic, numeric, rtol=1e-7, atol=1e-9)
    # and the penalty's part of it is β ∂KL/∂ log σ with KL[π_old ‖ π_θ] in closed form, π_old's σ held fixed
    no_penalty = numerical_gradient(lambda: loss_and_grad(agent, mb, config, kl_beta=0.0)[0], agent.log_std)
    out, _, _ = agent.forward(mb["obs"])
    mean_kl = lambda: closed_form_gaussian_kl(mb["policy_out"], mb["policy_log_std"], out, agent.log_std).mean()  # noqa: E731
    assert_close(numeric - no_penalty, 3.0 * numerical_gradient(mean_kl, agent.log_std), rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("env_id", ["Hopper-v5", "Pendulum-v1"])
def test_one_klpen_update_hands_the_beta_rule_the_papers_kl(env_id, monkeypatch):
    """One default klpen update; the KL the β rule is handed, beside KL[π_old ‖ π_θ] over the batch from scratch."""
    config = Config(env_id=env_id, objective="klpen", total_steps=2048, seed=3, dtype="float64")
    trainer = Trainer(config)
    seen = {}
    collect, rule = trainer.rollout.collect, losses.adaptive_beta

    def recording_collect():
        seen["batch"], seen["log_std_old"] = collect(), trainer.agent.log_std.copy()
        return seen["batch"]

    def recording_rule(beta, kl, kl_target):
        seen["kl"] = kl
        return rule(beta, kl, kl_target)

    monkeypatch.setattr(trainer.rollout, "collect", recording_collect)
    monkeypatch.setattr(losses, "adaptive_beta", recording_rule)
    trainer.run_update()

    batch = seen["batch"]
    obs = batch.obs.reshape(-1, batch.obs.shape[-1])
    mean_old = batch.policy_out.reshape(len(obs), -1)
    mean_new = trainer.agent.policy_output(obs)
    reference = np.mean(closed_form_gaussian_kl(mean_old, seen["log_std_old"], mean_new, trainer.agent.log_std))
    assert np.abs(trainer.agent.log_std - seen["log_std_old"]).max() > 1e-3  # σ moved: a live-σ π_old reads low
    assert seen["kl"] == pytest.approx(float(reference), rel=1e-3)


def test_a_policy_built_before_an_update_stays_the_old_policy(rng):
    """π_θ taken from the agent before some Adam steps is π_θold afterwards: its σ must not follow the agent's log σ,
    which the optimiser moves in place (the same trap as a batch without its own log σ)."""
    agent = ActorCritic(AgentSpec(3, "continuous", 2, hidden_sizes=(8,), log_std_init=-0.5), rng)
    obs = rng.standard_normal((16, 3))
    before = agent.distribution(agent.policy_output(obs))
    log_std_before = agent.log_std.copy()
    agent.log_std[...] += np.array([0.25, -0.1])  # what an update does to the live parameters
    after = agent.distribution(agent.policy_output(obs))
    expected = closed_form_gaussian_kl(before.mean, log_std_before, after.mean, agent.log_std)
    assert np.array_equal(before.log_std, log_std_before)
    assert np.allclose(after.kl(before), expected, rtol=1e-12, atol=0) and expected.min() > 0.01


def test_gaussian_kl_keeps_its_digits_when_sigma_barely_moves():
    log_std_old = np.array([0.3, -0.2])
    for delta in (1e-3, 1e-6, 1e-8):
        log_std = log_std_old + delta
        kl = DiagGaussian(np.zeros((1, 2)), log_std).kl(DiagGaussian(np.zeros((1, 2)), log_std_old))[0]
        # per dimension: d + ½(e^(−2d) − 1) = d² − (2/3)d³ + (1/3)d⁴ − …, for d = delta
        exact = 2 * (delta**2 - 2 / 3 * delta**3 + 1 / 3 * delta**4)
        assert kl == pytest.approx(exact, rel=1e-8), delta


def test_categorical_with_an_impossible_action_has_finite_entropy_and_kl():
    logits = np.array([[0.5, -np.inf, 1.0], [2.0, 0.0, -np.inf]])
    dist = Categorical(logits)
    finite = np.array([[0.5, 1.0], [2.0, 0.0]])
    probs = np.exp(finite) / np.exp(finite).sum(axis=1, keepdims=True)
    assert np.allclose(dist.entropy(), -(probs * np.log(probs)).sum(axis=1))
    assert np.allclose(dist.kl(dist), 0.0)
    (grad,) = dist.entropy_backward(np.ones(2))
    assert np.isfinite(grad).all()
    other = Categorical(np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]))
    kl = other.kl(dist)  # the old policy never takes the impossible action: each term is finite
    assert np.isfinite(kl).all() and math.isclose(kl[0], (probs[0] * np.log(probs[0] * 3)).sum())
    assert np.isinf(dist.kl(other)).all()  # the old policy takes an action the new one cannot: KL is +∞, as it is
