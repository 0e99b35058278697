"""The doctor's campaign (benchmarks/doctor_runs.py): its split is fixed by the runs' ids and balanced, each fault
changes the setting it names and nothing else; and (slow) a tiny run of each library writes what that library writes."""

import dataclasses
import hashlib
import importlib.util
import json
import random

import pytest

from benchmarks import doctor_libraries, doctor_runs
from benchmarks.doctor_libraries import FAULTS, FIELDS
from benchmarks.doctor_runs import PARTS
from minippo.doctor import MIN_UPDATES
from minippo.records import read_rows

LIBRARIES = ("minippo", "sb3", "cleanrl")
needs_sb3 = pytest.mark.skipif(importlib.util.find_spec("stable_baselines3") is None, reason="no stable-baselines3")
needs_tensorboard = pytest.mark.skipif(importlib.util.find_spec("tensorboard") is None, reason="no tensorboard")


def settings_of(entry) -> dict:
    maker = {"minippo": lambda e: doctor_libraries.minippo_config(e).to_dict(), "sb3": doctor_libraries.sb3_settings,
             "cleanrl": doctor_libraries.cleanrl_settings}  # fmt: skip
    return maker[entry.library](entry)


def digest(entry) -> bytes:
    return hashlib.sha256(entry.id.encode()).digest()


def test_the_split_is_fixed_by_the_ids_alone():
    entries = doctor_runs.manifest()
    parts = {entry.id: entry.part for entry in entries}
    assert len(parts) == len(entries) and set(parts.values()) == set(PARTS)
    assert {entry.id: entry.part for entry in doctor_runs.manifest()} == parts  # planned again
    shuffled = random.Random(0).sample(entries, len(entries))
    assert doctor_runs.split(shuffled) == parts  # the order of the manifest plays no part
    for stratum in {entry.stratum for entry in entries}:  # each alternates in the order of its ids' SHA-256
        ranked = sorted((e for e in entries if e.stratum == stratum), key=digest)
        assert [e.part for e in ranked] == list(PARTS) * (len(ranked) // 2)


def test_both_parts_hold_healthy_runs_and_every_fault_of_every_library():
    entries = doctor_runs.manifest()
    for part in PARTS:
        mine = [entry for entry in entries if entry.part == part]
        assert sum(e.fault == "healthy" for e in mine) >= 40 and sum(e.fault != "healthy" for e in mine) >= 20
        for library in LIBRARIES:
            assert {e.fault for e in mine if e.library == library} == {"healthy", *FAULTS}, (part, library)


@pytest.mark.parametrize("library", LIBRARIES)
def test_every_run_is_long_enough_for_the_doctor_to_judge(library):
    if library == "sb3" and importlib.util.find_spec("stable_baselines3") is None:
        pytest.skip("no stable-baselines3 (its batch size comes from SB3's own defaults)")
    entries = [entry for entry in doctor_runs.manifest() if entry.library == library]
    assert entries and all(doctor_libraries.updates_of(entry) >= MIN_UPDATES for entry in entries)


@needs_sb3
@pytest.mark.parametrize("library", LIBRARIES)
@pytest.mark.parametrize("fault", [fault for fault in FAULTS if fault != "reward_zero"])
def test_a_fault_changes_the_setting_it_names_and_no_other(library, fault):
    broken = next(e for e in doctor_runs.manifest() if (e.library, e.fault, e.task) == (library, fault, "Pendulum-v1"))
    before, after = settings_of(dataclasses.replace(broken, fault="healthy")), settings_of(broken)
    name = FIELDS[library][FAULTS[fault][0]]
    expected = {"lr_x10": 10 * before[name], "lr_x30": 30 * before[name], "epochs_50": 50, "clip_10": 10.0,
                "ent_-0.01": -0.01, "ent_-0.05": -0.05, "vf_0": 0.0}[fault]  # fmt: skip
    assert after[name] == pytest.approx(expected) and after[name] != before[name]
    assert {k: v for k, v in after.items() if k != name} == {k: v for k, v in before.items() if k != name}


@needs_sb3
def test_the_step_size_is_ten_times_each_librarys_default():
    lr = {e.library: settings_of(e)[FIELDS[e.library]["lr"]] for e in doctor_runs.manifest()
          if e.fault == "lr_x10" and e.task == "CartPole-v1"}  # fmt: skip
    # minippo's Config and SB3's PPO default to 3e-4, CleanRL's ppo.py to 2.5e-4
    assert lr == pytest.approx({"minippo": 3e-3, "sb3": 3e-3, "cleanrl": 2.5e-3})


def test_the_zero_reward_is_zero_through_each_librarys_wrappers():
    from benchmarks import cleanrl_ppo

    for env in (doctor_libraries.make_task("CartPole-v1", True),
                cleanrl_ppo.wrapped(lambda: doctor_libraries.make_task("Pendulum-v1", True), True, 0.99)):  # fmt: skip
        env.reset(seed=0)
        rewards = []
        for _ in range(20):
            _, reward, terminated, truncated, _ = env.step(env.action_space.sample())
            rewards.append(reward)
            if terminated or truncated:
                env.reset()
        assert rewards == [0.0] * 20
        env.close()


def test_a_recorded_run_is_not_made_again(tmp_path, monkeypatch, capsys):
    entry = doctor_runs.manifest()[0]
    record = tmp_path / "doctor_runs.json"
    record.write_text(json.dumps({"commands": [], "runs": [{"id": entry.id, "outcome": "ok"}]}))
    monkeypatch.setattr(doctor_runs, "RECORD_JSON", record)
    assert doctor_runs.main(["run", "--only", entry.id]) == 0
    assert "0 runs to make, 1 of those chosen already recorded" in capsys.readouterr().out
    assert json.loads(record.read_text())["commands"] == []


def tiny_run(entry_id: str, folder) -> dict:
    entry = doctor_runs.by_id(entry_id)
    tiny = dataclasses.replace(entry, tiny=max(doctor_libraries.batch_of(entry), 4096))
    return doctor_libraries.make_run(tiny, folder)


@pytest.mark.slow
def test_a_tiny_minippo_run_with_a_zero_reward(tmp_path):
    result = tiny_run("minippo-defaults-CartPole-v1-reward_zero-1x-seed1", tmp_path / "run")
    assert (result["outcome"], result["steps"], result["updates"]) == ("ok", 4096, 2)
    rows = read_rows(tmp_path / "run" / "progress.csv")
    assert [float(row["return_mean"]) for row in rows] == [0.0, 0.0]  # episodes end, and pay nothing
    assert json.loads((tmp_path / "run" / "config.json").read_text())["env_id"] == "CartPole-v1"


@pytest.mark.slow
@needs_sb3
@needs_tensorboard
def test_a_tiny_sb3_run_at_rl_zoos_settings(tmp_path):
    import yaml

    result = tiny_run("sb3-zoo-Pendulum-v1-healthy-1x-seed1", tmp_path / "run")
    assert (result["outcome"], result["steps"], result["updates"]) == ("ok", 4096, 1)
    with open(tmp_path / "run" / "config.yml") as handle:
        saved = dict(yaml.load(handle, Loader=yaml.UnsafeLoader))  # as rl-zoo reads its own
    assert saved["use_sde"] is True and saved["n_envs"] == 4 and saved["learning_rate"] == 1e-3
    assert read_rows(tmp_path / "run" / "progress.csv")[-1]["time/total_timesteps"] == "4096"
    assert list((tmp_path / "run").glob("events.out.tfevents.*"))


@pytest.mark.slow
@needs_tensorboard
def test_a_tiny_cleanrl_run_logs_cleanrls_scalars(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    result = tiny_run("cleanrl-ppo-CartPole-v1-healthy-1x-seed1", tmp_path / "run")
    assert (result["outcome"], result["steps"], result["updates"]) == ("ok", 4096, 8)
    events = EventAccumulator(str(tmp_path / "run"))
    events.Reload()
    tags = {"charts/episodic_return", "charts/episodic_length", "charts/learning_rate", "charts/SPS"}
    tags |= {f"losses/{name}" for name in ("value_loss", "policy_loss", "entropy", "old_approx_kl", "approx_kl")}
    assert set(events.Tags()["scalars"]) == tags | {"losses/clipfrac", "losses/explained_variance"}
    assert [event.step for event in events.Scalars("losses/approx_kl")] == list(range(512, 4097, 512))
    rates = [event.value for event in events.Scalars("charts/learning_rate")]
    assert rates[:2] == pytest.approx([2.5e-4, 2.5e-4 * 7 / 8])  # annealed over the 8 iterations


def test_the_replication_is_the_held_out_faults_again_at_a_seed_none_of_them_had():
    replicated = doctor_runs.replication()
    held_out = [e for e in doctor_runs.manifest() if e.part == "held-out" and e.fault != "healthy"]
    assert [(e.library, e.settings, e.task, e.fault, e.length) for e in replicated] == [
        (e.library, e.settings, e.task, e.fault, e.length) for e in held_out]  # fmt: skip
    assert {e.seed for e in held_out} == {1} and {e.seed for e in replicated} == {doctor_runs.REPLICATION_SEED} != {1}
    assert not {e.id for e in replicated} & {e.id for e in doctor_runs.manifest()}
    assert {e.part for e in replicated} == {doctor_runs.REPLICATION}


def test_the_replication_keeps_its_own_record(capsys):
    mixed = [doctor_runs.replication()[0].id, doctor_runs.manifest()[0].id]
    with pytest.raises(SystemExit) as stopped:
        doctor_runs.main(["run", "--only", *mixed])
    assert stopped.value.code == 2 and "record of their own" in capsys.readouterr().err
