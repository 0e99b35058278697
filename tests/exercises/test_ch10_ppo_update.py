"""Grading chapter 10: the assembled loss against its definition and finite differences at several configurations
(ε, c1, c2, advantage normalisation on and off), the epoch and minibatch loop (the number of steps, the exact order of
the rows with and without shuffling from the rng passed in, the gradient clip, each minibatch's own gradient), the
rollout (collect) on scripted environments whose episodes end at known steps (one step, several, clipped continuous
actions, terminations, truncations, both at once, two batches in a row) and then against minippo's own rollout on
CartPole-v1, and finally PPO learning CartPole-v1 with your update inside minippo's rollout, a backstop rather than
the evidence.

Tests run from the most specific to the most general, so the first failure names the mistake."""

import copy
import dataclasses
import time

import _harness
import numpy as np
import pytest
from _harness import call_checking_inputs, check_array, check_close, check_scalar, numerical_gradient, where_is_ratio
from gymnasium.wrappers import TimeLimit

from minippo import losses
from minippo.agent import ActorCritic, AgentSpec
from minippo.distributions import sample_categorical
from minippo.envs import make_env
from minippo.normalization import ObservationNormalizer, RewardScaler
from minippo.optimizer import linear_schedule
from minippo.ppo import Config, Trainer, compute_advantages, flatten
from minippo.presets import CARTPOLE_PPO
from minippo.rollout import Rollout

student = _harness.student  # the fixture: the implementation under test (see _harness.py)
pytest_generate_tests = _harness.pytest_generate_tests  # one run per wrong variant under MINIPPO_IMPL=wrong
rng = _harness.rng  # a seeded NumPy Generator

pytestmark = pytest.mark.timeout(30)
# clear of the band's edges for ε = 0.1, 0.2, 0.3, with one ratio in each window between 1 ± ε and e^±ε
RATIOS = np.array([0.5, 0.75, 0.95, 1.0, 1.05, 1.25, 1.6, 0.85, 1.15, 1.21, 0.81, 1.103, 0.902, 1.32, 0.72, 2.0])


def make_agent(kind, seed=3):
    act_dim = 3 if kind == "discrete" else 2
    return ActorCritic(AgentSpec(4, kind, act_dim, hidden_sizes=(8, 8), log_std_init=-0.4), np.random.default_rng(seed))


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


def loss_terms(agent, minibatch, config, normalize=None, epsilon=None, ddof=0, in_root=False):
    """(L^CLIP, L^VF with its ½, Ê[S]) written out; the advantages normalised over the minibatch when the config says
    so (``normalize`` overrides that: True also normalises a single sample; ``in_root`` divides by √(var + 1e-8))."""
    out, values, _ = agent.forward(minibatch["obs"])
    dist = agent.distribution(out)
    advantages = minibatch["advantages"]
    if normalize or (normalize is None and config.normalize_advantages and len(advantages) > 1):
        scale = np.sqrt(advantages.var(ddof=ddof) + 1e-8) if in_root else advantages.std(ddof=ddof) + 1e-8
        advantages = (advantages - advantages.mean()) / scale
    ratio = np.exp(dist.log_prob(minibatch["actions"]) - minibatch["logp"])
    eps = config.clip_epsilon if epsilon is None else epsilon
    clip_term = np.mean(np.minimum(ratio * advantages, np.clip(ratio, 1 - eps, 1 + eps) * advantages))
    value_term = 0.5 * np.mean((values - minibatch["returns"]) ** 2)
    return float(clip_term), float(value_term), float(np.mean(dist.entropy()))


def values_of(agent, minibatch):
    return agent.forward(minibatch["obs"])[1]


def reference_loss(agent, minibatch, config):
    """−(L^CLIP − c1 ½ Ê[(V − V^targ)²] + c2 Ê[S]) with the minibatch's advantages normalised, written out."""
    clip_term, value_term, entropy = loss_terms(agent, minibatch, config)
    return -(clip_term - config.value_coef * value_term + config.entropy_coef * entropy)


def check_loss(loss, agent, minibatch, config, what):
    """The loss is the reference, or the test fails naming the plausible mistake whose loss it equals."""
    loss = check_scalar(loss, "loss_and_grad", what)
    expected = reference_loss(agent, minibatch, config)
    if abs(loss - expected) <= 1e-6 * (1 + abs(expected)):
        return
    clip_term, value_term, entropy = loss_terms(agent, minibatch, config)
    c1, c2 = config.value_coef, config.entropy_coef
    candidates = {
        "the objective L^{CLIP+VF+S} itself; the loss to minimise is its negative": clip_term
        - c1 * value_term
        + c2 * entropy,
        "the value loss enters with the wrong sign (the loss is −L^CLIP + c1 L^VF − c2 S)": -clip_term
        - c1 * value_term
        - c2 * entropy,
        "the entropy bonus c2 S is missing": -clip_term + c1 * value_term,
        "the entropy bonus enters with the wrong sign": -clip_term + c1 * value_term + c2 * entropy,
        "c1 (config.value_coef) is missing from the value term": -clip_term + value_term - c2 * entropy,
        "the value loss lacks its ½": -clip_term + 2 * c1 * value_term - c2 * entropy,
        "the advantages are not normalised although config.normalize_advantages is True": None,
        "the advantages are normalised although config.normalize_advantages is False": None,
        "a minibatch of one sample is normalised (its advantage becomes 0); leave it as it is": None,
        "the advantages are normalised with the sample standard deviation (ddof = 1); the contract says np.std": None,
        "the advantages are divided by √(var Â + 1e-8), the 1e-8 inside the square root; the contract divides by "
        "std Â + 1e-8": None,
        "L^VF is computed from minibatch['values'] (the rollout's old values) instead of the network's V_θ(s_t) from "
        "agent.forward": None,
        "the value loss is clipped around minibatch['values'] (config.clip_value_loss); loss_and_grad has no value "
        "clipping": None,
    }
    n = len(minibatch["advantages"])
    names = list(candidates)
    if config.normalize_advantages and n > 1:
        candidates[names[6]] = (
            -loss_terms(agent, minibatch, config, normalize=False)[0] + c1 * value_term - c2 * entropy
        )
    if not config.normalize_advantages and n > 1:
        candidates[names[7]] = -loss_terms(agent, minibatch, config, normalize=True)[0] + c1 * value_term - c2 * entropy
    if config.normalize_advantages and n == 1:
        candidates[names[8]] = -loss_terms(agent, minibatch, config, normalize=True)[0] + c1 * value_term - c2 * entropy
    if config.normalize_advantages and n > 1:
        candidates[names[9]] = -loss_terms(agent, minibatch, config, ddof=1)[0] + c1 * value_term - c2 * entropy
        candidates[names[10]] = -loss_terms(agent, minibatch, config, in_root=True)[0] + c1 * value_term - c2 * entropy
    if "values" in minibatch:  # the rollout's values, which the value loss must not use
        old_values, returns = minibatch["values"], minibatch["returns"]
        candidates[names[11]] = -clip_term + c1 * 0.5 * float(np.mean((old_values - returns) ** 2)) - c2 * entropy
        clipped = losses.value_loss(values_of(agent, minibatch), returns, old_values, config.clip_epsilon)[0]
        candidates[names[12]] = -clip_term + c1 * clipped - c2 * entropy
    # a config field ignored: the loss is the one for the field's default value
    for field in ("clip_epsilon", "value_coef", "entropy_coef", "normalize_advantages"):
        default = getattr(Config(), field)
        if getattr(config, field) != default:
            words = f"config.{field} = {getattr(config, field)} is ignored: this is the loss for {field} = {default}"
            candidates[words] = reference_loss(agent, minibatch, dataclasses.replace(config, **{field: default}))
    why = next(
        (
            name
            for name, value in candidates.items()
            if value is not None and abs(loss - value) <= 1e-6 * (1 + abs(value))
        ),
        None,
    )
    raise AssertionError(
        f"loss_and_grad: {what} should be {expected:.6g}, not {loss:.6g}"
        + (f": {why}" if why else "")
        + f" (L^CLIP = {clip_term:.4g}, L^VF = {value_term:.4g}, S = {entropy:.4g}, c1 = {c1}, c2 = {c2})"
    )


def describe_parameter(agent, got, expected):
    """check_close's ``where`` for a gradient over agent.params: which weight the failing entry is, and which parts of
    the gradient (the policy network, the value network, log σ) are right."""
    blocks, parts, offset = [], {}, 0
    for name, net in agent.nets.items():
        start = offset
        for layer, (W, b) in enumerate(zip(net.W, net.b)):
            for what, size in (("W", W.size), ("b", b.size)):
                blocks.append((f"{what} of layer {layer + 1} of the {name} network", offset, offset + size))
                offset += size
        parts[f"the {name} network"] = slice(start, offset)
    if agent.kind == "continuous":
        blocks.append(("log σ", offset, len(got)))
        parts["log σ"] = slice(offset, len(got))
    summary = []
    for part, where in parts.items():
        mine, want = np.asarray(got[where], dtype=np.float64), expected[where]
        if np.allclose(mine, want, rtol=1e-5, atol=1e-7):
            summary.append(f"{part}: right")
        elif not np.any(mine):
            summary.append(f"{part}: all 0")
        else:
            big = np.abs(want) > 1e-6
            factor = float(np.median(mine[big] / want[big])) if big.any() else 0.0
            same_factor = big.any() and np.allclose(mine, factor * want, rtol=1e-4, atol=1e-7)
            summary.append(f"{part}: {factor:.3g} × the expected" if same_factor else f"{part}: wrong")

    def describe(index):
        i = int(index[0])
        block = next(name for name, start, stop in blocks if start <= i < stop)
        return f"{block}; by part, {', '.join(summary)}"

    return describe


CONFIGS = {
    "defaults": dict(value_coef=0.5, entropy_coef=0.0, normalize_advantages=True),
    "entropy-bonus": dict(value_coef=1.0, entropy_coef=0.2, normalize_advantages=True),
    "raw-advantages": dict(value_coef=0.25, entropy_coef=0.05, normalize_advantages=False),
    "epsilon-0.1": dict(clip_epsilon=0.1, value_coef=0.5, entropy_coef=0.01),
    "epsilon-0.3": dict(clip_epsilon=0.3, value_coef=2.0, entropy_coef=0.0, normalize_advantages=False),
}


def test_loss_and_grad_on_a_single_sample(student):
    config = Config(entropy_coef=0.01)
    for kind in ("discrete", "continuous"):
        agent = make_agent(kind)
        minibatch = {key: value[:1] for key, value in make_minibatch(agent).items()}
        loss = student.loss_and_grad(agent, minibatch, config)
        check_loss(loss, agent, minibatch, config, f"the loss on a minibatch of one sample ({kind})")
        assert np.all(np.isfinite(agent.grads)), "loss_and_grad: the gradient on one sample holds NaN or infinity"


def test_loss_and_grad_uses_config_clip_epsilon(student):
    # one sample whose ratio lies in each window; only config.clip_epsilon decides whether the clip acts
    for epsilon in (0.1, 0.3, 0.2):
        config = Config(clip_epsilon=epsilon, value_coef=0.5, entropy_coef=0.0, normalize_advantages=False)
        agent = make_agent("discrete")
        full = make_minibatch(agent)
        for row in (9, 10, 11, 12, 13, 14, 5, 8):  # r = 1.21, 0.81, 1.103, 0.902, 1.32, 0.72, 1.25, 1.15
            minibatch = {key: value[row : row + 1] for key, value in full.items()}
            minibatch["advantages"] = np.array([1.0 if RATIOS[row] > 1 else -1.0])
            loss = student.loss_and_grad(agent, minibatch, config)
            sample = f"one sample with r = {RATIOS[row]}, Â = {minibatch['advantages'][0]:g}"
            check_loss(
                loss,
                agent,
                minibatch,
                config,
                f"with config.clip_epsilon = {epsilon}, the loss for {sample} "
                f"(r is {where_is_ratio(RATIOS[row], epsilon)})",
            )


def test_loss_and_grad_with_equal_advantages(student):
    # std Â = 0: the 1e-8 in (Â − mean Â) / (std Â + 1e-8) keeps the normalised advantages at 0, not NaN
    config = Config(entropy_coef=0.01)
    agent = make_agent("discrete")
    minibatch = dict(make_minibatch(agent, 6), advantages=np.full(6, 2.5))
    loss = student.loss_and_grad(agent, minibatch, config)
    what = "the loss for a minibatch whose advantages are all equal (std Â = 0: divide by std Â + 1e-8)"
    check_loss(loss, agent, minibatch, config, what)
    assert np.all(np.isfinite(agent.grads)), (
        "loss_and_grad: the gradient for equal advantages holds NaN or infinity (divide by std Â + 1e-8)"
    )


def test_loss_and_grad_with_advantages_of_tiny_spread(student):
    # std Â = 1e-4: dividing by std Â + 1e-8 still gives advantages of about ±1; √(var Â + 1e-8) would not
    config = Config(entropy_coef=0.01)
    agent = make_agent("discrete")
    minibatch = make_minibatch(agent)
    advantages = minibatch["advantages"]
    minibatch["advantages"] = 2.0 + 1e-4 * (advantages - advantages.mean()) / advantages.std()
    loss = check_scalar(student.loss_and_grad(agent, minibatch, config), "loss_and_grad", "the loss")
    expected = reference_loss(agent, minibatch, config)
    if abs(loss - expected) > 1e-3 * (1 + abs(expected)):  # a guard against std = 0 in place of the 1e-8 passes
        what = "the loss for advantages with a tiny spread (std Â = 1e-4; normalised, they are still about ±1)"
        check_loss(loss, agent, minibatch, config, what)


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


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
@pytest.mark.parametrize("settings", list(CONFIGS), ids=list(CONFIGS))
def test_loss_and_grad_matches_the_definition_and_finite_differences(student, kind, settings):
    config = Config(**CONFIGS[settings])
    agent = make_agent(kind)
    minibatch = make_minibatch(agent)
    params = agent.params.copy()
    loss = call_checking_inputs(student.loss_and_grad, "loss_and_grad", agent, minibatch, config)
    assert np.array_equal(agent.params, params), "loss_and_grad: it should not change agent.params (only agent.grads)"
    check_loss(loss, agent, minibatch, config, f"the loss −(L^CLIP − c1 L^VF + c2 S) ({kind} actions, {settings})")
    grads = agent.grads.copy()
    numeric = numerical_gradient(lambda: reference_loss(agent, minibatch, config), agent.params)
    check_close(
        grads,
        numeric,
        "loss_and_grad",
        f"agent.grads, ∂loss/∂θ ({kind} actions, {settings}; checked by finite differences)",
        1e-5,
        1e-7,
        where=describe_parameter(agent, grads, numeric),
    )


class RecordingSGD:
    """An optimizer that remembers every gradient it was given and takes a plain gradient step."""

    # what a student's code, in the grader's worker process, may reach of it (minippo.grading.sandbox.offers)
    offered_to_graded_code = ("step", "lr", "params", "received")

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
    assert steps == epochs * per_epoch, (
        f"ppo_update: it should return the number of optimizer steps, {epochs * per_epoch} = {epochs} epochs × "
        f"ceil({n}/{size}), not {steps!r}"
    )
    assert seen and max(len(rows) for rows in seen) <= size, (
        f"ppo_update: the network should see minibatches of at most {size} rows (through agent.forward)"
    )
    counts = np.bincount(np.concatenate(seen), minlength=n)
    assert counts.min() == counts.max() and counts.min() % epochs == 0, (
        f"ppo_update: every sample should be used once per epoch, but the rows were used {counts.tolist()} times"
    )


def rows_per_call(seen):
    """The rows of each agent.forward call, a call repeated on the same rows counted once."""
    merged = []
    for rows in seen:
        if not (merged and np.array_equal(merged[-1], rows)):
            merged.append(rows)
    return merged


@pytest.mark.parametrize("shuffle", [False, True], ids=["in-order", "shuffled"])
def test_ppo_update_takes_the_rows_in_the_contract_s_order(student, shuffle):
    n, size, epochs = 10, 4, 3
    config = Config(epochs=epochs, minibatch_size=size, shuffle_minibatches=shuffle, grad_norm_clipping=False)
    agent = make_agent("discrete")
    data = make_minibatch(agent, n)
    seen = spy_on_rows(agent)
    rng = np.random.default_rng(5)
    replay = np.random.default_rng(5)  # the same stream, to replay what the contract draws from it
    expected = [replay.permutation(n) if shuffle else np.arange(n) for _ in range(epochs)]
    student.ppo_update(agent, RecordingSGD(agent.params, lr=0.0), data, config, rng)
    calls = rows_per_call(seen)
    got = np.concatenate(calls) if calls else np.zeros(0, int)
    want = np.concatenate(expected)
    if np.array_equal(got, want):
        sizes = [len(rows) for rows in calls]
        assert sizes == [4, 4, 2] * epochs, (
            f"ppo_update: the minibatches should be consecutive slices of {size} rows of each epoch's order, "
            f"[4, 4, 2] per epoch, not {sizes}"
        )
        return
    assert len(got) == len(want), (
        f"ppo_update: {epochs} epochs over {n} rows should pass {len(want)} rows through agent.forward, not {len(got)}"
    )
    orders = got.reshape(epochs, n)
    shown = "; ".join(f"epoch {k + 1}: {order.tolist()}" for k, order in enumerate(orders))
    if not shuffle:
        why = "with shuffle_minibatches = False every epoch should take the rows in order 0 … n−1"
    elif all(np.array_equal(order, np.arange(n)) for order in orders):
        why = "with shuffle_minibatches = True each epoch's order should be rng.permutation(n), not 0 … n−1"
    elif all(np.array_equal(order, orders[0]) for order in orders):
        why = "every epoch used the same order: draw a new rng.permutation(n) at the start of each epoch"
    else:
        why = (
            "the rows are shuffled, but not as rng.permutation(n) of the rng passed in, once per epoch (not np.random, "
            "not a new Generator, no other draws from rng)"
        )
    raise AssertionError(f"ppo_update: {why}; the rows seen were {shown}; expected {[e.tolist() for e in expected]}")


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
            assert min(norms) > 1e-3 * (1 + 1e-4), (
                f"ppo_update: with grad_norm_clipping = False the gradient should not be clipped, but a step got a "
                f"gradient of norm {min(norms):.3g}, the max_grad_norm = 0.001 of the config (the gradients here are "
                "far larger): is config.grad_norm_clipping ignored?"
            )


def test_ppo_update_gives_each_minibatch_its_own_gradient(student):
    # lr = 0 keeps θ fixed, so each step's gradient must be that of its own minibatch, advantages normalised over it
    config = Config(epochs=1, minibatch_size=5, shuffle_minibatches=False, grad_norm_clipping=False, entropy_coef=0.01)
    agent = make_agent("continuous")
    data = make_minibatch(agent, 12)
    data["advantages"] = data["advantages"] + np.repeat([4.0, -1.0, 0.0], [5, 5, 2])  # minibatches with other means
    optimizer = RecordingSGD(agent.params, lr=0.0)
    student.ppo_update(agent, optimizer, data, config, np.random.default_rng(0))
    assert len(optimizer.received) == 3, (
        f"ppo_update: one epoch over 12 rows in minibatches of 5 should take 3 steps, not {len(optimizer.received)}"
    )
    for k, start in enumerate(range(0, 12, 5)):
        minibatch = {key: value[start : start + 5] for key, value in data.items()}
        expected = numerical_gradient(lambda mb=minibatch: reference_loss(agent, mb, config), agent.params)
        check_close(
            optimizer.received[k],
            expected,
            "ppo_update",
            f"the gradient given to optimizer.step for minibatch {k + 1} (rows {start} … {min(start + 5, 12) - 1}; "
            "∂loss/∂θ of that minibatch alone, its advantages normalised over the minibatch, not the whole batch)",
            1e-5,
            1e-7,
            where=describe_parameter(agent, optimizer.received[k], expected),
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
        where=describe_parameter(agent, optimizer.received[0], expected),
    )
    check_close(agent.params, before - 0.01 * expected, "ppo_update", "the parameters after one step", 1e-5, 1e-9)


# The rollout: collect on scripted environments whose episodes end at known steps, then against minippo's own.


class SnapshotPolicy:
    """π_θold and V of an ActorCritic, for one batch of T steps in N environments. Its random numbers are drawn when it
    is made, as minippo's Rollout.collect draws them (uniforms (T, N) for a categorical policy, standard normals
    (T, N, act_dim) for a Gaussian), and its t-th sample call uses step t's."""

    offered_to_graded_code = ("sample", "log_prob", "value")

    def __init__(self, agent, rng, horizon, num_envs, log=None):
        self.agent, self.horizon, self.num_envs = agent, horizon, num_envs
        self.log = [] if log is None else log
        self.calls = 0
        if agent.kind == "continuous":
            noise = rng.standard_normal((horizon, num_envs, agent.act_dim))
            self.draws = (np.exp(agent.log_std) * noise).astype(agent.dtype)
        else:
            self.draws = rng.random((horizon, num_envs))

    def actions_for(self, t, obs):
        """What the t-th sample call returns for the (N, obs_dim) observations ``obs``."""
        out = self.agent.policy_output(np.asarray(obs, dtype=np.float64))
        if self.agent.kind == "continuous":
            return out + self.draws[t]
        return sample_categorical(out, self.draws[t])

    def sample(self, obs):
        obs = np.array(obs, dtype=np.float64)
        shape = (self.num_envs, self.agent.obs_dim)
        if obs.shape != shape:
            raise ValueError(
                f"policy.sample takes the normalised observations of one step of all N = {self.num_envs} "
                f"environments at once, an array of shape {shape}, not {obs.shape}"
            )
        if self.calls == self.horizon:
            raise ValueError(f"policy.sample was called more than T = {self.horizon} times: call it once per step")
        self.log.append(("sample", self.calls, obs))
        self.calls += 1
        return self.actions_for(self.calls - 1, obs)

    def _observations(self, obs, what):
        obs = np.asarray(obs, dtype=np.float64)
        if obs.ndim == 0 or obs.shape[-1] != self.agent.obs_dim:
            raise ValueError(f"policy.{what} takes observations of shape (..., {self.agent.obs_dim}), not {obs.shape}")
        return obs

    def log_prob(self, obs, actions):
        obs = self._observations(obs, "log_prob")
        actions = np.asarray(actions)
        continuous = self.agent.kind == "continuous"
        shape = obs.shape[:-1] + ((self.agent.act_dim,) if continuous else ())
        if actions.shape != shape:
            raise ValueError(
                f"policy.log_prob: observations of shape {obs.shape} go with actions of shape {shape}, not "
                f"{actions.shape}"
            )
        flat = obs.reshape(-1, self.agent.obs_dim)
        dist = self.agent.distribution(self.agent.policy_output(flat))
        chosen = actions.reshape(len(flat), -1) if continuous else actions.reshape(-1)
        return dist.log_prob(chosen).reshape(obs.shape[:-1])

    def value(self, obs):
        obs = self._observations(obs, "value")
        return self.agent.value(obs.reshape(-1, self.agent.obs_dim)).reshape(obs.shape[:-1])


class ScriptedEnv:
    """An environment whose episodes end at known steps: ``ends`` maps the number of steps it has taken before (over
    its whole life, 0, 1, …) to how that step ends its episode: "terminated", "truncated" or "both". Its observations
    do not depend on the actions; each is made of its index, its episode and the step within the episode, so that no
    two are alike (the final observation of an episode differs from the next one's first). Every step's reward differs
    too."""

    def __init__(self, index, ends):
        self.index, self.ends = index, dict(ends)
        self.steps = self.episode = self.step_in_episode = 0

    def observation(self):
        i, k, j = self.index, self.episode, self.step_in_episode
        return np.array([0.6 * j - 1.0 + 0.25 * i, 0.9 * k - 0.5 - 0.3 * i, 0.2 * j - 0.35 * k + 0.4 * i])

    def step(self, action):
        end = self.ends.get(self.steps)
        reward = 1.0 + 0.125 * self.steps + 0.5 * self.index
        self.steps += 1
        self.step_in_episode += 1
        return self.observation(), reward, end in ("terminated", "both"), end in ("truncated", "both"), {}

    def reset(self):
        self.episode += 1
        self.step_in_episode = 0
        return self.observation(), {}


class WatchedEnv:
    """An environment as the graded code sees it: step and reset, each call written to the shared log."""

    offered_to_graded_code = ("step", "reset")

    def __init__(self, env, index, log):
        self.env, self.index, self.log = env, index, log

    def step(self, action):
        self.log.append(("step", self.index, np.array(action, dtype=np.float64)))
        return self.env.step(action)

    def reset(self):
        self.log.append(("reset", self.index))
        return self.env.reset()


class WatchedNormalizer:
    """An ObservationNormalizer as the graded code sees it: calling it normalises, update folds raw observations into
    its statistics; both are written to the shared log."""

    offered_to_graded_code = ("__call__", "update")

    def __init__(self, normalizer, log):
        self.normalizer, self.log = normalizer, log

    def __call__(self, raw):
        raw = np.array(raw, dtype=np.float64)
        self.log.append(("normalise", raw.copy()))
        return self.normalizer(raw)

    def update(self, raw):
        raw = np.array(raw, dtype=np.float64)
        self.log.append(("update", raw.copy()))
        self.normalizer.update(raw)


ROLLOUT_KEYS = ("obs", "actions", "logp", "values", "next_values", "rewards", "terminated", "truncated", "raw_obs")
OBS_DIM = 3


def scripted_normalizer():
    """An ObservationNormalizer whose statistics are far from 0 and 1, so that normalising changes every number."""
    normalizer = ObservationNormalizer((OBS_DIM,))
    normalizer.stats.mean = np.array([0.4, 0.3, -0.2])
    normalizer.stats.var = np.array([2.5, 0.6, 1.8])
    normalizer.stats.count = 40.0
    normalizer.refresh()
    return normalizer


def show(value) -> str:
    value = np.asarray(value, dtype=np.float64)
    if value.ndim == 0:
        return f"{float(value):.6g}"
    return " ".join(np.array2string(value, precision=4, suppress_small=True).split())


class Scene:
    """N scripted environments (``ends``, one dict per environment), an agent, its normaliser and its random numbers,
    for batches of T steps in a row; ``expect`` works out each batch from the script, ``run`` grades one."""

    def __init__(self, ends, horizon, kind="discrete", bounds=None, seed=0):
        self.T, self.N, self.bounds = horizon, len(ends), bounds
        act_dim = 2 if kind == "continuous" else 3
        spec = AgentSpec(OBS_DIM, kind, act_dim, (8, 8), log_std_init=0.3)
        self.agent = ActorCritic(spec, np.random.default_rng(seed))
        self.rng, self.replay = np.random.default_rng(seed + 1), np.random.default_rng(seed + 1)
        self.envs = [ScriptedEnv(i, e) for i, e in enumerate(ends)]
        self.twins = [ScriptedEnv(i, e) for i, e in enumerate(ends)]  # the same course, stepped by the tests
        self.normalizer, self.twin_normalizer = scripted_normalizer(), scripted_normalizer()
        self.raw_obs = np.stack([env.observation() for env in self.envs])
        self.batches = 0

    def expect(self) -> dict:
        """The batch as the contract defines it, worked out from the script, with the usual mistakes beside it."""
        T, N = self.T, self.N
        s = np.empty((T + 1, N, OBS_DIM))  # s_0 … s_T
        s[0] = [twin.observation() for twin in self.twins]
        final = np.empty((T, N, OBS_DIM))  # what each step returned, before any reset
        rewards, terminated, truncated, both = np.zeros((T, N)), *np.zeros((3, T, N), dtype=bool)
        for t in range(T):
            for i, twin in enumerate(self.twins):
                final[t, i], rewards[t, i], term, trunc, _ = twin.step(None)
                terminated[t, i], truncated[t, i], both[t, i] = term, trunc and not term, term and trunc
                s[t + 1, i] = twin.reset()[0] if term or trunc else final[t, i]
        normalize, policy = self.twin_normalizer, SnapshotPolicy(self.agent, self.replay, T, N)
        updated = copy.deepcopy(normalize)
        updated.update(s[:T].reshape(-1, OBS_DIM))
        o = normalize(s)
        actions = np.stack([policy.actions_for(t, o[t]) for t in range(T)])
        clipped = actions if self.bounds is None else np.clip(actions, *self.bounds)
        V, V_final = policy.value(o), policy.value(normalize(final))
        ended = terminated | truncated
        self.twin_normalizer = updated
        return {
            "obs": o[:T],
            "actions": actions,
            "logp": policy.log_prob(o[:T], actions),
            "values": V[:T],
            "next_values": np.where(terminated, 0.0, np.where(truncated, V_final, V[1:])),
            "rewards": rewards,
            "terminated": terminated,
            "truncated": truncated,
            "raw_obs": s[T],
            # what the mistakes give
            "s": s,
            "final": final,
            "ended": ended,
            "both": both,
            "clipped": clipped,
            "logp_clipped": policy.log_prob(o[:T], clipped),
            "o": o,
            "o_updated": updated(s),
            "V": V,
            "V_final": V_final,
            "o_final": normalize(final),
            "V_updated": policy.value(updated(s)),
            "V_final_updated": policy.value(updated(final)),
        }

    def describe(self, want, t, i) -> str:
        where = f"step t = {t} of environment {i}"
        if want["both"][t, i]:
            where += ", which reported both terminated and truncated"
        elif want["terminated"][t, i]:
            where += ", where its episode terminated"
        elif want["truncated"][t, i]:
            where += ", where a time limit truncated its episode"
        return where + (", the batch's last step" if t == self.T - 1 else "")

    def run(self, student) -> dict:
        """Grade one batch: the calls collect made (to the policy, the environments and the normaliser), then what it
        returned. Returns the expected batch."""
        self.batches += 1
        T, N, log = self.T, self.N, []
        policy = SnapshotPolicy(self.agent, self.rng, T, N, log)
        envs = [WatchedEnv(env, i, log) for i, env in enumerate(self.envs)]
        raw_obs = self.raw_obs.copy()
        result = student.collect(policy, envs, WatchedNormalizer(self.normalizer, log), raw_obs, T, self.bounds)
        assert np.array_equal(raw_obs, self.raw_obs), (
            "collect changed its input raw_obs in place: copy it (np.array(raw_obs, dtype=np.float64)) and work on "
            "the copy"
        )
        want = self.expect()
        self.check_calls(log, want)
        self.check_result(result, want, raw_obs)
        self.raw_obs = want["raw_obs"]
        return want

    def check_calls(self, log, want) -> None:
        T, N = self.T, self.N
        batch = f" (batch {self.batches})" if self.batches > 1 else ""
        updates = [k for k, event in enumerate(log) if event[0] == "update"]
        steps = [k for k, event in enumerate(log) if event[0] == "step"]
        assert updates, (
            f"collect: obs_normalizer.update was never called{batch}: call it once, after the last step, with the "
            "raw observations s_0 … s_{T−1} the policy acted on"
        )
        if len(updates) > 1:
            after = [sum(1 for k in steps if k < u) // N - 1 for u in updates]
            raise AssertionError(
                f"collect: obs_normalizer.update was called {len(updates)} times{batch} (after steps "
                f"{', '.join(str(t) for t in after[:6])}{', …' if len(after) > 6 else ''}): the statistics were "
                "updated mid-rollout, so the batch's observations were normalised with different statistics; call it "
                "once, last"
            )
        update = updates[0]
        if steps and update < steps[-1]:
            done = sum(1 for k in steps if k < update) // N
            raise AssertionError(
                f"collect: obs_normalizer.update was called before the batch ended{batch} (after {done} of its "
                f"T = {T} steps): the steps after it were normalised with other statistics; call it once, last"
            )
        late = [event[1] for event in log[update + 1 :] if event[0] == "normalise"]
        if late:
            raise AssertionError(
                f"collect: obs_normalizer was called (on {show(late[0])}) after obs_normalizer.update{batch}: what it "
                "normalised then (s_T, or a truncated episode's final observation, for a bootstrap value) saw the "
                "updated statistics instead of the batch's; normalise everything first and update the statistics last"
            )
        for i in range(N):
            mine = [event for event in log if event[0] in ("step", "reset") and event[1] == i]
            t = 0
            for k, event in enumerate(mine):
                if event[0] == "reset":
                    if t == 0 or t > T or not want["ended"][t - 1, i] or mine[k - 1][0] == "reset":
                        when = "before its first step" if t == 0 else f"after step t = {t - 1}"
                        raise AssertionError(
                            f"collect: environment {i} was reset {when}{batch}, where its episode had not ended: "
                            "call env.reset() only right after a step that returned terminated or truncated"
                        )
                    continue
                if 0 < t <= T and want["ended"][t - 1, i] and mine[k - 1][0] != "reset":
                    how = "terminated" if want["terminated"][t - 1, i] else "truncated"
                    raise AssertionError(
                        f"collect: environment {i}'s episode ended at step t = {t - 1} ({how}){batch}, but it was "
                        f"stepped again at step {t} without env.reset(): reset it right after a step that returned "
                        "terminated or truncated, and go on from the observation reset returns"
                    )
                t += 1
            assert t == T, (
                f"collect: environment {i} took {t} steps in a batch of T = {T}{batch}: every environment takes one "
                "step per step of the batch"
            )
            if want["ended"][T - 1, i]:
                assert mine[-1][0] == "reset", (
                    f"collect: environment {i}'s episode ended at the batch's last step{batch}, but it was not reset: "
                    "reset it, so that the next batch starts from the new episode's first observation"
                )
        samples = [event for event in log if event[0] == "sample"]
        assert len(samples) == T, (
            f"collect: policy.sample was called {len(samples)} times in a batch of T = {T} steps: call it once per "
            "step, with the N observations of that step"
        )
        for _, t, given in samples:
            wrong = ~np.all(np.isclose(given, want["obs"][t], rtol=1e-9, atol=1e-12), axis=-1)
            if wrong.any():
                i = int(np.argmax(wrong))
                guess = ""
                if np.allclose(given[i], want["s"][t, i]):
                    guess = ": the raw observation s_t; the policy acts on o_t = obs_normalizer(s_t)"
                elif np.allclose(given[i], want["o_updated"][t, i]):
                    guess = ": normalised with statistics updated during the batch"
                elif t > 0 and want["ended"][t - 1, i] and np.allclose(given[i], want["o_final"][t - 1, i]):
                    guess = (
                        ": the final observation of the episode that ended at step t − 1; after env.reset(), go on "
                        "from the observation reset returns"
                    )
                raise AssertionError(
                    f"collect: policy.sample at step t = {t}{batch} got {show(given[i])} for environment {i}, not "
                    f"o_t = obs_normalizer(s_t) = {show(want['obs'][t, i])} (s_t = {show(want['s'][t, i])}){guess}"
                )
        for i in range(N):
            given_actions = [event[2] for event in log if event[0] == "step" and event[1] == i]
            for t, action in enumerate(given_actions):
                expected = want["clipped"][t, i]
                if not np.allclose(action, expected, rtol=1e-9, atol=1e-12):
                    guess = ""
                    if self.bounds is not None and np.allclose(action, want["actions"][t, i]):
                        guess = (
                            ": the action as sampled; with action_bounds the environment gets np.clip(a_t, low, high)"
                        )
                    raise AssertionError(
                        f"collect: environment {i} was given the action {show(action)} at step t = {t}{batch}, "
                        f"not {show(expected)} (a_t[{i}] of policy.sample(o_t)"
                        f"{', clipped to action_bounds' if self.bounds is not None else ''}){guess}"
                    )
        given = log[update][1]
        rows = given.reshape(-1, OBS_DIM) if given.size % OBS_DIM == 0 else given
        acted = want["s"][:T].reshape(-1, OBS_DIM)
        if rows.shape == acted.shape and np.allclose(np.sort(rows, axis=0), np.sort(acted, axis=0), 1e-12, 1e-12):
            return
        candidates = {
            "s_1 … s_T, the observations after each step, not s_0 … s_{T−1}, the ones the policy acted on": want["s"][
                1:
            ],
            "the normalised observations o_t; the statistics are of the raw observations": want["obs"],
            "s_0 … s_T, s_T included; only the T·N observations the policy acted on": want["s"],
        }
        extra = want["final"][want["truncated"]]
        if len(extra):
            candidates["s_0 … s_{T−1} with the final observations of the truncated episodes; only what the policy "
                       "acted on"] = np.concatenate([acted, extra])  # fmt: skip
        named = ""
        for words, rows_of in candidates.items():
            rows_of = np.asarray(rows_of).reshape(-1, OBS_DIM)
            if rows.shape == rows_of.shape and np.allclose(np.sort(rows, axis=0), np.sort(rows_of, axis=0)):
                named = f": {words}?"
        raise AssertionError(
            f"collect: obs_normalizer.update{batch} should get the T·N = {T * N} raw observations s_0 … s_{{T−1}} "
            f"the policy acted on, as an array of shape ({T * N}, {OBS_DIM}) or ({T}, {N}, {OBS_DIM}), not the array "
            f"of shape {given.shape} it got{named}"
        )

    def check_result(self, result, want, raw_obs) -> None:
        T, N = self.T, self.N
        batch = f" of batch {self.batches}" if self.batches > 1 else ""
        assert isinstance(result, dict), (
            f"collect: it should return a dict with the keys {', '.join(ROLLOUT_KEYS)}, not {type(result).__name__}"
        )
        missing = [key for key in ROLLOUT_KEYS if key not in result]
        assert not missing, f"collect: the dict it returns lacks the key(s) {', '.join(missing)}"
        check_rollout_arrays(result, want, T, N, raw_obs)

        def entries(name, alternatives=()):
            check_entries(result[name], want[name], name, lambda t, i: self.describe(want, t, i) + batch, alternatives)

        entries("obs", {"the raw observation s_t; store o_t = obs_normalizer(s_t)": want["s"][:T]})
        entries("actions", {"the clipped action; store a_t as policy.sample returned it": want["clipped"]})
        entries("rewards")
        for name in ("terminated", "truncated"):
            flags = result[name]
            wrong = flags != want[name]
            if wrong.any():
                t, i = (int(x) for x in np.argwhere(wrong)[0])
                why = ""
                if want["both"][t, i]:
                    why = ": a step that reports both terminated and truncated counts as terminated (nothing follows)"
                raise AssertionError(
                    f"collect: {name}[{t}, {i}] ({self.describe(want, t, i)}{batch}) should be "
                    f"{bool(want[name][t, i])}, not {bool(flags[t, i])}{why}"
                )
        entries(
            "logp",
            {"log π_θold of the clipped action sent to the environment, not of a_t as sampled": want["logp_clipped"]},
        )
        entries("values", {"V of the raw observation s_t; V(o_t) takes the normalised one": self.raw_values(want)})
        T1 = np.arange(T) == T - 1
        V_next_later = np.where(T1[:, None], want["V"][T], want["V"][np.minimum(np.arange(T) + 2, T)])
        at_truncation = np.where(want["truncated"], 1.0, np.nan)  # a mistake named only where it shows
        at_termination = np.where(want["terminated"], 1.0, np.nan)
        entries(
            "next_values",
            {
                "0 where a time limit truncated the episode: no bootstrap at a truncation, but a time limit is not a "
                "terminal state; bootstrap from V of the final observation the step returned": 0.0 * at_truncation,
                "V of the final observation where the episode terminated: a bootstrap at a termination, where nothing "
                "follows (0)": want["V_final"] * at_termination,
                "V of the observation env.reset() returned (the next episode's first), not of the final observation "
                "the step returned; keep that one before resetting": want["V"][1:] * at_truncation,
                "V of the observation env.reset() returned (the next episode's first) where the episode terminated: "
                "nothing follows a terminal state, so next_values is 0 there (minippo's Batch keeps that value, which "
                "GAE multiplies by 0; the contract asks for 0)": want["V"][1:] * at_termination,
                "V(o_t), the value of the step's own observation (off by one): next_values[t] is V(o_{t+1})": want[
                    "values"
                ],
                "V(o_{t+2}) (off by one)": V_next_later,
                "normalised with the statistics updated by this batch; normalise with the batch's statistics, then "
                "update": np.where(want["truncated"], want["V_final_updated"], want["V_updated"][1:]),
            },
        )
        got = result["raw_obs"]
        if not np.allclose(got, want["raw_obs"], rtol=1e-12, atol=1e-12):
            i = int(np.argmax(~np.all(np.isclose(got, want["raw_obs"], 1e-12, 1e-12), axis=-1)))
            guess = ""
            if np.allclose(got[i], want["s"][T - 1, i]):
                guess = ": s_{T−1}, the observation of the last step, not the one after it"
            elif np.allclose(got[i], want["final"][T - 1, i]):
                guess = ": the final observation of the episode that ended at the last step, not the one reset returned"
            elif np.allclose(got[i], want["o_updated"][T, i]) or np.allclose(got[i], want["o"][T, i]):
                guess = ": a normalised observation; raw_obs holds the raw s_T"
            raise AssertionError(
                f"collect: raw_obs{batch} should be s_T, the raw observation each environment is at after the batch; "
                f"for environment {i} it is {show(got[i])}, not {show(want['raw_obs'][i])}{guess}"
            )

    def raw_values(self, want):
        return SnapshotPolicy(self.agent, np.random.default_rng(0), self.T, self.N).value(want["s"][: self.T])


def check_rollout_arrays(result, want, T, N, raw_obs=None) -> None:
    """Every array of the batch has the contract's shape and dtype, and none is one of the inputs."""
    for name in ("obs", "logp", "values", "next_values", "rewards", "raw_obs"):
        check_array(result[name], "collect", want[name].shape, f'the batch\'s "{name}"')
    actions = result["actions"]
    assert isinstance(actions, np.ndarray) and actions.shape == want["actions"].shape, (
        f'collect: the batch\'s "actions" should be an array of shape {want["actions"].shape} (a_t as '
        f"policy.sample returned them), not {getattr(actions, 'shape', type(actions).__name__)}"
    )
    assert actions.dtype == want["actions"].dtype, (
        f'collect: the batch\'s "actions" should be {want["actions"].dtype}, as policy.sample returns them, not '
        f"{actions.dtype}"
    )
    for name in ("terminated", "truncated"):
        flags = result[name]
        assert isinstance(flags, np.ndarray) and flags.shape == (T, N) and flags.dtype == bool, (
            f'collect: the batch\'s "{name}" should be a bool array of shape {(T, N)}, not '
            f"{getattr(flags, 'dtype', type(flags).__name__)} {getattr(flags, 'shape', '')}"
        )
    if raw_obs is not None:
        for name in ROLLOUT_KEYS:
            assert not np.shares_memory(result[name], raw_obs), (
                f'collect: the batch\'s "{name}" is the input raw_obs (or a view of it): return a new array'
            )


def check_entries(got, want, name, describe, alternatives=(), rtol=1e-9, atol=1e-12) -> None:
    """``got`` equals ``want`` entry by entry, or the test fails at the earliest step (then environment) where they
    differ, saying where that is and which of ``alternatives`` (words: what a mistake gives) the entry equals."""
    got, want = np.asarray(got, dtype=np.float64), np.asarray(want, dtype=np.float64)
    close = np.isclose(got, want, rtol=rtol, atol=atol)
    wrong = ~close.reshape(close.shape[:2] + (-1,)).all(axis=-1)
    if not wrong.any():
        return
    t, i = (int(x) for x in np.argwhere(wrong)[0])
    named = [
        words
        for words, value in dict(alternatives).items()
        if np.allclose(got[t, i], np.asarray(value)[t, i], rtol=rtol, atol=atol)
        and not np.allclose(want[t, i], np.asarray(value)[t, i], rtol=rtol, atol=atol)
    ]
    raise AssertionError(
        f"collect: {name}[{t}, {i}] ({describe(t, i)}) should be {show(want[t, i])}, not {show(got[t, i])}"
        + (": " + " Or ".join(f"{words}?" for words in named) if named else "")
    )


def test_collect_one_step_in_one_environment(student):
    Scene([{}], horizon=1).run(student)


def test_collect_several_steps_in_several_environments(student):
    Scene([{}, {}, {}], horizon=5, seed=1).run(student)


def test_collect_clips_only_what_the_environments_get(student):
    bounds = (np.array([-0.5, -0.2]), np.array([0.5, 0.9]))
    Scene([{}, {}], horizon=4, kind="continuous", bounds=bounds, seed=2).run(student)


def test_collect_at_terminations(student):
    # an episode that terminates mid-batch, one at the first step and at the last, one that lasts a single step
    ends = [{2: "terminated"}, {0: "terminated", 6: "terminated"}, {3: "terminated", 4: "terminated"}]
    Scene(ends, horizon=7, seed=3).run(student)


def test_collect_at_truncations(student):
    # a time limit mid-batch, one at the batch's last step, and truncations around a termination
    ends = [{2: "truncated"}, {6: "truncated"}, {1: "truncated", 4: "terminated", 5: "truncated"}]
    Scene(ends, horizon=7, seed=4).run(student)


def test_collect_when_a_step_reports_both_flags(student):
    ends = [{1: "both"}, {2: "truncated", 4: "both"}]
    Scene(ends, horizon=5, seed=5).run(student)


def test_collect_two_batches_in_a_row(student):
    # the second batch starts where the first ended (raw_obs), with the statistics the first one's update left
    ends = [{3: "truncated", 8: "terminated"}, {5: "both", 7: "truncated"}, {4: "terminated", 6: "truncated"}]
    bounds = (np.array([-0.6, -0.6]), np.array([0.6, 0.6]))
    scene = Scene(ends, horizon=5, kind="continuous", bounds=bounds, seed=6)
    scene.run(student)
    scene.run(student)


def test_collect_matches_minippo_s_rollout_on_cartpole(student):
    # three batches of T = 64 steps in N = 4 CartPole-v1 environments with a time limit of 30 steps, so that the
    # untrained policy's episodes both terminate (the pole falls) and are truncated; the statistics are on
    T, N, seed, batches = 64, 4, 3, 3
    agent = ActorCritic(AgentSpec(4, "discrete", 2, (64, 64)), np.random.default_rng(seed))

    def environments():
        return [TimeLimit(make_env("CartPole-v1"), max_episode_steps=30) for _ in range(N)]

    theirs, mine = environments(), environments()
    scaler = RewardScaler(0.99, enabled=False, num_envs=N)
    rollout = Rollout(theirs, agent, ObservationNormalizer((4,)), scaler, T, np.random.default_rng(seed), seed)
    normalizer, rng = ObservationNormalizer((4,)), np.random.default_rng(seed)
    raw = np.stack([env.reset(seed=seed + i)[0] for i, env in enumerate(mine)]).astype(np.float64)
    seen = {"terminated": 0, "truncated": 0}
    try:
        for b in range(1, batches + 1):
            batch = rollout.collect()
            log = []
            envs = [WatchedEnv(env, i, log) for i, env in enumerate(mine)]
            policy = SnapshotPolicy(agent, rng, T, N, log)
            result = student.collect(policy, envs, WatchedNormalizer(normalizer, log), raw, T)
            assert isinstance(result, dict) and all(key in result for key in ROLLOUT_KEYS), (
                f"collect: it should return a dict with the keys {', '.join(ROLLOUT_KEYS)}"
            )
            theirs_batch = {
                "obs": batch.obs,
                "actions": batch.actions,
                "logp": batch.logp,
                "values": batch.values,
                # minippo keeps V of the next episode's first observation where one terminated; the contract, 0
                "next_values": np.where(batch.terminated, 0.0, batch.next_values),
                "rewards": batch.rewards,
                "terminated": batch.terminated,
                "truncated": batch.truncated,
                "raw_obs": rollout.raw_obs,
            }
            check_rollout_arrays(result, theirs_batch, T, N, raw)
            for _, t, given in (event for event in log if event[0] == "sample"):
                check_close(
                    given,
                    batch.obs[t],
                    "collect",
                    f"the observations policy.sample got at step t = {t} of batch {b} on CartPole-v1 (minippo's o_t)",
                    rtol=1e-9,
                    atol=1e-12,
                )

            def where(t, i, b=b, flags=batch):
                end = " (terminated there)" if flags.terminated[t, i] else ""
                end = " (truncated there)" if flags.truncated[t, i] else end
                return f"CartPole-v1, batch {b}, step t = {t} of environment {i}{end}; the value is minippo's"

            for name in ("obs", "actions", "rewards", "terminated", "truncated", "logp", "values", "next_values"):
                check_entries(result[name], theirs_batch[name], name, where)
            check_close(result["raw_obs"], rollout.raw_obs, "collect", f"raw_obs after batch {b} (minippo's s_T)")
            for stat in ("mean", "var", "count"):
                check_close(
                    getattr(normalizer.stats, stat),
                    getattr(rollout.obs_normalizer.stats, stat),
                    "collect",
                    f"the observation statistics' {stat} after batch {b} (minippo's, updated with s_0 … s_(T−1))",
                    rtol=1e-9,
                    atol=1e-12,
                )
            raw = result["raw_obs"]
            seen["terminated"] += int(batch.terminated.sum())
            seen["truncated"] += int(batch.truncated.sum())
    finally:
        for env in theirs + mine:
            env.close()
    assert seen["terminated"] and seen["truncated"], f"the test's run should hold both kinds of episode end: {seen}"


# Algorithm 1 with your update: CartPole-v1 must learn.


LEARN_STEPS = 60_000
LEARN_THRESHOLD = 150.0


# the transfer task: the loss's gradient at the output of a shared trunk


@pytest.fixture
def trunk_case(rng):
    n, d, k = 8, 5, 3
    features, policy_weights, value_weights = (
        rng.standard_normal((n, d)),
        rng.normal(0, 0.5, (d, k)),
        rng.standard_normal(d),
    )
    actions = rng.integers(0, k, n)
    logits = features @ policy_weights
    log_probs = logits - np.log(np.exp(logits).sum(axis=1, keepdims=True))
    ratios = np.array([0.6, 0.9, 1.0, 1.1, 1.5, 0.7, 1.05, 2.0])  # both sides of the band and inside, off its edges
    logp_old = log_probs[np.arange(n), actions] - np.log(ratios)
    return features, policy_weights, value_weights, actions, logp_old, rng.standard_normal(n), rng.standard_normal(n)


def trunk_loss(features, policy_weights, value_weights, actions, logp_old, advantages, returns, epsilon, value_coef):
    logits = features @ policy_weights
    log_probs = logits - np.log(np.exp(logits).sum(axis=1, keepdims=True))
    clip_value, _ = losses.clip_objective(log_probs[np.arange(len(actions)), actions], logp_old, advantages, epsilon)
    values = features @ value_weights
    return -clip_value + value_coef * 0.5 * float(np.mean((values - returns) ** 2))


def test_shared_trunk_gradient_of_the_value_head_alone(student, trunk_case):
    # with Â = 0 the policy's term is 0 everywhere: what is left is c1 ∂L^VF/∂h, through the value head only
    features, policy_weights, value_weights, actions, logp_old, _, returns = trunk_case
    advantages = np.zeros(len(actions))
    result = call_checking_inputs(
        student.shared_trunk_gradient, "shared_trunk_gradient", features, policy_weights, value_weights, actions,
        logp_old, advantages, returns, 0.2, 0.5,
    )  # fmt: skip
    assert isinstance(result, tuple) and len(result) == 2, "shared_trunk_gradient should return (loss, grad_features)"
    grad = check_array(result[1], "shared_trunk_gradient", features.shape, "∂loss/∂h with Â = 0")
    error = features @ value_weights - returns
    expected = 0.5 * error[:, None] * value_weights[None, :] / len(actions)
    mistakes = {
        "the value term's sign flipped (the loss adds c1 L^VF; the objective subtracts it)": -expected,
        "the value head's gradient missing: only the policy's path into h": np.zeros(features.shape),
        "L^VF without its ½ (chapter 8's value loss has it)": 2 * expected,
    }
    for words, wrong in mistakes.items():
        if np.allclose(grad, wrong, rtol=1e-6, atol=1e-12):
            raise AssertionError(
                f"shared_trunk_gradient: with Â = 0 the gradient should be c1 (V_t − V^targ_t) w_V / n, row by row, "
                f"not what it is: {words}?"
            )
    check_close(grad, expected, "shared_trunk_gradient", "∂loss/∂h with Â = 0 (the value head's path alone)")


def test_shared_trunk_gradient_matches_finite_differences(student, trunk_case):
    features, policy_weights, value_weights, actions, logp_old, advantages, returns = trunk_case
    args = (policy_weights, value_weights, actions, logp_old, advantages, returns, 0.2, 0.5)
    loss, grad = student.shared_trunk_gradient(features, *args)
    check_close(
        check_scalar(loss, "shared_trunk_gradient"),
        trunk_loss(features, *args),
        "shared_trunk_gradient",
        "the loss −(L^CLIP − c1 L^VF)",
    )
    h = features.copy()
    numeric = numerical_gradient(lambda: trunk_loss(h, *args), h, 1e-7)
    policy_only = numeric - 0.5 * ((features @ value_weights - returns)[:, None] * value_weights[None, :]) / len(
        actions
    )
    if np.allclose(grad, policy_only, rtol=1e-5, atol=1e-8):
        raise AssertionError(
            "shared_trunk_gradient: ∂loss/∂h holds the policy head's path only: the value head reads the same h, and "
            "its gradient adds up with the policy's there?"
        )
    check_close(
        check_array(grad, "shared_trunk_gradient", features.shape, "∂loss/∂h"),
        numeric,
        "shared_trunk_gradient",
        "∂loss/∂h (finite differences)",
        1e-5,
        1e-8,
    )


@pytest.mark.timeout(150)
def test_ppo_update_learns_cartpole(student):
    config = Config(**CARTPOLE_PPO, total_steps=LEARN_STEPS, seed=1)
    trainer = Trainer(config)
    started, recent = time.perf_counter(), [0.0]
    try:
        for update in range(1, config.num_updates + 1):
            trainer.optimizer.lr = linear_schedule(config.lr, update, config.num_updates)
            batch = trainer.rollout.collect()
            advantages, returns = compute_advantages(batch, config)
            data = flatten(batch, advantages, returns, trainer.agent.params.dtype)
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
