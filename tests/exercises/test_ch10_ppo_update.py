"""Grading chapter 10: the assembled loss against its definition and finite differences at several configurations
(ε, c1, c2, advantage normalisation on and off), the epoch and minibatch loop (the number of steps, the exact order of
the rows with and without shuffling from the rng passed in, the gradient clip, each minibatch's own gradient), and
finally PPO learning CartPole-v1 with your update inside minippo's rollout, a backstop rather than the evidence.

Tests run from the most specific to the most general, so the first failure names the mistake."""

import dataclasses
import time

import _harness
import numpy as np
import pytest
from _harness import call_checking_inputs, check_close, check_scalar, numerical_gradient, where_is_ratio

from minippo import losses
from minippo.agent import ActorCritic
from minippo.optimizer import linear_schedule
from minippo.ppo import Config, Trainer, compute_advantages, flatten
from minippo.presets import CARTPOLE_PPO

student = _harness.student  # the fixture: the implementation under test (see _harness.py)
pytest_generate_tests = _harness.pytest_generate_tests  # one run per wrong variant under MINIPPO_IMPL=wrong
rng = _harness.rng  # a seeded NumPy Generator

pytestmark = pytest.mark.timeout(30)
# clear of the band's edges for ε = 0.1, 0.2, 0.3, with one ratio in each window between 1 ± ε and e^±ε
RATIOS = np.array([0.5, 0.75, 0.95, 1.0, 1.05, 1.25, 1.6, 0.85, 1.15, 1.21, 0.81, 1.103, 0.902, 1.32, 0.72, 2.0])


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


# Algorithm 1 with your update: CartPole-v1 must learn.


LEARN_STEPS = 60_000
LEARN_THRESHOLD = 150.0


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
