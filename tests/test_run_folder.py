"""The trainer's state and the run folder: ``Trainer.state_dict`` carries a run on bitwise, in memory and through
checkpoint.npz; a checkpoint of the previous format still resumes; a new run with --force replaces an old one only once
its settings are valid; and only ``RunFolder`` names the run's files."""

import ast
import shutil
from pathlib import Path

import numpy as np
import pytest

from minippo.checkpoint import FORMAT, load_checkpoint, save_checkpoint
from minippo.cli import main
from minippo.normalization import ObservationNormalizer, RewardScaler, RunningMeanStd
from minippo.optimizer import Adam
from minippo.ppo import Config, Trainer
from minippo.rollout import Rollout
from minippo.run_folder import RunFolder

ROOT = Path(__file__).resolve().parents[1]
# a run of 2 updates written by minippo 0.1.0 (checkpoint format 1), with the settings of OLD_RUN_OPTIONS:
#   minippo train CartPole-v1 --steps 128 --seed 5 --out RUN --quiet --horizon 64 --minibatch-size 32 --epochs 1 \
#       --no-anneal-lr --hidden-sizes 8,8 --checkpoint-every 1
OLD_RUN = ROOT / "tests" / "data" / "old_checkpoint_run"
OLD_RUN_OPTIONS = ["--seed", "5", "--horizon", "64", "--minibatch-size", "32", "--epochs", "1", "--no-anneal-lr"]
OLD_RUN_OPTIONS += ["--hidden-sizes", "8,8", "--checkpoint-every", "1"]
TIMING = ("steps_per_s", "wall_s")
SMALL = Config(env_id="CartPole-v1", total_steps=6 * 64, seed=3, horizon=64, minibatch_size=32, epochs=2)


def without_clock(row: dict) -> dict:
    return {key: value for key, value in row.items() if key not in TIMING}


def same_arrays(a: dict, b: dict) -> bool:
    """Two (nested) state dicts hold the same keys and, bit for bit, the same values."""
    if a.keys() != b.keys():
        return False
    for key in a:
        if isinstance(a[key], dict):
            if not same_arrays(a[key], b[key]):
                return False
        elif np.asarray(a[key]).tobytes() != np.asarray(b[key]).tobytes():
            return False
    return True


def files_of(folder: Path) -> dict[str, bytes]:
    return {path.name: path.read_bytes() for path in sorted(folder.iterdir())}


# the trainer's state


@pytest.mark.parametrize("through_disk", [False, True])
def test_a_trainer_given_another_s_state_dict_goes_on_as_it_would_have(tmp_path, through_disk):
    first = Trainer(SMALL)
    for _ in range(2):
        first.run_update()
    state = first.state_dict()
    if through_disk:
        save_checkpoint(tmp_path / "checkpoint.npz", state)
        state = load_checkpoint(tmp_path / "checkpoint.npz")
    second = Trainer(SMALL)  # a fresh one: other environments, an rng at the start
    assert second.load_state_dict(state) is None  # CartPole's environments are saved mid-episode
    assert same_arrays(second.state_dict(), first.state_dict())
    for _ in range(2):
        assert without_clock(second.run_update()) == without_clock(first.run_update())
    assert same_arrays(without_clock(second.state_dict()), without_clock(first.state_dict())) and second.update == 4


def test_the_state_dict_is_one_dict_of_each_part_s_own():
    trainer = Trainer(SMALL)
    trainer.run_update()
    state = trainer.state_dict()
    assert set(state) == {"update", "wall_s", "kl_beta", "rng", "params", "optimizer", "obs_normalizer",
                          "reward_scaler", "rollout"}  # fmt: skip
    assert same_arrays(state["optimizer"], trainer.optimizer.state_dict())
    assert same_arrays(state["rollout"], trainer.rollout.state_dict())
    assert set(state["reward_scaler"]) == {"mean", "var", "count", "discounted"}
    state["params"][0] += 1.0  # a copy: the trainer's weights are not the dict's
    assert trainer.agent.params[0] != state["params"][0]


def test_one_idea_has_one_spelling():
    """Every part that a checkpoint holds saves and loads itself by the same two names, as PyTorch's modules do."""
    for part in (Trainer, Adam, Rollout, ObservationNormalizer, RewardScaler, RunningMeanStd):
        assert callable(part.state_dict) and callable(part.load_state_dict), part.__name__
        assert not {"state", "load", "load_state"} & set(vars(part)), part.__name__


# checkpoint.npz


def test_a_checkpoint_is_the_state_dict_it_was_given(tmp_path):
    state = {"update": 3, "wall_s": 0.1 + 0.2, "rng": '{"state": 1}', "optimizer": {"m": np.arange(3.0), "t": 7}}
    state["rollout"] = {"env0.np_random": "{}", "raw_obs": np.ones((1, 4))}
    save_checkpoint(tmp_path / "c.npz", state)
    with np.load(tmp_path / "c.npz") as data:
        assert sorted(data.files) == ["format", "optimizer/m", "optimizer/t", "rng", "rollout/env0.np_random",
                                      "rollout/raw_obs", "update", "wall_s"]  # fmt: skip
        assert int(data["format"]) == FORMAT
    loaded = load_checkpoint(tmp_path / "c.npz")
    assert same_arrays(loaded, state) and float(loaded["wall_s"]) == 0.1 + 0.2


def test_a_checkpoint_of_the_previous_format_resumes_as_the_uninterrupted_run(tmp_path, capsys):
    """A run that minippo 0.1.0 checkpointed at update 2 (one namespace: adam_m, obs_mean, steps, env0.…) is
    extended to 4 updates; it ends as a run of 4 updates trained from the start."""
    with np.load(OLD_RUN / "checkpoint.npz") as data:
        assert "format" not in data.files and "adam_m" in data.files  # the fixture is of the old format
    old, whole = tmp_path / "old", tmp_path / "whole"
    shutil.copytree(OLD_RUN, old)
    assert main(["train", "CartPole-v1", "--out", str(old), "--resume", "--steps", "256", "--quiet"]) == 0
    assert capsys.readouterr().err == ""  # no notice: the environments went on mid-episode
    assert main(["train", "CartPole-v1", "--steps", "256", "--out", str(whole), "--quiet", *OLD_RUN_OPTIONS]) == 0
    rows = [RunFolder(folder).progress_until(4) for folder in (old, whole)]
    assert [without_clock(row) for row in rows[0]] == [without_clock(row) for row in rows[1]]
    with np.load(old / "policy.npz") as a, np.load(whole / "policy.npz") as b:
        assert sorted(a.files) == sorted(b.files)
        assert all(a[key].tobytes() == b[key].tobytes() for key in a.files)


def test_a_checkpoint_of_an_unknown_format_is_refused_in_one_line(tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(OLD_RUN, run)
    np.savez(run / "checkpoint.npz", format=np.array(FORMAT + 1), update=np.array(2))
    assert main(["train", "CartPole-v1", "--out", str(run), "--resume", "--steps", "256", "--quiet"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and f"has format {FORMAT + 1}, which this minippo (format {FORMAT})" in error


# the run folder's rules


@pytest.mark.parametrize(
    "words, fragment",
    [
        (["--horizon", "0"], "--horizon (horizon): must be a positive integer, not 0"),
        (["--config", "minibatch_size=100000"], "--minibatch-size (minibatch_size): 100000 exceeds the batch"),
        (["--preset", "atari"], "--network (network): network=minatar_cnn needs image observations"),
        (["--config", "horizn=5"], "unknown config field 'horizn'; did you mean horizon?"),
        (["--steps", "0"], "--steps (total_steps): must be between 1 and 10^10, not 0"),
    ],
)
def test_force_with_invalid_settings_leaves_the_old_run_intact(tmp_path, capsys, words, fragment):
    run = tmp_path / "run"
    shutil.copytree(OLD_RUN, run)
    before = files_of(run)
    assert main(["train", "CartPole-v1", "--steps", "512", "--out", str(run), "--quiet", "--force", *words]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and fragment in error, error
    assert files_of(run) == before


def test_force_with_an_unknown_environment_leaves_the_old_run_intact(tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(OLD_RUN, run)
    before = files_of(run)
    assert main(["train", "CartPole-v9", "--steps", "512", "--out", str(run), "--quiet", "--force"]) == 2
    assert "CartPole-v9" in capsys.readouterr().err and files_of(run) == before


def test_force_replaces_the_old_run_s_files_and_keeps_the_others(tmp_path):
    run = tmp_path / "run"
    shutil.copytree(OLD_RUN, run)
    (run / "curve.png").write_bytes(b"the old run's curve")
    (run / "notes.txt").write_text("mine")
    argv = ["train", "CartPole-v1", "--steps", "64", "--horizon", "64", "--seed", "9", "--out", str(run), "--quiet"]
    assert main(argv) == 2  # not without --force
    assert main([*argv, "--force"]) == 0
    folder = RunFolder(run)
    assert folder.read_config().seed == 9 and folder.checkpoint_update() == 1
    assert folder.curve_png.read_bytes()[:4] == b"\x89PNG" and (run / "notes.txt").read_text() == "mine"
    with np.load(folder.checkpoint_npz) as data:
        assert int(data["format"]) == FORMAT


def test_write_files_replaces_a_run_s_files_whole(tmp_path):
    folder = RunFolder(tmp_path / "run")
    folder.write_files({RunFolder.CONFIG: b"{}", RunFolder.CHECKPOINT: b"old", RunFolder.CURVE: b"old"})
    folder.write_files({RunFolder.CONFIG: b"{}\n", RunFolder.PROGRESS: b"update\n"})  # a later attempt's
    assert folder.files() == {RunFolder.CONFIG: b"{}\n", RunFolder.PROGRESS: b"update\n"}
    assert sorted(path.name for path in folder.path.iterdir()) == ["config.json", "progress.csv"]


def test_only_the_run_folder_names_the_run_s_files():
    """A file name of the run folder written as a string anywhere else in minippo is a second owner of it."""
    offenders = []
    for path in (ROOT / "minippo").rglob("*.py"):
        if path.name == "run_folder.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Constant) and node.value in RunFolder.FILES:
                offenders.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.value}")
    assert offenders == []
