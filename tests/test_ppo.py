"""The assembled algorithm: the whole loss gradient by finite differences, determinism, learning, checkpoints."""

import csv
import dataclasses
import json

import numpy as np
import pytest
from conftest import assert_close, numerical_gradient

from minippo import Config, train
from minippo.agent import ActorCritic, AgentSpec
from minippo.agent_files import load_policy, save_policy
from minippo.errors import MinippoError, NonFiniteError
from minippo.normalization import ObservationNormalizer, RewardScaler, RunningMeanStd
from minippo.optimizer import Adam
from minippo.ppo import loss_and_grad, update_minibatch
from minippo.presets import CARTPOLE_PPO, MUJOCO
from minippo.rollout import Rollout
from minippo.run_folder import PROGRESS_FIELDS

TIMING = {"steps_per_s", "wall_s"}


def minibatch(agent, rng, n=9):
    obs = rng.standard_normal((n, agent.obs_dim))
    out, values, _ = agent.forward(obs)
    if agent.kind == "discrete":
        actions = rng.integers(0, agent.act_dim, n)
        old_out = out + 0.3 * rng.standard_normal(out.shape)
    else:
        actions = out + rng.standard_normal(out.shape)
        old_out = out + 0.1 * rng.standard_normal(out.shape)
    old_log_std = agent.log_std + 0.2 * rng.standard_normal(agent.log_std.shape)  # π_θold's own σ, not the live one
    old = agent.distribution(old_out, old_log_std)
    return {
        "obs": obs,
        "actions": actions,
        "logp": old.log_prob(actions),
        "policy_out": old_out,
        "policy_log_std": np.tile(old_log_std, (n, 1)),
        "values": values + 0.05 * rng.standard_normal(n),
        "advantages": rng.standard_normal(n),
        "returns": values + rng.standard_normal(n),
    }


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
@pytest.mark.parametrize("shared", [False, True])
@pytest.mark.parametrize("objective", ["clip", "cpi", "klpen", "pg"])
def test_whole_loss_gradient_matches_finite_differences(rng, kind, shared, objective):
    agent = ActorCritic(AgentSpec(4, kind, 3, hidden_sizes=(8, 8), shared=shared, log_std_init=-0.3), rng)
    agent.params[...] += 0.3 * rng.standard_normal(agent.params.shape)  # move the heads off their tiny init
    config = Config(objective=objective, entropy_coef=0.01, value_coef=0.7)
    mb = minibatch(agent, rng)
    loss, _ = loss_and_grad(agent, mb, config, kl_beta=2.0)
    analytic = agent.grads.copy()
    numeric = numerical_gradient(lambda: loss_and_grad(agent, mb, config, kl_beta=2.0)[0], agent.params)
    assert_close(analytic, numeric, rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
@pytest.mark.parametrize("objective", ["clip", "cpi", "klpen", "pg"])
def test_a_float32_agent_computes_its_gradients_in_float32(rng, kind, objective, monkeypatch):
    """One float64 number in the chain (a NumPy float64 scalar is enough) would turn every matmul of the backward
    pass into float64 and cost a third of the update's time, without changing any result visibly."""
    agent = ActorCritic(AgentSpec(4, kind, 3, hidden_sizes=(8, 8), dtype="float32"), rng)
    mb = {
        key: value.astype(np.float32) if value.dtype.kind == "f" else value
        for key, value in minibatch(agent, rng).items()
    }
    seen = {}
    backward = agent.backward

    def spy(cache, grad_out, grad_values, grad_log_std=None):
        seen.update(out=grad_out.dtype.name, values=grad_values.dtype.name)
        return backward(cache, grad_out, grad_values, grad_log_std)

    monkeypatch.setattr(agent, "backward", spy)
    loss_and_grad(agent, mb, Config(objective=objective, entropy_coef=0.01), kl_beta=2.0)
    assert seen == {"out": "float32", "values": "float32"}


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_a_nan_gradient_stops_before_the_parameters_change(rng):
    agent = ActorCritic(AgentSpec(4, "continuous", 2, hidden_sizes=(8,)), rng)
    mb = minibatch(agent, rng)
    mb["advantages"][0] = np.inf
    before = agent.params.copy()
    with pytest.raises(NonFiniteError):
        update_minibatch(agent, Adam(agent.params), mb, Config(), 1.0)
    assert np.array_equal(agent.params, before)


@pytest.mark.filterwarnings("error")
def test_the_observation_check_stops_nan_and_inf_and_nothing_else():
    rollout = Rollout.__new__(Rollout)  # the check reads only the step count
    rollout.steps = 4096
    huge = np.array([1e200, -1e200, 3.0])  # finite, though its square overflows
    assert rollout._check(huge, 0) is huge
    for bad in (np.nan, np.inf, -np.inf):
        with pytest.raises(NonFiniteError, match="at step 4100"):
            rollout._check(np.array([1.0, bad, 2.0]), 3)


def test_running_mean_std_matches_numpy(rng):
    data = rng.normal(3.0, 2.0, (1000, 3))
    stats = RunningMeanStd((3,), epsilon=0.0)
    for chunk in np.array_split(data, 7):
        stats.update(chunk)
    assert np.allclose(stats.mean, data.mean(0)) and np.allclose(stats.var, data.var(0))


def test_normalizers_clip_and_scale(rng):
    norm = ObservationNormalizer((2,), clip=10.0)
    norm.update(rng.normal([5.0, -1.0], [2.0, 0.1], (5000, 2)))
    out = norm(rng.normal([5.0, -1.0], [2.0, 0.1], (5000, 2)))
    assert np.allclose(out.mean(0), 0, atol=0.1) and np.allclose(out.std(0), 1, atol=0.1)
    assert np.all(norm(np.array([[1e6, -1e6]])) == [[10.0, -10.0]])
    scaler = RewardScaler(gamma=0.99)
    scaled = scaler.scale(np.full((500, 1), 100.0), np.zeros((500, 1), bool))
    assert scaled.max() <= 10.0 and scaled.min() > 0  # divided, never shifted


def test_policy_round_trip(tmp_path, rng):
    agent = ActorCritic(AgentSpec(5, "continuous", 2, hidden_sizes=(16, 8), shared=True, log_std_init=-0.5), rng)
    norm = ObservationNormalizer((5,))
    norm.update(rng.normal(size=(100, 5)))
    save_policy(tmp_path / "policy.npz", agent, norm, {"env_id": "Hopper-v5"})
    loaded, loaded_norm, meta = load_policy(tmp_path / "policy.npz")
    obs = rng.normal(size=(3, 5))
    assert np.array_equal(loaded.policy_output(loaded_norm(obs)), agent.policy_output(norm(obs)))
    assert loaded.spec == agent.spec and meta["env_id"] == "Hopper-v5"
    assert meta["hidden_sizes"] == [16, 8] and meta["log_std_init"] == -0.5  # the spec's fields, as JSON has them


def test_a_policy_file_of_an_older_minippo_still_loads(tmp_path, rng):
    """Files written before the agent had a spec describe it with eight keys, dtype and network among them optional."""
    agent = ActorCritic(AgentSpec(4, "discrete", 2, hidden_sizes=(8,)), rng)
    norm = ObservationNormalizer((4,))
    old_meta = {"obs_dim": 4, "kind": "discrete", "act_dim": 2, "hidden_sizes": [8], "shared": False}
    old_meta |= {"env_id": "CartPole-v1", "normalize_observations": True, "obs_clip": 10.0}
    stats = {f"obs_{key}": value for key, value in norm.state_dict().items()}  # obs_mean, obs_var, obs_count, as ever
    path = tmp_path / "policy.npz"
    np.savez(path, params=agent.params, meta=np.array(json.dumps(old_meta)), **stats)
    loaded, _, _ = load_policy(path)
    assert loaded.spec == AgentSpec(4, "discrete", 2, hidden_sizes=(8,), dtype="float64")
    assert np.array_equal(loaded.params, agent.params)
    del old_meta["act_dim"]
    np.savez(path, params=agent.params, meta=np.array(json.dumps(old_meta)), **stats)
    with pytest.raises(MinippoError, match="no entry 'act_dim'"):
        load_policy(path)


def test_an_agent_spec_refuses_what_no_network_can_be():
    with pytest.raises(ValueError, match="kind must be"):
        AgentSpec(4, "multibinary", 2)
    with pytest.raises(ValueError, match="shared must be True"):
        AgentSpec(50, "discrete", 3, network="minatar_cnn", image_shape=(5, 5, 2))
    spec = AgentSpec(4, "discrete", 2)
    with pytest.raises(dataclasses.FrozenInstanceError):
        spec.act_dim = 3


def test_a_copy_is_the_same_agent_with_its_own_parameters(rng):
    agent = ActorCritic(AgentSpec(3, "continuous", 2, hidden_sizes=(8,), log_std_init=-1.0), rng)
    twin = agent.copy()
    assert twin.spec == agent.spec and np.array_equal(twin.params, agent.params)
    twin.params += 1.0
    assert not np.array_equal(twin.params, agent.params)


def read_rows(path):
    with open(path, newline="") as handle:
        return [{k: v for k, v in row.items() if k not in TIMING} for row in csv.DictReader(handle)]


@pytest.mark.parametrize("env_id", ["CartPole-v1", "Hopper-v5"])
def test_same_seed_same_progress_bitwise(tmp_path, env_id):
    config = dict(env_id=env_id, total_steps=1024, horizon=512, epochs=2, seed=7)
    train(Config(**config), out=tmp_path / "a")
    train(Config(**config), out=tmp_path / "b")
    train(Config(**{**config, "seed": 8}), out=tmp_path / "c")
    a, b, c = (read_rows(tmp_path / x / "progress.csv") for x in "abc")
    assert len(a) == 2 and a == b  # every learning number identical, to the last printed digit
    assert a != c
    assert (tmp_path / "a" / "policy.npz").read_bytes() == (tmp_path / "b" / "policy.npz").read_bytes()
    assert list(a[0]) == [f for f in PROGRESS_FIELDS if f not in TIMING]


CARTPOLE = CARTPOLE_PPO


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_cartpole_learns():
    rows = train(Config(**CARTPOLE, total_steps=50_176, seed=3))
    assert rows[0]["return_mean"] < 40  # random play lasts about 22 steps
    assert rows[-1]["return_mean"] > 150, rows[-1]


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_inverted_pendulum_learns():
    rows = train(Config(env_id="InvertedPendulum-v5", total_steps=30_720, horizon=1024, seed=1))
    assert rows[0]["return_mean"] < 30
    assert rows[-1]["return_mean"] > 150, rows[-1]  # the last-100 mean lags; single episodes reach 1000 soon after


def test_interrupted_run_resumes_from_its_checkpoint(tmp_path):
    config = Config(**CARTPOLE, total_steps=2048, seed=5, checkpoint_every=2)
    train(config, out=tmp_path)
    first = read_rows(tmp_path / "progress.csv")
    train(dataclasses.replace(config, total_steps=4096), out=tmp_path, resume=True)
    rows = read_rows(tmp_path / "progress.csv")
    assert [int(r["update"]) for r in rows] == list(range(1, 9))
    assert rows[:4] == first
    assert int(rows[-1]["step"]) == 4096


def test_the_paper_mujoco_preset_is_configs_defaults():
    defaults = Config()
    assert {key: getattr(defaults, key) for key in MUJOCO} == MUJOCO
    assert (defaults.horizon, defaults.lr, defaults.epochs, defaults.minibatch_size) == (2048, 3e-4, 10, 64)
