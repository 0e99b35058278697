"""Grading chapter 10: the assembled loss against its definition and finite differences, the epoch and minibatch
loop, the gradient clip, and finally PPO learning CartPole-v1 with your update inside minippo's rollout."""

import time

import _harness
import numpy as np
import pytest
from _harness import call_checking_inputs, check_close, check_scalar, numerical_gradient

from minippo.agent import ActorCritic
from minippo.optimizer import linear_schedule
from minippo.ppo import Config, Trainer, compute_advantages

student = _harness.student  # the fixture: the implementation under test (see _harness.py)
pytest_generate_tests = _harness.pytest_generate_tests  # one run per wrong variant under MINIPPO_IMPL=wrong
rng = _harness.rng  # a seeded NumPy Generator

pytestmark = pytest.mark.timeout(30)
RATIOS = np.array([0.5, 0.7, 0.9, 1.0, 1.1, 1.3, 1.6, 0.95, 1.05, 0.6, 1.45, 0.85, 1.15, 2.0, 0.4, 1.0])


def make_agent(kind, seed=3):
    act_dim = 3 if kind == "discrete" else 2
    return ActorCritic(4, kind, act_dim, hidden_sizes=(8, 8), log_std_init=-0.4, rng=np.random.default_rng(seed))


def make_minibatch(agent, n=16, seed=4):
    rng = np.random.default_rng(seed)
    obs = rng.normal(size=(n, 4))
    obs[:, 0] = np.arange(n)  # a row number, so a test can tell which rows the update used
    out, _, _ = agent.forward(obs)
    dist = agent.distribution(out)
    actions = rng.integers(0, 3, n) if agent.kind == "discrete" else out + 0.7 * rng.normal(size=out.shape)
    ratios = np.resize(RATIOS, n)  # where π_θold was, relative to the current π_θ
    return {
        "obs": obs,
        "actions": actions,
        "logp": dist.log_prob(actions) - np.log(ratios),
        "policy_out": out.copy(),
        "values": rng.normal(size=n),
        "advantages": rng.normal(0.5, 2.0, n),
        "returns": rng.normal(size=n),
    }


def reference_loss(agent, minibatch, config):
    """−(L^CLIP − c1 ½ Ê[(V − V^targ)²] + c2 Ê[S]) with the minibatch's advantages normalised, written out."""
    out, values, _ = agent.forward(minibatch["obs"])
    dist = agent.distribution(out)
    advantages = minibatch["advantages"]
    if config.normalize_advantages and len(advantages) > 1:
        advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
    ratio = np.exp(dist.log_prob(minibatch["actions"]) - minibatch["logp"])
    eps = config.clip_epsilon
    clip_term = np.mean(np.minimum(ratio * advantages, np.clip(ratio, 1 - eps, 1 + eps) * advantages))
    value_term = 0.5 * np.mean((values - minibatch["returns"]) ** 2)
    return float(-(clip_term - config.value_coef * value_term + config.entropy_coef * np.mean(dist.entropy())))


CONFIGS = {
    "defaults": dict(value_coef=0.5, entropy_coef=0.0, normalize_advantages=True),
    "entropy-bonus": dict(value_coef=1.0, entropy_coef=0.2, normalize_advantages=True),
    "raw-advantages": dict(value_coef=0.25, entropy_coef=0.05, normalize_advantages=False),
}


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
@pytest.mark.parametrize("settings", list(CONFIGS), ids=list(CONFIGS))
def test_loss_and_grad_matches_the_definition_and_finite_differences(student, kind, settings):
    config = Config(**CONFIGS[settings])
    agent = make_agent(kind)
    minibatch = make_minibatch(agent)
    params = agent.params.copy()
    loss = call_checking_inputs(student.loss_and_grad, "loss_and_grad", agent, minibatch, config)
    assert np.array_equal(agent.params, params), "loss_and_grad: it should not change agent.params (only agent.grads)"
    check_close(
        check_scalar(loss, "loss_and_grad", "the loss"),
        reference_loss(agent, minibatch, config),
        "loss_and_grad",
        f"the loss −(L^CLIP − c1 L^VF + c2 S) ({kind} actions, {settings})",
    )
    grads = agent.grads.copy()
    numeric = numerical_gradient(lambda: reference_loss(agent, minibatch, config), agent.params)
    check_close(
        grads,
        numeric,
        "loss_and_grad",
        f"agent.grads, ∂loss/∂θ ({kind} actions, {settings}; checked by finite differences)",
        1e-5,
        1e-7,
    )


def test_loss_and_grad_normalises_advantages_per_minibatch(student):
    config = Config(entropy_coef=0.01)
    agent = make_agent("discrete")
    minibatch = make_minibatch(agent)
    loss = check_scalar(student.loss_and_grad(agent, minibatch, config), "loss_and_grad", "the loss")
    grads = agent.grads.copy()
    shifted = dict(minibatch, advantages=3.0 * minibatch["advantages"] + 5.0)
    shifted_loss = check_scalar(student.loss_and_grad(agent, shifted, config), "loss_and_grad", "the loss")
    check_close(
        shifted_loss,
        loss,
        "loss_and_grad",
        "the loss for advantages 3Â + 5 (with normalize_advantages it should equal the loss for Â)",
    )
    check_close(agent.grads, grads, "loss_and_grad", "the gradient for advantages 3Â + 5 (it should not change)")


def test_loss_and_grad_on_a_single_sample(student):
    config = Config(entropy_coef=0.01)
    for kind in ("discrete", "continuous"):
        agent = make_agent(kind)
        minibatch = {key: value[:1] for key, value in make_minibatch(agent).items()}
        loss = check_scalar(
            student.loss_and_grad(agent, minibatch, config),
            "loss_and_grad",
            f"the loss on a minibatch of one sample ({kind}; no normalisation with n = 1)",
        )
        check_close(
            loss,
            reference_loss(agent, minibatch, config),
            "loss_and_grad",
            f"the loss on a minibatch of one sample ({kind})",
        )
        assert np.all(np.isfinite(agent.grads)), "loss_and_grad: the gradient on one sample holds NaN or infinity"


class RecordingSGD:
    """An optimizer that remembers every gradient it was given and takes a plain gradient step."""

    def __init__(self, params, lr=1e-3):
        self.params, self.lr, self.received = params, lr, []

    def step(self, grads):
        self.received.append(grads.copy())
        self.params -= self.lr * grads


def spy_on_rows(agent):
    """Record the row numbers (column 0 of obs) of every batch the agent's forward pass sees."""
    seen, forward = [], agent.forward

    def recording_forward(obs):
        seen.append(obs[:, 0].astype(int).copy())
        return forward(obs)

    agent.forward = recording_forward
    return seen


@pytest.mark.parametrize("n, size, epochs", [(16, 5, 3), (16, 16, 2), (7, 3, 1)])
def test_ppo_update_uses_every_sample_once_per_epoch(student, n, size, epochs):
    config = Config(epochs=epochs, minibatch_size=size, grad_norm_clipping=False)
    agent = make_agent("discrete")
    data = make_minibatch(agent, n)
    optimizer = RecordingSGD(agent.params)
    seen = spy_on_rows(agent)
    steps = call_checking_inputs(
        student.ppo_update, "ppo_update", agent, optimizer, data, config, np.random.default_rng(0)
    )
    per_epoch = -(-n // size)
    assert len(optimizer.received) == epochs * per_epoch, (
        f"ppo_update: {epochs} epochs of minibatches of {size} over {n} samples should take {epochs * per_epoch} "
        f"optimizer steps (the last minibatch may be smaller), not {len(optimizer.received)}"
    )
    assert steps == epochs * per_epoch, f"ppo_update: it should return the number of steps, {epochs * per_epoch}"
    assert seen and max(len(rows) for rows in seen) <= size, (
        f"ppo_update: the network should see minibatches of at most {size} rows (through agent.forward)"
    )
    counts = np.bincount(np.concatenate(seen), minlength=n)
    assert counts.min() == counts.max() and counts.min() % epochs == 0, (
        f"ppo_update: every sample should be used once per epoch, but the rows were used {counts.tolist()} times"
    )
    if size < n:
        order = np.concatenate(seen)
        assert not np.array_equal(order, np.tile(np.arange(n), len(order) // n)), (
            "ppo_update: with shuffle_minibatches the rows should be shuffled every epoch (rng.permutation)"
        )


def test_ppo_update_on_one_full_batch_takes_one_gradient_step(student):
    config = Config(epochs=1, minibatch_size=16, grad_norm_clipping=False, entropy_coef=0.01)
    agent = make_agent("continuous")
    data = make_minibatch(agent)
    expected = numerical_gradient(lambda: reference_loss(agent, data, config), agent.params)
    before = agent.params.copy()
    optimizer = RecordingSGD(agent.params, lr=0.01)
    student.ppo_update(agent, optimizer, data, config, np.random.default_rng(0))
    assert len(optimizer.received) == 1, "ppo_update: one epoch over one full minibatch should take exactly one step"
    check_close(
        optimizer.received[0],
        expected,
        "ppo_update",
        "the gradient given to optimizer.step (it should be ∂loss/∂θ, the gradient of the loss to minimise)",
        1e-5,
        1e-7,
    )
    check_close(agent.params, before - 0.01 * expected, "ppo_update", "the parameters after one step", 1e-5, 1e-9)


def test_ppo_update_clips_the_gradient_norm(student):
    agent = make_agent("discrete")
    data = make_minibatch(agent)
    for clipping in (True, False):
        config = Config(epochs=2, minibatch_size=8, grad_norm_clipping=clipping, max_grad_norm=1e-3)
        agent = make_agent("discrete")
        optimizer = RecordingSGD(agent.params, lr=1e-4)
        student.ppo_update(agent, optimizer, data, config, np.random.default_rng(1))
        norms = [float(np.linalg.norm(g)) for g in optimizer.received]
        assert norms, "ppo_update: optimizer.step was never called"
        if clipping:
            assert max(norms) <= 1e-3 * (1 + 1e-4), (
                f"ppo_update: with grad_norm_clipping the gradient's global norm should be at most max_grad_norm = "
                f"0.001, but one step got a gradient of norm {max(norms):.3g}"
            )
            assert min(norms) > 0.9e-3, (
                "ppo_update: clipping should rescale the gradient to the limit, not shrink it "
                "further (the gradients here are far larger than 0.001)"
            )
        else:
            assert min(norms) > 1e-3, "ppo_update: without grad_norm_clipping the gradient should not be clipped"


# Algorithm 1 with your update: CartPole-v1 must learn.


def as_samples(batch, advantages, returns, dtype) -> dict:
    """The rollout's (T, N) arrays as T·N rows, floats in the networks' dtype."""
    T, N = batch.values.shape
    data = {
        "obs": batch.obs.reshape(T * N, -1),
        "actions": batch.actions.reshape(T * N, *batch.actions.shape[2:]),
        "logp": batch.logp.reshape(-1),
        "policy_out": batch.policy_out.reshape(T * N, -1),
        "values": batch.values.reshape(-1),
        "advantages": advantages.reshape(-1),
        "returns": returns.reshape(-1),
    }
    return {key: v.astype(dtype) if v.dtype.kind == "f" else v for key, v in data.items()}


LEARN_STEPS = 60_000
LEARN_THRESHOLD = 150.0


@pytest.mark.timeout(150)
def test_ppo_update_learns_cartpole(student):
    config = Config(
        env_id="CartPole-v1",
        total_steps=LEARN_STEPS,
        seed=1,
        horizon=512,
        minibatch_size=128,
        epochs=4,
        entropy_coef=0.01,
        normalize_observations=False,
        scale_rewards=False,
        clip_value_loss=False,
        lr=2.5e-4,
    )
    trainer = Trainer(config)
    started, recent = time.perf_counter(), [0.0]
    try:
        for update in range(1, config.num_updates + 1):
            trainer.optimizer.lr = linear_schedule(config.lr, update, config.num_updates)
            batch = trainer.rollout.collect()
            advantages, returns = compute_advantages(batch, config)
            data = as_samples(batch, advantages, returns, trainer.agent.params.dtype)
            student.ppo_update(trainer.agent, trainer.optimizer, data, config, trainer.rng)
            assert np.all(np.isfinite(trainer.agent.params)), (
                f"ppo_update: the parameters became NaN or infinite at update {update}"
            )
            recent = trainer.rollout.completed_returns[-20:]
            if len(recent) == 20 and np.mean(recent) >= LEARN_THRESHOLD:
                break
    finally:
        for env in trainer.envs:
            env.close()
    reached = float(np.mean(recent))
    start = float(np.mean(trainer.rollout.completed_returns[:20] or [np.nan]))
    assert reached >= LEARN_THRESHOLD, (
        f"ppo_update: PPO with your update did not learn CartPole-v1: the mean return of the last 20 episodes is "
        f"{reached:.0f} after {trainer.rollout.steps} steps ({time.perf_counter() - started:.0f} s); it should reach "
        f"{LEARN_THRESHOLD:.0f} (the run's first 20 episodes averaged {start:.0f})"
    )
