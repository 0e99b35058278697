"""minippo beside Stable-Baselines3 (benchmarks/peers.py): the scored table on hand-computed numbers, the record's
rows, SB3's settings as translated from minippo's Config, and one real tiny run of each library through the
sweep engine (skipped when Stable-Baselines3 or Ray is not installed)."""

import importlib.util
import math

import pytest

from benchmarks import common, peers, report, scoring
from minippo.optimizer import linear_schedule
from minippo.ppo import Config
from minippo.records import append_row, read_rows

# the statistics


def test_welch_interval_by_hand():
    # Equal sizes and variances, where Welch's df is a whole number. a = 10, 12, 14: mean 12, s² = 4;
    # b = 4, 6, 8: mean 6, s² = 4. se² = 4/3 + 4/3 = 8/3, se = 1.6329932. df = (8/3)² / (2 · (4/3)²/2) = 4.
    # t(0.975, 4) = 2.7764451 (from the table), half-width 2.7764451 · 1.6329932 = 4.5339159: 6 ± 4.5339159.
    interval = scoring.welch_interval([10, 12, 14], [4, 6, 8])
    assert interval["diff"] == 6
    assert (interval["low"], interval["high"]) == pytest.approx((1.4660841, 10.5339159), abs=1e-7)
    assert interval["standing"] == "ahead"

    # Unequal sizes, a fractional df. a = 3, 4, 5: mean 4, s² = 1, s²/n = 1/3; b = 1, 2: mean 1.5, s² = 1/2,
    # s²/n = 1/4. se² = 7/12, se = 0.7637626. df = (7/12)² / ((1/3)²/2 + (1/4)²/1) = (49/144) / (17/144) = 49/17
    # = 2.8823529. t(0.975, 49/17) = 3.2572081 (scipy.stats.t.ppf(0.975, 49/17), computed once); half-width
    # 3.2572081 · 0.7637626 = 2.4877338: 2.5 ± 2.4877338 = [0.0122662, 4.9877338], which just excludes 0
    # (scipy.stats.ttest_ind(a, b, equal_var=False).confidence_interval() gives the same).
    interval = scoring.welch_interval([3, 4, 5], [1, 2])
    assert (interval["low"], interval["high"]) == pytest.approx((0.0122662, 4.9877338), abs=1e-7)
    assert interval["standing"] == "ahead"
    swapped = scoring.welch_interval([1, 2], [3, 4, 5])
    assert (swapped["low"], swapped["high"]) == pytest.approx((-4.9877338, -0.0122662), abs=1e-7)
    assert swapped["standing"] == "behind"
    assert scoring.welch_interval([1, 2, 3], [2, 3, 4])["standing"] == "level"
    with pytest.raises(ValueError):
        scoring.welch_interval([1.0], [1.0, 2.0])


def peer_record(library, task, seed, train, evaluation, wall_s=600.0, steps=999_424):
    return {
        "library": library,
        "version": f"{library} 1",
        "task": task,
        "seed": str(seed),
        "steps": str(steps),
        "return_mean": str(train),
        "eval_mean": str(evaluation),
        "wall_s": str(wall_s),
        "commit": "abc1234",
        "command": "python benchmarks/peers.py",
    }


def test_the_peers_table(tmp_path):
    rows = [
        *(peer_record("minippo", "Hopper-v5", seed, v, 2 * v, 120) for seed, v in zip((1, 2, 3), (3000, 4000, 5000))),
        *(peer_record("sb3", "Hopper-v5", seed, v, 2 * v, 600) for seed, v in zip((1, 2), (1000, 2000))),
        peer_record("minippo", "Walker2d-v5", 1, 3000, 3100),  # one seed each: not compared
        peer_record("sb3", "Walker2d-v5", 1, 2000, 2100),
    ]
    train, evaluation = scoring.peers(rows)
    assert (train["task"], train["score"], evaluation["score"]) == ("Hopper-v5", "train", "eval")
    assert train["minippo_mean"] == 4000 and train["minippo_se"] == pytest.approx(round(1000 / math.sqrt(3), 1))
    assert (train["sb3_mean"], train["sb3_se"], train["seeds"]) == (1500, 500, "3/2")
    assert (train["sb3_minutes"], train["minippo_minutes"]) == (10.0, 2.0)
    # the hand-computed interval above, ×1000 (train) and ×2000 (eval)
    assert (train["diff"], train["low"], train["high"]) == (2500.0, 12.3, 4987.7)
    assert evaluation["low"] == pytest.approx(24.5) and train["standing"] == evaluation["standing"] == "ahead"


def test_the_curves_figure_draws_each_librarys_seeds(tmp_path):
    runs = tmp_path / "runs"
    drawn = []
    for library, level in (("minippo", 100.0), ("sb3", 50.0)):
        for seed in (1, 2):
            # SB3's runs in the side-by-side folder, minippo's in the seven tasks' (the runs its side reads)
            sb3_folder = runs / f"sb3-Hopper-v5-seed{seed}"
            folder = sb3_folder if library == "sb3" else tmp_path / "seven" / f"Hopper-v5-seed{seed}"
            folder.mkdir(parents=True)
            lines = ["update,step,return_mean"] + [f"{k},{2048 * k},{level * k + seed}" for k in range(1, 6)]
            (folder / "progress.csv").write_text("\n".join(lines) + "\n")
    rows = [peer_record(library, "Hopper-v5", seed, 1, 1) for library in ("minippo", "sb3") for seed in (1, 2)]

    import matplotlib.axes

    original = matplotlib.axes.Axes.plot

    def spy(ax, x, y, *args, **kwargs):
        drawn.append((kwargs.get("label"), list(x)[0], list(y)[0], list(y)[-1]))
        return original(ax, x, y, *args, **kwargs)

    matplotlib.axes.Axes.plot = spy
    try:
        report.figure_peers(rows, tmp_path / "peers_curves.png", runs, tmp_path / "seven")
    finally:
        matplotlib.axes.Axes.plot = original
    assert (tmp_path / "peers_curves.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the mean over the two seeds (seed adds 1 or 2) at the first and the last update
    assert drawn == [("minippo, 2 seeds", 2048.0, 101.5, 501.5), ("sb3, 2 seeds", 2048.0, 51.5, 251.5)]


# the runner: runs, rows, settings


def test_runs_alternate_libraries_and_name_their_command():
    runs = peers.sweep_runs(["Hopper-v5", "Walker2d-v5"], [1, 2], 1_000_000)
    assert [run.name for run in runs[:4]] == [
        "minippo-Hopper-v5-seed1",
        "sb3-Hopper-v5-seed1",
        "minippo-Hopper-v5-seed2",
        "sb3-Hopper-v5-seed2",
    ]
    assert runs[1].labels == {"library": "sb3", "task": "Hopper-v5", "seed": 1}
    assert runs[0].config == Config(env_id="Hopper-v5", seed=1)
    assert runs[1].command("benchmarks/runs/peers") == (
        "python -m benchmarks.peers --libraries sb3 --tasks Hopper-v5 --seeds 1 --steps 1000000"
    )
    assert runs[0].command("/tmp/elsewhere").endswith("--steps 1000000 --runs /tmp/elsewhere")


def test_a_record_row_has_the_columns_in_order():
    run = peers.sweep_runs(["Hopper-v5"], [3], 4096, ["sb3"])[0]
    sweep_row = {"steps": 4096, "return_mean": "12.3456", "wall_s": 5.04, "commit": "abc", "command": "python x"}
    result = {"eval": [10.0, 11.0, 12.5], "version": "stable-baselines3 2.9.2, torch 2.13.0+cpu"}
    row = peers.peer_row(run, sweep_row, result)
    assert (
        list(row)
        == peers.FIELDS
        == [
            "library",
            "version",
            "task",
            "seed",
            "steps",
            "return_mean",
            "eval_mean",
            "wall_s",
            "commit",
            "command",
        ]
    )
    assert row == {
        "library": "sb3",
        "version": "stable-baselines3 2.9.2, torch 2.13.0+cpu",
        "task": "Hopper-v5",
        "seed": 3,
        "steps": 4096,
        "return_mean": 12.35,
        "eval_mean": 11.17,
        "wall_s": 5.0,
        "commit": "abc",
        "command": "python x",
    }


def test_sb3_settings_are_minippos_defaults():
    config = Config(env_id="Hopper-v5", seed=4)
    settings = peers.sb3_settings(config)
    ppo, normalize = settings["ppo"], settings["vec_normalize"]
    assert (ppo["n_steps"], ppo["batch_size"], ppo["n_epochs"]) == (2048, 64, 10)
    assert (ppo["gamma"], ppo["gae_lambda"], ppo["clip_range"], ppo["clip_range_vf"]) == (0.99, 0.95, 0.2, None)
    assert (ppo["ent_coef"], ppo["vf_coef"], ppo["max_grad_norm"], ppo["seed"]) == (0.0, 0.25, 0.5, 4)
    assert ppo["policy_kwargs"]["net_arch"] == {"pi": [64, 64], "vf": [64, 64]}
    assert ppo["policy_kwargs"]["optimizer_kwargs"] == {"eps": 1e-5} and ppo["policy_kwargs"]["log_std_init"] == 0
    assert normalize == {
        "norm_obs": True,
        "norm_reward": True,
        "clip_obs": 10.0,
        "clip_reward": 10.0,
        "gamma": 0.99,
        "epsilon": 1e-8,
    }
    assert settings["total_timesteps"] == 488 * 2048
    # SB3 calls the schedule with the progress remaining after update k's rollout, 1 − k·2048/total
    rate = ppo["learning_rate"]
    for k in (1, 2, 244, 488):
        progress_remaining = 1 - k * 2048 / settings["total_timesteps"]
        sb3_rate = rate["initial"] * (progress_remaining + rate["plus"])
        assert sb3_rate == pytest.approx(linear_schedule(3e-4, k, 488), rel=1e-12, abs=1e-15)


def test_the_runner_refuses_what_it_cannot_run(capsys):
    for argv, message in [
        (["--tasks", "CartPole-v1"], "discrete actions"),
        (["--tasks", "NoSuchTask-v0"], "unknown task"),
        (["--steps", "100"], "at least one horizon"),
        (["--seeds", "1", "1"], "named twice"),
    ]:
        with pytest.raises(SystemExit) as exit_info:
            peers.main(argv)
        assert exit_info.value.code == 2 and message in capsys.readouterr().err


# one real tiny run of each library through the sweep engine


@pytest.fixture
def ray_here(ray_environment):
    """Ray in the session's environment (conftest.py): loopback, no usage reports, this checkout's minippo."""


@pytest.mark.skipif(importlib.util.find_spec("stable_baselines3") is None, reason="stable-baselines3 not installed")
def test_a_tiny_run_of_each_library_through_the_engine(tmp_path, ray_here):
    record, runs = tmp_path / "peers.csv", tmp_path / "runs"
    argv = ["--tasks", "Pendulum-v1", "--seeds", "1", "--steps", "4096", "--csv", str(record), "--runs", str(runs)]
    assert peers.main([*argv, "--workers", "2", "--quiet"]) == 0
    rows = read_rows(record)
    assert [row["library"] for row in rows] in (["minippo", "sb3"], ["sb3", "minippo"])  # as they finish
    for row in rows:
        assert list(row) == peers.FIELDS
        assert (row["task"], row["seed"], row["steps"]) == ("Pendulum-v1", "1", "4096")
        # Pendulum's returns lie between about −1,900 and 0 per 200-step episode
        assert -2000 < float(row["return_mean"]) < 0 and -2000 < float(row["eval_mean"]) < 0
        assert float(row["wall_s"]) > 0 and row["commit"] == peers.code_commit()
        assert row["command"] == (
            f"python -m benchmarks.peers --libraries {row['library']} --tasks Pendulum-v1 --seeds 1 --steps 4096 "
            f"--runs {common.relative(runs)}"
        )
    versions = {row["library"]: row["version"] for row in rows}
    assert versions["minippo"].startswith("minippo ") and versions["sb3"].startswith("stable-baselines3 ")
    # both ran two updates with the same step sizes, minippo's linear annealing
    mine = read_rows(runs / "minippo-Pendulum-v1-seed1" / "progress.csv")
    theirs = read_rows(runs / "sb3-Pendulum-v1-seed1" / "progress.csv")
    assert [row["step"] for row in mine] == [row["step"] for row in theirs] == ["2048", "4096"]
    assert [float(row["lr"]) for row in theirs] == pytest.approx([float(row["lr"]) for row in mine]) == [3e-4, 1.5e-4]
    assert (runs / "sb3-Pendulum-v1-seed1" / "config.json").exists()
    assert (runs / "minippo-Pendulum-v1-seed1" / "policy.npz").exists()
    log = read_rows(runs / "sweep.csv")
    assert sorted((row["library"], row["status"]) for row in log) == [("minippo", "ok"), ("sb3", "ok")]
    # recorded runs are skipped: the same command does nothing more
    assert peers.main([*argv, "--quiet"]) == 0 and len(read_rows(record)) == 2


def test_the_list_shows_recorded_and_left_runs(tmp_path, capsys):
    record = tmp_path / "peers.csv"
    append_row(record, peers.FIELDS, peer_record("sb3", "Hopper-v5", 1, 1234.5, 1500))
    assert peers.main(["--tasks", "Hopper-v5", "--seeds", "1", "--csv", str(record), "--list"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("to do     minippo  Hopper-v5") and out[1].startswith("recorded  sb3      Hopper-v5")


def test_a_missing_sb3_is_named_with_its_install_command(monkeypatch, capsys):
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: None if name == "stable_baselines3" else real(name))
    with pytest.raises(SystemExit):
        peers.main(["--tasks", "Pendulum-v1", "--libraries", "sb3"])
    assert "pip install torch==2.13.0" in capsys.readouterr().err


def test_the_peer_sweep_logs_and_records_its_own_columns(tmp_path):
    job = peers.PeerSweep(peers.sweep_runs(["Hopper-v5"], [1], 4096), tmp_path / "runs", tmp_path / "peers.csv")
    assert job.task is peers.peer_run  # given to the engine when the sweep is made
    assert job.fields[:4] == ["library", "task", "seed", "steps"] and job.record_csv == tmp_path / "peers.csv"
    assert job.csv_path == tmp_path / "runs" / "sweep.csv" and job.commit == peers.code_commit()


def test_minippo_side_from_another_records_runs(tmp_path):
    from minippo.ppo import train

    folder = tmp_path / "runs" / "Pendulum-v1-seed1"
    train(Config(env_id="Pendulum-v1", total_steps=2048, seed=1, horizon=1024), folder)
    run = {"env": "Pendulum-v1", "seed": "1", "steps": "2048", "return_mean": "-1200.5", "wall_s": "3.0"}
    run |= {"steps_per_s": "700", "commit": "abc", "command": "minippo train Pendulum-v1 ..."}
    append_row(tmp_path / "runs.csv", list(run), run)
    record = tmp_path / "peers.csv"
    assert peers.evaluate_record(tmp_path / "runs.csv", tmp_path / "runs", record, ["Pendulum-v1"]) == 1
    (row,) = read_rows(record)
    assert list(row) == peers.FIELDS and row["library"] == "minippo" and row["command"] == run["command"]
    assert -2000 < float(row["eval_mean"]) < 0 and row["return_mean"] == "-1200.5"
    assert peers.evaluate_record(tmp_path / "runs.csv", tmp_path / "runs", record, ["Pendulum-v1"]) == 0  # once
