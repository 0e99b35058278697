"""minippo doctor reads the logs practitioners keep: SB3's CSV and TensorBoard logs and CleanRL's TensorBoard log,
written by those libraries' own logging calls, W&B's CSV export, and a CSV file's path; a log it cannot read, or reads
only in part, gets a line that says so."""

import csv
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from minippo.cli import main
from minippo.doctor import RULES, RULES_BY_SOURCE, diagnose, read_run, report
from minippo.doctor_logs import SOURCES, read_log
from minippo.errors import MinippoError
from minippo.records import read_rows, write_rows

N_STEPS = 256  # environment steps an iteration, in the logs made here


def kl_of(update: int) -> float:  # the approx KL logged for update u: a value to find again, as exact as float32 keeps
    return 0.001 + 1e-5 * update


def sb3_log(folder: Path, iterations: int, log_interval: int = 1, formats=("csv",), episodes_from: int = 1) -> Path:
    """``folder`` with the log that SB3's PPO.learn writes through its logger, made by the same record and dump calls
    in the same order (OnPolicyAlgorithm.learn and dump_logs, PPO.train), with known values: update u's approx KL is
    kl_of(u), its entropy 0.69 − 0.001 u, its rollout's mean return 10 + u. No episode has ended before iteration
    ``episodes_from``, so rollout/ is not recorded before it (as dump_logs does on an empty episode buffer)."""
    logger_module = pytest.importorskip("stable_baselines3.common.logger", reason="needs Stable-Baselines3")
    logger = logger_module.configure(str(folder), list(formats))
    num_timesteps = 0
    for iteration in range(1, iterations + 1):
        num_timesteps += N_STEPS  # collect_rollouts
        if iteration % log_interval == 0:  # dump_logs(iteration)
            logger.record("time/iterations", iteration, exclude="tensorboard")
            if iteration >= episodes_from:
                logger.record("rollout/ep_rew_mean", 10.0 + iteration)
                logger.record("rollout/ep_len_mean", 10.0 + iteration)
            logger.record("time/fps", 1000)
            logger.record("time/time_elapsed", iteration, exclude="tensorboard")
            logger.record("time/total_timesteps", num_timesteps, exclude="tensorboard")
            logger.dump(step=num_timesteps)
        update = iteration  # train(): the update on this iteration's rollout
        logger.record("train/learning_rate", 3e-4)
        logger.record("train/entropy_loss", -(0.69 - 0.001 * update))
        logger.record("train/policy_gradient_loss", -0.01)
        logger.record("train/value_loss", 40.0 - 0.1 * update)
        logger.record("train/approx_kl", kl_of(update))
        logger.record("train/clip_fraction", 0.05)
        logger.record("train/loss", 1.0)
        logger.record("train/explained_variance", 0.5)
        logger.record("train/n_updates", 10 * update, exclude="tensorboard")
        logger.record("train/clip_range", 0.2)
    logger.close()
    return folder


def cleanrl_events(folder: Path, iterations: int, num_envs: int = 2, num_steps: int = 64, episode_every: int = 10,
                   nan_explained_variance_at=(), extra_episodes: int = 0,
                   hyperparameters: dict | None = None) -> list[tuple[int, float]]:  # fmt: skip
    """``folder`` (runs/RUN_NAME) with the events CleanRL's ppo.py writes, by its own calls in its order
    (cleanrl/ppo.py lines 185-215 and 300-309): each env ends an episode every ``episode_every`` of its steps, with
    return global_step / 100; update u's approx KL is kl_of(u). With ``hyperparameters`` (its Args as a dict), the
    table it writes first (cleanrl/ppo.py line 170). Returns the episodes as (global step, return)."""
    tensorboard = pytest.importorskip("torch.utils.tensorboard", reason="needs torch and tensorboard")
    writer = tensorboard.SummaryWriter(str(folder))
    if hyperparameters is not None:
        rows = "\n".join([f"|{key}|{value}|" for key, value in hyperparameters.items()])
        writer.add_text("hyperparameters", f"|param|value|\n|-|-|\n{rows}")
    global_step, episodes = 0, []
    for iteration in range(1, iterations + 1):
        for step in range(num_steps):
            global_step += num_envs
            for env in range(num_envs):
                if (step + 1 + 3 * env) % episode_every == 0:
                    episodes.append((global_step, global_step / 100))
                    writer.add_scalar("charts/episodic_return", global_step / 100, global_step)
                    writer.add_scalar("charts/episodic_length", episode_every, global_step)
        writer.add_scalar("charts/learning_rate", 2.5e-4, global_step)
        writer.add_scalar("losses/value_loss", 10.0 - 0.1 * iteration, global_step)
        writer.add_scalar("losses/policy_loss", -0.02, global_step)
        writer.add_scalar("losses/entropy", 0.69 - 0.001 * iteration, global_step)
        writer.add_scalar("losses/old_approx_kl", 0.5 * kl_of(iteration), global_step)
        writer.add_scalar("losses/approx_kl", kl_of(iteration), global_step)
        writer.add_scalar("losses/clipfrac", 0.05, global_step)
        explained = math.nan if iteration in nan_explained_variance_at else 0.5  # CleanRL's np.nan when var_y == 0
        writer.add_scalar("losses/explained_variance", explained, global_step)
        writer.add_scalar("charts/SPS", 1000, global_step)
    for _ in range(extra_episodes):  # a run stopped in the rollout after its last update
        global_step += num_envs
        writer.add_scalar("charts/episodic_return", 99.0, global_step)
    writer.close()
    return episodes


# Stable-Baselines3


def test_an_sb3_log_written_every_5th_iteration_is_read_whole(tmp_path, capsys):
    run = sb3_log(tmp_path / "sb3", iterations=160, log_interval=5)  # 32 dumps, at iterations 5, 10, ..., 160
    log = read_log(run)
    assert log.source == "sb3" and len(log.rows) == 32  # the first dump carries update 4's train/ values too
    assert [row["update"] for row in log.rows] == list(range(4, 160, 5))
    for row in log.rows:
        update = row["update"]
        assert row["step"] == N_STEPS * update  # the steps of the update's own rollout
        assert row["approx_kl"] == pytest.approx(kl_of(update))
        assert row["entropy"] == pytest.approx(0.69 - 0.001 * update)
        assert row["return_mean"] == 10 + update + 1  # of the rollout after it, said in the notes
    assert any("every 5 iterations (log_interval=5)" in note and "32 of updates 1-159" in note for note in log.notes)
    assert main(["doctor", str(run)]) == 0
    out = capsys.readouterr().out
    assert "32 updates" in out and "log_interval=5" in out and "nan" not in out


def test_an_sb3_log_with_no_episode_ended_yet_says_where_the_return_is_missing(tmp_path):
    log = read_log(sb3_log(tmp_path / "sb3", iterations=21, episodes_from=4))
    assert len(log.rows) == 20 and [row["update"] for row in log.rows] == list(range(1, 21))
    returns = [row["return_mean"] for row in log.rows]
    assert all(math.isnan(r) for r in returns[:3]) and returns[3:] == [10.0 + u for u in range(4, 21)]
    assert "return_mean (rollout/ep_rew_mean) has no value on 3 of the 20 updates" in log.notes
    assert diagnose(log.rows, RULES_BY_SOURCE[log.source]) == []  # with its own source's thresholds


def test_sb3s_tensorboard_log_reads_as_its_csv_log(tmp_path):
    pytest.importorskip("tensorboard", reason="needs the tensorboard package (pip install 'minippo[doctor]')")
    run = sb3_log(tmp_path / "sb3", iterations=16, formats=("csv", "tensorboard"))
    events = sorted(run.glob("events.out.tfevents.*"))
    assert len(events) == 1
    from_csv, from_events = read_log(run / "progress.csv"), read_log(events[0])
    assert (from_csv.file, from_events.file) == ("progress.csv", "TensorBoard events")
    assert len(from_events.rows) == len(from_csv.rows) == 15
    for a, b in zip(from_csv.rows, from_events.rows):
        assert a["update"] == b["update"] and a["step"] == b["step"]
        for name in SOURCES["sb3"]:
            assert b[name] == pytest.approx(a[name], rel=1e-6), name  # TensorBoard keeps float32
    assert [row["approx_kl"] for row in from_events.rows] == pytest.approx([kl_of(u) for u in range(1, 16)])
    assert any("log_interval=1" in note for note in from_events.notes)  # no iteration count in TensorBoard: said


def test_sb3s_tensorboard_log_written_every_5th_iteration_is_read_by_record(tmp_path):
    pytest.importorskip("tensorboard", reason="needs the tensorboard package (pip install 'minippo[doctor]')")
    run = sb3_log(tmp_path / "sb3", iterations=60, log_interval=5, formats=("tensorboard",))
    log = read_log(run)  # TensorBoard holds no iteration count: the updates are numbered by record, and said
    assert len(log.rows) == 12 and [row["update"] for row in log.rows] == list(range(1, 13))
    assert [row["step"] for row in log.rows] == [N_STEPS * 5 * record for record in range(1, 13)]
    assert [row["approx_kl"] for row in log.rows] == pytest.approx([kl_of(5 * record - 1) for record in range(1, 13)])
    assert any("log_interval > 1" in note for note in log.notes)


def test_a_real_sb3_ppo_run_logged_to_tensorboard_is_read(tmp_path, capsys):
    pytest.importorskip("tensorboard", reason="needs the tensorboard package (pip install 'minippo[doctor]')")
    sb3 = pytest.importorskip("stable_baselines3", reason="needs Stable-Baselines3")
    import torch

    torch.set_num_threads(1)
    model = sb3.PPO("MlpPolicy", "CartPole-v1", n_steps=32, batch_size=16, n_epochs=2, seed=0, device="cpu",
                    tensorboard_log=str(tmp_path / "tb"))  # fmt: skip
    model.learn(total_timesteps=32 * 12)  # 12 iterations: 11 updates logged, in tb/PPO_1
    kind, rows = read_run(tmp_path / "tb")  # the folder of the runs: the one run in it is read
    assert kind == "sb3" and [row["update"] for row in rows] == list(range(1, 12))
    assert [row["step"] for row in rows] == [32 * u for u in range(1, 12)]
    kls = [row["approx_kl"] for row in rows]  # SB3's: measured before each minibatch's step, so 0 on the first
    assert min(kls) > -1e-6 and 0.0 < max(kls) < 0.1
    assert all(0.6 < row["entropy"] <= math.log(2) + 1e-6 and row["return_mean"] > 8 for row in rows)
    assert main(["doctor", str(tmp_path / "tb"), "--json"]) in (0, 1)
    assert json.loads(capsys.readouterr().out)["updates"] == 11


# CleanRL


def test_cleanrls_tensorboard_log_is_read_update_by_update(tmp_path, capsys):
    pytest.importorskip("tensorboard", reason="needs the tensorboard package (pip install 'minippo[doctor]')")
    run = tmp_path / "runs" / "CartPole-v1__ppo__1__1700000000"
    episodes = cleanrl_events(run, iterations=20, nan_explained_variance_at=(7,), extra_episodes=3)
    log = read_log(tmp_path / "runs")
    assert (log.source, log.file, len(log.rows)) == ("cleanrl", "TensorBoard events", 20)
    batch = 2 * 64
    for row in log.rows:
        update = row["update"]
        ended = [r for step, r in episodes if batch * (update - 1) < step <= batch * update]
        assert row["step"] == batch * update
        assert row["return_mean"] == pytest.approx(np.mean(ended), rel=1e-6)  # the episodes of its own rollout
        assert row["approx_kl"] == pytest.approx(kl_of(update))
        assert row["entropy"] == pytest.approx(0.69 - 0.001 * update)  # CleanRL logs the entropy, not its negative
        assert row["policy_objective"] == pytest.approx(0.02)  # −losses/policy_loss
        assert row["value_loss"] == pytest.approx(10.0 - 0.1 * update)  # already ½(V − V^targ)²
    assert math.isnan(log.rows[6]["explained_variance"])
    assert "explained_variance (losses/explained_variance) has no value on 1 of the 20 updates" in log.notes
    assert "3 episodes ended after the last update's step (its update was not logged): not counted" in log.notes
    assert main(["doctor", str(run)]) == 0
    out = capsys.readouterr().out
    assert "CleanRL TensorBoard events, 20 updates" in out and "nan" not in out


def test_a_wandb_csv_export_reads_as_the_events_it_copies(tmp_path):
    pytest.importorskip("tensorboard", reason="needs the tensorboard package (pip install 'minippo[doctor]')")
    run = tmp_path / "runs" / "run"
    cleanrl_events(run, iterations=12)
    from_events = read_log(run)
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    accumulator = EventAccumulator(str(run), size_guidance={"scalars": 0})
    accumulator.Reload()
    tags = accumulator.Tags()["scalars"]
    history = {}  # W&B's history of a synced run: a row a logged step, each tag a column, blank where not logged
    for tag in tags:
        for event in accumulator.Scalars(tag):
            history.setdefault(event.step, {})[tag] = repr(event.value)
    export = tmp_path / "wandb_export.csv"
    with open(export, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=["_step", "global_step", "_runtime", *tags], restval="")
        writer.writeheader()
        for row_number, (step, values) in enumerate(sorted(history.items())):
            writer.writerow({"_step": row_number, "global_step": step, "_runtime": row_number / 10, **values})
    from_export = read_log(export)
    assert (from_export.source, from_export.file) == ("cleanrl", "W&B CSV export")
    assert len(from_export.rows) == len(from_events.rows) == 12
    for a, b in zip(from_events.rows, from_export.rows):
        assert a.keys() == b.keys()
        assert all(a[key] == pytest.approx(b[key], nan_ok=True) for key in a)


def test_a_wandb_csv_export_of_an_sb3_run_is_read(tmp_path):
    export = tmp_path / "sb3.csv"  # an SB3 run synced from TensorBoard: no time/iterations, global_step the step
    tags = ["rollout/ep_rew_mean", "time/fps", *(tag for tag, _, when in SOURCES["sb3"].values() if when == "update")]
    with open(export, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["_step", "global_step", *tags])
        for iteration in range(1, 13):
            train = [kl_of(iteration - 1) if tag == "train/approx_kl" else 1.0 for tag in tags[2:]]
            train = train if iteration > 1 else [""] * len(train)  # the first record: no update yet
            writer.writerow([iteration - 1, N_STEPS * iteration, 10 + iteration, 500, *train])
    log = read_log(export)
    assert (log.source, log.file, len(log.rows)) == ("sb3", "W&B CSV export", 11)
    assert [row["approx_kl"] for row in log.rows] == pytest.approx([kl_of(u) for u in range(1, 12)])
    assert [row["return_mean"] for row in log.rows] == [10 + u for u in range(1, 12)]


# the paths and the errors


def test_a_csv_files_path_reads_as_its_folder(tmp_path, capsys):
    run = sb3_log(tmp_path / "sb3", iterations=12)
    assert read_run(run / "progress.csv") == read_run(run)
    assert main(["doctor", str(run / "progress.csv")]) == 0
    assert "11 updates" in capsys.readouterr().out


def test_json_errors_are_json_on_stdout_with_the_same_exit_status(tmp_path, capsys):
    for argv in (["doctor", str(tmp_path / "nothing"), "--json"], ["doctor", "--json"]):
        assert main(argv) == 2
        captured = capsys.readouterr()
        error = json.loads(captured.out)["error"]
        assert error and captured.err.strip() == f"minippo: error: {error}"


def test_a_folder_with_no_known_log_names_what_it_found_and_what_is_read(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("lr 3e-4\n")
    (tmp_path / "model.zip").write_bytes(b"PK")
    assert main(["doctor", str(tmp_path)]) == 2
    line = capsys.readouterr().err.strip()
    assert "\n" not in line and "found: model.zip, notes.txt" in line
    assert all(word in line for word in ("progress.csv", "W&B", "TensorBoard", "CleanRL", "Stable-Baselines3"))


def test_event_files_with_other_tags_or_of_several_runs_are_refused_in_one_line(tmp_path, capsys):
    tensorboard = pytest.importorskip("torch.utils.tensorboard", reason="needs torch and tensorboard")
    writer = tensorboard.SummaryWriter(str(tmp_path / "other"))
    writer.add_scalar("loss/train", 0.5, 1)
    writer.close()
    assert main(["doctor", str(tmp_path / "other")]) == 2
    assert "found: loss/train" in capsys.readouterr().err
    cleanrl_events(tmp_path / "runs" / "a", iterations=2)
    cleanrl_events(tmp_path / "runs" / "b", iterations=2)
    assert main(["doctor", str(tmp_path / "runs")]) == 2
    assert "the TensorBoard event files of 2 runs (a, b): name one" in capsys.readouterr().err


def test_event_files_without_tensorboard_say_what_to_install(tmp_path, monkeypatch):
    tensorboard = pytest.importorskip("torch.utils.tensorboard", reason="needs torch and tensorboard")
    writer = tensorboard.SummaryWriter(str(tmp_path))
    writer.add_scalar("losses/approx_kl", 0.01, 128)
    writer.close()
    monkeypatch.setitem(sys.modules, "tensorboard.backend.event_processing.event_accumulator", None)
    with pytest.raises(MinippoError, match=r"needs the tensorboard package: pip install 'minippo\[doctor\]'"):
        read_log(tmp_path)


def test_every_rule_reads_a_field_that_every_source_maps():
    for source, table in SOURCES.items():
        assert {rule.variable for rule in RULES} <= set(table), source
        assert all(factor in (1.0, -1.0, 0.5) and when in ("update", "rollout", "episode")
                   for _, factor, when in table.values()), source  # fmt: skip


def test_the_report_of_a_partial_log_is_strict_json(tmp_path):
    run = sb3_log(tmp_path / "sb3", iterations=21, episodes_from=4)
    text, status = report(run, as_json=True)
    parsed = json.loads(text, parse_constant=lambda name: pytest.fail(f"{name} in the JSON"))
    assert status == 0 and parsed["updates"] == 20 and parsed["notes"]


# the run's settings, where the log carries them

CLEANRL_ARGS = {"exp_name": "ppo", "seed": 1, "env_id": "CartPole-v1", "total_timesteps": 500000,
                "learning_rate": 0.00025, "num_envs": 4, "num_steps": 128, "anneal_lr": True, "gamma": 0.99,
                "gae_lambda": 0.95, "num_minibatches": 4, "update_epochs": 4, "norm_adv": True, "clip_coef": 0.2,
                "clip_vloss": True, "ent_coef": 0.01, "vf_coef": 0.5, "max_grad_norm": 0.5,
                "target_kl": None}  # fmt: skip


def rl_zoo_config(folder: Path, hyperparameters: dict) -> None:
    """config.yml as rl-zoo's ExperimentManager saves it: yaml.dump of an OrderedDict of the sorted hyperparameters."""
    yaml = pytest.importorskip("yaml", reason="needs PyYAML (pip install 'minippo[doctor]')")
    from collections import OrderedDict

    with open(folder / "config.yml", "w") as handle:
        yaml.dump(OrderedDict(sorted(hyperparameters.items())), handle)


def test_cleanrls_hyperparameters_table_is_read_and_a_negative_entropy_coefficient_is_named_first(tmp_path, capsys):
    pytest.importorskip("tensorboard", reason="needs the tensorboard package (pip install 'minippo[doctor]')")
    run = tmp_path / "runs" / "CartPole-v1__ppo__1__1700000000"
    cleanrl_events(run, iterations=20, hyperparameters=CLEANRL_ARGS | {"ent_coef": -0.05})
    log = read_log(run)
    assert log.settings == {"clip_epsilon": 0.2, "value_coef": 0.5, "entropy_coef": -0.05, "lr": 0.00025,
                            "epochs": 4.0}  # fmt: skip
    assert main(["doctor", str(run)]) == 1
    out = capsys.readouterr().out
    assert "1. setting entropy_coef = -0.05 (< 0 by definition" in out and "[entropy-bonus-negative]" in out
    assert "#atlas-entropy" in out
    text, status = report(run, as_json=True)
    first = json.loads(text)["findings"][0]
    assert (status, first["kind"], first["id"], first["value"]) == (1, "setting", "entropy-bonus-negative", -0.05)


def test_a_healthy_cleanrl_run_is_checked_against_its_settings_and_passes(tmp_path, capsys):
    pytest.importorskip("tensorboard", reason="needs the tensorboard package (pip install 'minippo[doctor]')")
    run = tmp_path / "run"
    cleanrl_events(run, iterations=20, hyperparameters=CLEANRL_ARGS)
    assert main(["doctor", str(run)]) == 0
    out = capsys.readouterr().out
    assert "settings (" in out and "entropy_coef = 0.01 (bound: < 0)" in out and "clip_epsilon = 0.2" in out


def test_rl_zoos_config_yml_beside_an_sb3_log_is_read_with_sb3s_defaults_for_what_it_leaves_out(tmp_path, capsys):
    run = sb3_log(tmp_path / "sb3", iterations=20)
    rl_zoo_config(run, {"learning_rate": "lin_0.001", "n_envs": 8, "n_epochs": 20, "ent_coef": -0.01,
                        "policy": "MlpPolicy"})  # fmt: skip
    log = read_log(run)  # clip_range and vf_coef are SB3's defaults, 0.2 and 0.5
    assert log.settings == {"clip_epsilon": 0.2, "value_coef": 0.5, "entropy_coef": -0.01, "lr": 0.001, "epochs": 20.0}
    assert log.settings_file == str(run / "config.yml")
    assert main(["doctor", str(run / "progress.csv")]) == 1  # the CSV file's path finds the config beside it too
    assert "1. setting entropy_coef = -0.01 (< 0 by definition" in capsys.readouterr().out
    rl_zoo_config(run, {"clip_range": "lin_0.2", "vf_coef": 0.0, "policy": "MlpPolicy"})
    assert read_log(run).settings == {"clip_epsilon": 0.2, "value_coef": 0.0, "entropy_coef": 0.0, "lr": 3e-4,
                                      "epochs": 10.0}  # fmt: skip


def test_a_config_yml_above_sb3s_tensorboard_folder_is_found_up_to_the_path_given(tmp_path):
    """PPO(..., tensorboard_log=folder) writes folder/PPO_1/events.out.tfevents.*: a config.yml in folder is found when
    the doctor is given folder, and not when it is given folder/PPO_1 (it never reads above the path given)."""
    pytest.importorskip("tensorboard", reason="needs the tensorboard package (pip install 'minippo[doctor]')")
    folder = tmp_path / "tb"
    sb3_log(folder / "PPO_1", iterations=20, formats=("tensorboard",))
    rl_zoo_config(folder, {"vf_coef": 0.0, "policy": "MlpPolicy"})
    log = read_log(folder)
    assert (log.file, log.settings["value_coef"], log.settings_file) == ("TensorBoard events", 0.0,
                                                                         str(folder / "config.yml"))  # fmt: skip
    below = read_log(folder / "PPO_1")
    assert below.settings == {} and any("give them with --settings FILE" in note for note in below.notes)
    assert read_log(folder / "PPO_1", settings=folder / "config.yml").settings["value_coef"] == 0.0


def test_settings_named_with_the_settings_option_are_checked(tmp_path, capsys):
    run = sb3_log(tmp_path / "sb3", iterations=20)
    elsewhere = tmp_path / "logs" / "ppo" / "CartPole-v1_1" / "CartPole-v1"  # where rl-zoo saves its config.yml
    elsewhere.mkdir(parents=True)
    rl_zoo_config(elsewhere, {"clip_range": 10.0, "policy": "MlpPolicy"})
    assert main(["doctor", str(run), "--settings", str(elsewhere / "config.yml")]) == 1
    assert "[clip-cannot-bind]" in capsys.readouterr().out
    (tmp_path / "args.json").write_text(json.dumps({"clip_range": 0.2, "ent_coef": 0.0}))
    assert main(["doctor", str(run), "--settings", str(tmp_path / "args.json")]) == 0
    assert main(["doctor", str(run), "--settings", str(tmp_path / "missing.yml")]) == 2
    assert "--settings: no file" in capsys.readouterr().err


def test_a_clip_range_of_1_or_more_is_out_of_bounds_and_a_minippo_config_is_read(tmp_path, capsys):
    from minippo.config import Config

    run = sb3_log(tmp_path / "sb3", iterations=20)
    table = read_rows(run / "progress.csv")
    rows = [{"update": i + 1, "step": 256 * (i + 1), "return_mean": 10 + i, "approx_kl": kl_of(i + 1),
             "clip_fraction": 0.05, "entropy": 0.69 - 0.001 * i, "explained_variance": 0.5,
             "value_loss": 20.0 - 0.1 * i} for i in range(len(table))]  # fmt: skip
    minippo_run = tmp_path / "minippo"
    minippo_run.mkdir()
    write_rows(minippo_run / "progress.csv", list(rows[0]), rows)
    (minippo_run / "config.json").write_text(json.dumps(Config(env_id="CartPole-v1", clip_epsilon=1.0).to_dict()))
    assert read_log(minippo_run).settings["clip_epsilon"] == 1.0
    assert main(["doctor", str(minippo_run)]) == 1
    assert "1. setting clip_epsilon = 1 (>= 1 by definition" in capsys.readouterr().out
    (minippo_run / "config.json").write_text(json.dumps(Config(env_id="CartPole-v1", clip_epsilon=0.99).to_dict()))
    assert "[clip-cannot-bind]" not in report(minippo_run)[0]


def test_a_log_without_settings_says_so_and_settings_it_cannot_use_are_notes(tmp_path, capsys):
    run = sb3_log(tmp_path / "sb3", iterations=20)
    log = read_log(run)
    assert log.settings == {} and log.settings_file is None
    assert any("the run's settings are not in the log" in note and "config.yml" in note for note in log.notes)
    assert main(["doctor", str(run)]) == 0  # the status is the rules': a log without settings is not a finding
    capsys.readouterr()
    pytest.importorskip("yaml", reason="needs PyYAML (pip install 'minippo[doctor]')")
    for text, says in [("clip_range: [unclosed\n", "cannot be read as YAML"),
                       ("- 1\n- 2\n", "holds no table of hyperparameters"),
                       ("foo: bar\n", "holds none of the settings the doctor checks")]:  # fmt: skip
        (run / "config.yml").write_text(text)
        log = read_log(run)
        assert log.settings == {} and any(says in note for note in log.notes), text
        assert main(["doctor", str(run), "--json"]) == 0
        assert json.loads(capsys.readouterr().out)["settings"] == {}
    (run / "config.yml").write_text("vf_coef: .nan\nent_coef: false\nclip_range: 0.2\nn_epochs: 10\n")
    log = read_log(run)  # not numbers: said, and not checked (SB3's defaults stand in for neither)
    assert log.settings == {"clip_epsilon": 0.2, "lr": 3e-4, "epochs": 10.0}
    assert sum("is not a number: not checked" in note for note in log.notes) == 2
    assert main(["doctor", str(run), "--json"]) == 0  # strict JSON: no NaN
    assert json.loads(capsys.readouterr().out)["settings"] == log.settings


def test_a_minippo_config_that_is_not_a_table_or_has_no_numbers_is_a_note(tmp_path, capsys):
    rows = [{"update": u, "step": 256 * u, "return_mean": 10 + u, "approx_kl": kl_of(u), "clip_fraction": 0.05,
             "entropy": 0.69 - 0.001 * u, "explained_variance": 0.5, "value_loss": 20.0} for u in range(1, 21)]
    run = tmp_path / "minippo"
    run.mkdir()
    write_rows(run / "progress.csv", list(rows[0]), rows)
    for text, says in [("[1, 2]", "holds no table of settings"), ("null", "holds no table of settings"),
                       ("{not json", "cannot be read as JSON"),
                       ('{"lr": 1' + "0" * 400 + ', "value_coef": 0.5}', "lr = ")]:  # fmt: skip
        (run / "config.json").write_text(text)
        log = read_log(run)
        assert any(says in note for note in log.notes), (text[:20], log.notes)
        assert main(["doctor", str(run), "--json"]) == 0, text[:20]
        capsys.readouterr()
