"""The atlas's faults: each injection changes what it says it changes, and nothing is left changed after it."""

import dataclasses
import json

import numpy as np
import pytest

import minippo.losses
import minippo.ppo
from benchmarks import atlas, atlas_signatures
from benchmarks.atlas_faults import FAULT_TASKS, FAULTS, TASKS, Fault, task_config
from minippo.distributions import DiagGaussian
from minippo.ppo import Config, Trainer, compute_advantages
from minippo.presets import CARTPOLE_PPO
from minippo.records import read_rows
from minippo.rollout import Batch
from minippo.run_folder import PROGRESS_FIELDS

TINY_CARTPOLE = Config(**{**CARTPOLE_PPO, "horizon": 128}, total_steps=128 * 4, seed=1)


@pytest.mark.parametrize("mode", [name for name, fault in FAULTS.items() if fault.patches])
def test_every_patch_is_in_place_inside_the_block_and_restored_after_it(mode):
    fault = FAULTS[mode]
    originals = [(owner, name, getattr(owner, name)) for owner, name, _ in fault.patches]
    with fault.injected_into():
        assert all(getattr(owner, name) is not original for owner, name, original in originals)
    assert all(getattr(owner, name) is original for owner, name, original in originals)


def test_a_patch_is_restored_when_the_block_raises():
    original = minippo.losses.value_loss
    with pytest.raises(RuntimeError), FAULTS["value_loss_sign"].injected_into():
        raise RuntimeError
    assert minippo.losses.value_loss is original


@pytest.mark.parametrize("mode", [name for name, fault in FAULTS.items() if name != "healthy" and not fault.patches])
def test_a_config_fault_changes_its_fields_and_leaves_the_task_config_alone(mode):
    for task in FAULT_TASKS:
        if task in FAULTS[mode].not_applicable:
            continue
        base = task_config(task, 1)
        kept = dataclasses.asdict(base)
        faulty = FAULTS[mode].configure(base)
        assert dataclasses.asdict(base) == kept
        changed = {k for k, v in dataclasses.asdict(faulty).items() if kept[k] != v}
        assert changed and changed == set(FAULTS[mode].changes(base))


def test_the_ratio_against_the_current_policy_never_clips_and_logs_no_kl():
    healthy, faulty = Trainer(TINY_CARTPOLE), Trainer(TINY_CARTPOLE)
    healthy_rows = [healthy.run_update() for _ in range(4)]
    with FAULTS["ratio_vs_current_policy"].injected_into():
        faulty_rows = [faulty.run_update() for _ in range(4)]
    assert all(row["clip_fraction"] == 0.0 and row["approx_kl"] == 0.0 for row in faulty_rows)
    assert min(row["approx_kl"] for row in healthy_rows) > 0.0
    assert not np.allclose(faulty.agent.params, healthy.agent.params)  # it still takes (other) steps


def test_the_flipped_value_loss_keeps_its_value_and_negates_its_gradient():
    values, targets = np.array([0.0, 1.0, 2.0]), np.array([1.0, 1.0, 0.0])
    loss, grad = minippo.losses.value_loss(values, targets)
    with FAULTS["value_loss_sign"].injected_into():
        faulty_loss, faulty_grad = minippo.losses.value_loss(values, targets)
    assert faulty_loss == loss and np.array_equal(faulty_grad, -grad)


def test_the_wrong_axis_gives_every_sample_the_mean_and_its_gradient_matches_finite_differences():
    rng = np.random.default_rng(0)
    n, k = 6, 3
    mean, log_std, actions = rng.normal(size=(n, k)), rng.normal(size=k) * 0.3, rng.normal(size=(n, k))
    weights = rng.normal(size=n)
    right = DiagGaussian(mean, log_std).log_prob(actions)
    assert (mean * 0).sum(axis=0).shape == (k,)  # the reduction over the samples has one entry per component
    with FAULTS["log_prob_wrong_axis"].injected_into():
        wrong = DiagGaussian(mean, log_std).log_prob(actions)
        grad_mean, grad_log_std = DiagGaussian(mean, log_std).log_prob_backward(actions, weights)

        def objective(mu, ls):
            return float(weights @ DiagGaussian(mu, ls).log_prob(actions))

        step, fd_mean, fd_log_std = 1e-6, np.zeros_like(mean), np.zeros_like(log_std)
        for index in np.ndindex(mean.shape):
            shift = np.zeros_like(mean)
            shift[index] = step
            fd_mean[index] = (objective(mean + shift, log_std) - objective(mean - shift, log_std)) / (2 * step)
        for i in range(k):
            shift = np.zeros_like(log_std)
            shift[i] = step
            fd_log_std[i] = (objective(mean, log_std + shift) - objective(mean, log_std - shift)) / (2 * step)
    assert wrong.shape == right.shape and np.allclose(wrong, right.mean()) and not np.allclose(wrong, right)
    np.testing.assert_allclose(grad_mean, fd_mean, rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(grad_log_std, fd_log_std, rtol=1e-6, atol=1e-8)
    assert np.array_equal(DiagGaussian(mean, log_std).log_prob(actions), right)


def small_batch():
    """Four steps of one environment: a termination at step 1, a time-limit truncation at step 3."""
    column = np.ones((4, 1))
    return Batch(
        obs=np.zeros((4, 1, 2)), actions=np.zeros((4, 1), dtype=np.int64), logp=np.zeros((4, 1)),
        policy_out=np.zeros((4, 1, 2)), policy_log_std=np.zeros(0), values=column * 5.0,
        next_values=column * 7.0, rewards=column, terminated=np.array([[False], [True], [False], [False]]),
        truncated=np.array([[False], [False], [False], [True]]),
    )  # fmt: skip


def test_the_two_bootstrapping_faults_change_only_their_own_episode_end():
    config = Config(gamma=0.9, gae_lambda=0.0)  # λ = 0: each advantage is its own step's TD residual
    healthy, _ = compute_advantages(small_batch(), config)
    with FAULTS["bootstrap_at_termination"].injected_into():
        at_termination, _ = minippo.ppo.compute_advantages(small_batch(), config)
    with FAULTS["no_bootstrap_at_truncation"].injected_into():
        at_truncation, _ = minippo.ppo.compute_advantages(small_batch(), config)
    assert healthy[1, 0] == pytest.approx(1 - 5) and at_termination[1, 0] == pytest.approx(1 + 0.9 * 7 - 5)
    assert healthy[3, 0] == pytest.approx(1 + 0.9 * 7 - 5) and at_truncation[3, 0] == pytest.approx(1 - 5)
    assert np.array_equal(np.delete(at_termination, 1), np.delete(healthy, 1))
    assert np.array_equal(np.delete(at_truncation, 3), np.delete(healthy, 3))


def test_the_stale_critic_is_the_first_rollouts_and_the_policy_stays_live():
    trainer = Trainer(TINY_CARTPOLE)
    first = trainer.agent.copy()
    with FAULTS["stale_value_targets"].injected_into():
        trainer.rollout.collect()
        trainer.agent.params += 0.05  # as an update would move both networks
        batch = trainer.rollout.collect()
    obs = batch.obs.reshape(len(batch.obs), -1)
    np.testing.assert_allclose(batch.values[:, 0], first.value(obs), rtol=1e-6)
    assert not np.allclose(batch.values[:, 0], trainer.agent.value(obs))
    np.testing.assert_allclose(batch.policy_out[:, 0], trainer.agent.policy_output(obs), rtol=1e-6)
    assert trainer.rollout.agent is trainer.agent


def test_the_plan_leaves_out_what_does_not_apply():
    runs = atlas.planned_runs(list(FAULTS), list(TASKS), atlas.SEEDS)
    assert ("healthy", "MinAtar/Breakout-v1", 1) in runs
    assert not any(mode == "log_prob_wrong_axis" and task == "CartPole-v1" for mode, task, _ in runs)
    assert not any(mode != "healthy" and task.startswith("MinAtar") for mode, task, _ in runs)
    assert len(runs) == len(set(runs))


def test_the_signature_rule_finds_the_variable_that_moved():
    rng = np.random.default_rng(0)

    def run(kl):
        n = 20
        row = {name: 1.0 + 0.01 * rng.random(n) for name in atlas_signatures.VARIABLES}
        row["approx_kl"] = kl * (1.0 + 0.1 * rng.random(n))
        row["return_mean"] = np.linspace(10.0, 100.0, n)
        return row

    runs = {("healthy", task, seed): run(0.01) for task in TASKS for seed in atlas.SEEDS}
    runs |= {("lr_10x", "Hopper-v5", seed): run(1.0) for seed in atlas.SEEDS}
    (rule,) = atlas_signatures.signature_rules(runs)
    assert rule["rule"].split()[0].startswith("kl_") and rule["rule"].split()[1] == ">"
    assert rule["seeds_holding"] == "3/3" and rule["healthy_false_alarms"] == "0/9" and rule["verdict"] == "separated"


def value_loss_nan(original):
    def value_loss(*args, **kwargs):
        _, grad = original(*args, **kwargs)
        return float("nan"), grad

    return value_loss


def test_a_fault_that_stops_the_run_at_its_first_update_is_recorded_with_no_rows(tmp_path, monkeypatch):
    fault = Fault("value_loss_nan", "losses.value_loss returns NaN", "a non-finite loss", "a finite loss",
                  patches=((minippo.losses, "value_loss", value_loss_nan),))  # fmt: skip
    monkeypatch.setitem(FAULTS, fault.name, fault)
    monkeypatch.setattr(atlas, "RUNS_CSV", tmp_path / "atlas_runs.csv")
    monkeypatch.setattr(atlas, "RUNS_JSON", tmp_path / "atlas_runs.json")
    monkeypatch.setattr(atlas, "RUN_FOLDERS", tmp_path / "runs")
    argv = ["run", "--modes", fault.name, "--tasks", "CartPole-v1", "--seeds", "1"]
    assert atlas.record_runs([fault.name], ["CartPole-v1"], [1], argv) == 0
    (run,) = json.loads((tmp_path / "atlas_runs.json").read_text())["runs"]
    assert run["updates"] == 0 and run["outcome"] == "stopped: non-finite loss or gradient at update 1", run
    header = (tmp_path / "atlas_runs.csv").read_text().splitlines()
    assert header == [",".join(["mode", "task", "seed", *PROGRESS_FIELDS])]  # the columns, and no row
    assert read_rows(tmp_path / "atlas_runs.csv") == []
