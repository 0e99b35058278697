"""The reference solutions agree with minippo's own functions on random inputs (the rollout, on a real task), so the
course and the library cannot drift apart. (Three exercises have no counterpart in minippo: normalize_advantages and
importance_ratio are inline expressions there, and clipped_surrogate, the clip without the min, is a teaching step
that minippo does not use.)"""

import _harness  # noqa: F401 - puts the repository root (solutions/) on sys.path
import numpy as np
import pytest
from gymnasium.wrappers import TimeLimit
from test_ch10_ppo_update import SnapshotPolicy

from minippo import advantages as adv
from minippo import losses
from minippo.agent import ActorCritic, AgentSpec
from minippo.conv import conv2d_backward, conv2d_forward
from minippo.distributions import Categorical, DiagGaussian
from minippo.envs import make_env
from minippo.lm.dpo import dpo_loss
from minippo.lm.grpo import group_advantages, grpo_objective
from minippo.lm.reward_model import bradley_terry_loss
from minippo.lm.rlhf import kl_shaped_rewards
from minippo.network import MLP, linear_backward, tanh_backward
from minippo.normalization import ObservationNormalizer, RewardScaler
from minippo.optimizer import Adam
from minippo.ppo import Config, update_minibatch
from minippo.ppo import loss_and_grad as minippo_loss_and_grad
from minippo.rollout import Rollout
from solutions import (
    ch01_network,
    ch02_distributions,
    ch03_vanilla_pg,
    ch04_cpi,
    ch05_clipping,
    ch06_the_min,
    ch07_advantages,
    ch08_shared_network,
    ch09_kl_penalty,
    ch10_ppo_update,
    ch12_pixels,
    ch13_language_model,
    ch14_grpo_dpo,
)

pytestmark = pytest.mark.timeout(60)
SEEDS = [0, 1, 2]


def same(a, b, rtol=1e-10, atol=1e-12):
    if isinstance(a, (tuple, list)):
        assert len(a) == len(b)
        for x, y in zip(a, b):
            same(x, y, rtol, atol)
        return
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    assert a.shape == b.shape, (a.shape, b.shape)
    np.testing.assert_allclose(a, b, rtol=rtol, atol=atol)


@pytest.mark.parametrize("seed", SEEDS)
def test_network_and_adam(seed):
    rng = np.random.default_rng(seed)
    x, W, grad_y = rng.normal(size=(5, 3)), rng.normal(size=(3, 4)), rng.normal(size=(5, 4))
    same(ch01_network.linear_backward(x, W, grad_y), linear_backward(x, W, grad_y))
    h, grad_h = np.tanh(rng.normal(size=(4, 6))), rng.normal(size=(4, 6))
    same(ch01_network.tanh_backward(h, grad_h), tanh_backward(h, grad_h))

    mlp = MLP((3, 7, 5, 2), rng=rng)
    layers = list(zip(mlp.W, mlp.b))
    out, cache = mlp.forward(x)
    my_out, my_cache = ch01_network.mlp_forward(layers, x)
    same(my_out, out)
    grad_out = rng.normal(size=out.shape)
    grad_x = mlp.backward(cache, grad_out, need_grad_input=True)
    my_grads, my_grad_x = ch01_network.mlp_backward(layers, my_cache, grad_out)
    same(my_grad_x, grad_x)
    same([g for pair in my_grads for g in pair], [g for pair in zip(mlp.grad_W, mlp.grad_b) for g in pair])

    params = rng.normal(size=10)
    adam = Adam(params.copy(), lr=0.01, eps=1e-6)
    mine, m, v = params.copy(), np.zeros(10), np.zeros(10)
    for t in range(1, 8):
        grads = rng.normal(size=10)
        adam.step(grads)
        mine, m, v = ch01_network.adam_step(mine, grads, m, v, t, lr=0.01, eps=1e-6)
        same(mine, adam.params, rtol=1e-9)


@pytest.mark.parametrize("seed", SEEDS)
def test_distributions(seed):
    rng = np.random.default_rng(seed)
    logits, actions, upstream = rng.normal(0, 3, (6, 4)), rng.integers(0, 4, 6), rng.normal(size=6)
    dist = Categorical(logits)
    same(ch02_distributions.categorical_log_prob(logits, actions), dist.log_prob(actions))
    same(ch02_distributions.categorical_log_prob_backward(logits, actions, upstream), dist.log_prob_backward(actions,
         upstream)[0])  # fmt: skip
    same(ch02_distributions.categorical_entropy(logits), dist.entropy())
    same(ch02_distributions.categorical_entropy_backward(logits, upstream), dist.entropy_backward(upstream)[0])

    mean, log_std = rng.normal(size=(6, 3)), rng.normal(0, 0.5, 3)
    actions = mean + rng.normal(size=(6, 3))
    gauss = DiagGaussian(mean, log_std)
    same(ch02_distributions.gaussian_log_prob(mean, log_std, actions), gauss.log_prob(actions))
    same(
        ch02_distributions.gaussian_log_prob_backward(mean, log_std, actions, upstream),
        gauss.log_prob_backward(actions, upstream),
    )
    same(ch02_distributions.gaussian_entropy(mean, log_std), gauss.entropy())
    same(ch02_distributions.gaussian_entropy_backward(mean, log_std, upstream), gauss.entropy_backward(upstream))


@pytest.mark.parametrize("seed", SEEDS)
def test_surrogates(seed):
    rng = np.random.default_rng(seed)
    logp_old = rng.normal(-1.5, 0.5, 20)
    logp, advantages = logp_old + rng.normal(0, 0.3, 20), rng.normal(size=20)
    same(ch03_vanilla_pg.pg_objective(logp, advantages), losses.pg_objective(logp, advantages))
    same(ch04_cpi.cpi_objective(logp, logp_old, advantages), losses.cpi_objective(logp, logp_old, advantages))
    for epsilon in (0.1, 0.2):
        same(ch05_clipping.clip_fraction(logp, logp_old, epsilon), losses.clip_fraction(logp, logp_old, epsilon))
        same(
            ch06_the_min.clip_objective(logp, logp_old, advantages, epsilon),
            losses.clip_objective(logp, logp_old, advantages, epsilon),
        )


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("shape", [(30,), (30, 3)])
def test_advantages(seed, shape):
    rng = np.random.default_rng(seed)
    rewards, values, next_values = rng.normal(size=shape), rng.normal(size=shape), rng.normal(size=shape)
    terminated, truncated = rng.random(shape) < 0.1, rng.random(shape) < 0.1
    truncated &= ~terminated
    same(
        ch07_advantages.discounted_returns(rewards, next_values, terminated, truncated, 0.97),
        adv.discounted_returns(rewards, next_values, terminated, truncated, 0.97),
    )
    same(
        ch07_advantages.td_residuals(rewards, values, next_values, terminated, 0.97),
        adv.td_residuals(rewards, values, next_values, terminated, 0.97),
    )
    same(
        ch07_advantages.gae(rewards, values, next_values, terminated, truncated, 0.97, 0.9),
        adv.gae(rewards, values, next_values, terminated, truncated, 0.97, 0.9),
    )


@pytest.mark.parametrize("seed", SEEDS)
def test_value_losses_and_the_combined_objective(seed):
    rng = np.random.default_rng(seed)
    values, targets, values_old = rng.normal(size=15), rng.normal(size=15), rng.normal(size=15)
    same(ch08_shared_network.value_loss(values, targets), losses.value_loss(values, targets))
    same(
        ch08_shared_network.clipped_value_loss(values, targets, values_old, 0.2),
        losses.value_loss(values, targets, values_old, 0.2),
    )
    logp_old = rng.normal(-1.0, 0.5, 15)
    logp, advantages, entropy = logp_old + rng.normal(0, 0.3, 15), rng.normal(size=15), rng.random(15)
    value, grad_logp, grad_values, grad_entropy = ch08_shared_network.clip_vf_s_objective(
        logp, logp_old, advantages, values, targets, entropy, 0.2, 0.5, 0.01
    )
    clip_value, clip_grad = losses.clip_objective(logp, logp_old, advantages, 0.2)
    vf_value, vf_grad = losses.value_loss(values, targets)
    bonus, bonus_grad = losses.entropy_bonus(entropy)
    same(value, clip_value - 0.5 * vf_value + 0.01 * bonus)
    same((grad_logp, grad_values, grad_entropy), (clip_grad, -0.5 * vf_grad, 0.01 * bonus_grad))


@pytest.mark.parametrize("seed", SEEDS)
def test_kl_penalty(seed):
    rng = np.random.default_rng(seed)
    logits_old, logits, upstream = rng.normal(size=(6, 4)), rng.normal(size=(6, 4)), rng.normal(size=6)
    old, new = Categorical(logits_old), Categorical(logits)
    same(ch09_kl_penalty.categorical_kl(logits_old, logits), new.kl(old))
    same(ch09_kl_penalty.categorical_kl_backward(logits_old, logits, upstream), new.kl_backward(old, upstream)[0])
    logp_old = rng.normal(-1.0, 0.5, 6)
    logp, advantages, kl = logp_old + rng.normal(0, 0.2, 6), rng.normal(size=6), rng.random(6) * 0.05
    same(
        ch09_kl_penalty.kl_penalty_objective(logp, logp_old, advantages, kl, 2.0),
        losses.kl_penalty_objective(logp, logp_old, advantages, kl, 2.0),
    )
    for d in rng.uniform(0, 0.05, 50):
        assert ch09_kl_penalty.adaptive_beta(0.7, d, 0.01) == losses.adaptive_beta(0.7, d, 0.01)


def minibatch_for(agent, rng, n):
    obs = rng.normal(size=(n, 4))
    out, values, _ = agent.forward(obs)
    dist = agent.distribution(out)
    actions = dist.sample(rng)
    return {
        "obs": obs,
        "actions": actions,
        "logp": dist.log_prob(actions) + rng.normal(0, 0.3, n),
        "policy_out": out,
        "values": values,
        "advantages": rng.normal(size=n),
        "returns": rng.normal(size=n),
    }


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
@pytest.mark.parametrize("seed", SEEDS)
def test_ppo_loss_and_update(seed, kind):
    rng = np.random.default_rng(seed)
    config = Config(clip_value_loss=False, entropy_coef=0.01, epochs=3, minibatch_size=7, objective="clip")
    agent = ActorCritic(AgentSpec(4, kind, 2, hidden_sizes=(8, 8)), np.random.default_rng(seed))
    minibatch = minibatch_for(agent, rng, 12)
    loss = ch10_ppo_update.loss_and_grad(agent, minibatch, config)
    grads = agent.grads.copy()
    expected_loss, _ = minippo_loss_and_grad(agent, minibatch, config)
    same(loss, expected_loss)
    same(grads, agent.grads)

    # the epochs of Trainer.run_update, written with minippo's update_minibatch, from the same parameters and rng
    twin = agent.copy()
    adam, twin_adam = Adam(agent.params, lr=1e-3), Adam(twin.params, lr=1e-3)
    steps = ch10_ppo_update.ppo_update(agent, adam, minibatch, config, np.random.default_rng(5))
    twin_rng = np.random.default_rng(5)
    for _ in range(config.epochs):
        order = twin_rng.permutation(12)
        for start in range(0, 12, config.minibatch_size):
            index = order[start : start + config.minibatch_size]
            update_minibatch(twin, twin_adam, {key: value[index] for key, value in minibatch.items()}, config)
    assert steps == config.epochs * 2
    same(agent.params, twin.params, rtol=1e-9)


@pytest.mark.parametrize("seed", SEEDS)
def test_rollout_with_clipped_continuous_actions(seed):
    # collect beside minippo's Rollout.collect on Pendulum-v1 (actions clipped to ±2, a time limit of 30 steps so that
    # episodes are truncated inside the batches), two batches, the observation statistics on; chapter 10's grading
    # test does the same on CartPole-v1, whose actions are discrete
    T, N = 40, 2
    agent = ActorCritic(AgentSpec(3, "continuous", 1, (8, 8), log_std_init=0.5), np.random.default_rng(seed))

    def environments():
        return [TimeLimit(make_env("Pendulum-v1"), max_episode_steps=30) for _ in range(N)]

    theirs, mine = environments(), environments()
    scaler = RewardScaler(0.99, enabled=False, num_envs=N)
    rollout = Rollout(theirs, agent, ObservationNormalizer((3,)), scaler, T, np.random.default_rng(seed), seed)
    normalizer, rng = ObservationNormalizer((3,)), np.random.default_rng(seed)
    raw = np.stack([env.reset(seed=seed + i)[0] for i, env in enumerate(mine)]).astype(np.float64)
    bounds = (mine[0].action_space.low, mine[0].action_space.high)
    for _ in range(2):
        batch = rollout.collect()
        policy = SnapshotPolicy(agent, rng, T, N)
        result = ch10_ppo_update.collect(policy, mine, normalizer, raw, T, bounds)
        assert batch.truncated.any() and np.any(np.abs(batch.actions) > 2.0)
        for name in ("obs", "actions", "logp", "values", "rewards", "terminated", "truncated"):
            same(result[name], getattr(batch, name))
        same(result["next_values"], np.where(batch.terminated, 0.0, batch.next_values))
        same(result["raw_obs"], rollout.raw_obs)
        same([normalizer.stats.mean, normalizer.stats.var], [rollout.obs_normalizer.stats.mean,
             rollout.obs_normalizer.stats.var])  # fmt: skip
        raw = result["raw_obs"]


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("x_shape, K_shape", [((2, 10, 10, 4), (3, 3, 4, 16)), ((3, 5, 7, 2), (2, 3, 2, 5))])
def test_pixels(seed, x_shape, K_shape):
    rng = np.random.default_rng(seed)
    x, K, b = rng.normal(size=x_shape), rng.normal(size=K_shape), rng.normal(size=K_shape[-1])
    y = conv2d_forward(x, K, b)
    same(ch12_pixels.conv2d_forward(x, K, b), y)
    grad_y = rng.normal(size=y.shape)
    same(ch12_pixels.conv2d_backward(x, K, grad_y), conv2d_backward(x, K, grad_y))
    same(ch12_pixels.conv2d_backward(x, K, grad_y, need_grad_x=False)[1:], conv2d_backward(x, K, grad_y, False)[1:])
    assert ch12_pixels.conv2d_backward(x, K, grad_y, need_grad_x=False)[0] is None


@pytest.mark.parametrize("seed", SEEDS)
def test_language_model(seed):
    rng = np.random.default_rng(seed)
    preferred, rejected = rng.normal(0, 3, 9), rng.normal(0, 3, 9)
    same(ch13_language_model.bradley_terry_loss(preferred, rejected), bradley_terry_loss(preferred, rejected))
    logp, logp_ref = rng.normal(-1.5, 0.5, (4, 6)), rng.normal(-1.5, 0.5, (4, 6))
    scores, lengths = rng.normal(size=4), rng.integers(1, 7, 4)
    same(
        ch13_language_model.kl_shaped_rewards(logp, logp_ref, scores, lengths, 0.4),
        kl_shaped_rewards(logp, logp_ref, scores, lengths, 0.4),
    )


@pytest.mark.parametrize("seed", SEEDS)
def test_grpo_and_dpo(seed):
    rng = np.random.default_rng(seed)
    scores = rng.normal(size=(5, 6))
    scores[0] = 1.5  # a group that all scored the same
    same(ch14_grpo_dpo.group_advantages(scores), group_advantages(scores))
    logp_old = rng.normal(-1.5, 0.5, 20)
    tokens = logp_old + rng.normal(0, 0.3, 20), logp_old, rng.normal(-1.5, 0.5, 20), rng.normal(size=20)
    weights = rng.uniform(0.01, 0.2, 20)
    same(ch14_grpo_dpo.grpo_objective(*tokens, weights, 0.2, 0.3), grpo_objective(*tokens, weights, 0.2, 0.3))
    logps = [rng.normal(-6.0, 2.0, 8) for _ in range(4)]
    same(ch14_grpo_dpo.dpo_loss(*logps, 0.4), dpo_loss(*logps, 0.4))
