"""The benchmark scripts' logic on small made-up records: Table 1's scoring, CSV appends, the runners' sweeps and
their resumes, the speed table's ratios, and the summary. No training runs here: the sweep engine's Ray tasks are
replaced by a stub that returns what a finished training leaves behind."""

import csv
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import records  # noqa: E402
import seven_tasks  # noqa: E402
import speed  # noqa: E402
import summary  # noqa: E402
import table1  # noqa: E402


def write_csv(path, rows):
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def table1_run(setting, env_id, seed, value, steps="4096"):
    """One row of a Table 1 runs record, as the scoring reads it."""
    return {"setting": setting, "env": env_id, "seed": str(seed), "steps": steps, "return_mean": str(value)}


def random_rows(env_ids, value="10"):
    """random.csv rows giving every task the same random-policy return."""
    return [{"env": env_id, "return_mean": value, "episodes": "100", "seed": "0"} for env_id in env_ids]


def fake_run(folder, updates, returns, horizon=2048, checkpoint_update=None):
    """A run folder as ``minippo train`` leaves it: progress.csv with one row per update, and a checkpoint."""
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    for update, value in zip(range(1, updates + 1), returns):
        rows.append(
            {
                "update": update,
                "step": update * horizon,
                "return_mean": repr(float(value)),
                "steps_per_s": "3000.123456789",
                "wall_s": repr(update * horizon / 3000.123456789),
            }
        )
    write_csv(folder / "progress.csv", rows)
    np.savez(folder / "checkpoint.npz", update=np.array(updates if checkpoint_update is None else checkpoint_update))


# Table 1's scoring


def test_normalized_scores_match_hand_computation():
    randoms = {"A": 0.0, "B": -100.0}
    runs = [
        {"setting": "clip", "env": "A", "return_mean": "80"},
        {"setting": "clip", "env": "B", "return_mean": "100"},  # best on B
        {"setting": "cpi", "env": "A", "return_mean": "-40"},  # below random: negative score
        {"setting": "cpi", "env": "B", "return_mean": "0"},
        {"setting": "kl", "env": "A", "return_mean": "100"},  # best on A
        {"setting": "kl", "env": "B", "return_mean": "50"},
    ]
    scores = table1.normalized_scores(runs, randoms)
    # A: random 0, best 100; B: random -100, best 100 (span 200)
    assert scores["clip"]["score"] == pytest.approx((0.8 + 1.0) / 2)
    assert scores["cpi"]["score"] == pytest.approx((-0.4 + 0.5) / 2)
    assert scores["kl"]["score"] == pytest.approx((1.0 + 0.75) / 2)
    assert scores["clip"]["runs"] == 2 and scores["clip"]["tasks"] == 2
    assert scores["clip"]["se"] is None  # one seed per task: no spread to measure


def test_score_standard_error_pools_the_seeds_within_each_task():
    randoms = {"A": 0.0, "B": 0.0}
    returns = {"A": [100.0, 60.0, 80.0], "B": [10.0, 30.0]}  # best: 100 on A, 30 on B
    runs = [{"setting": "s", "env": env, "return_mean": str(v)} for env, values in returns.items() for v in values]
    score = table1.normalized_scores(runs, randoms)["s"]
    # normalised: A 1.0, 0.6, 0.8 (variance 0.04 over 3 seeds); B 1/3, 1 (variance 2/9 over 2 seeds)
    assert score["score"] == pytest.approx((1.0 + 0.6 + 0.8 + 1 / 3 + 1.0) / 5)
    assert score["se"] == pytest.approx(((0.04 / 3 + (2 / 9) / 2) ** 0.5) / 2)


def test_normalized_scores_average_over_seeds():
    runs = [
        {"setting": "s", "env": "A", "return_mean": "10"},
        {"setting": "s", "env": "A", "return_mean": "30"},
        {"setting": "t", "env": "A", "return_mean": "50"},
    ]
    scores = table1.normalized_scores(runs, {"A": 10.0})
    assert scores["s"]["score"] == pytest.approx((0.0 + 0.5) / 2)
    assert scores["t"]["score"] == pytest.approx(1.0)


def test_normalized_scores_refuse_missing_random_or_no_progress():
    with pytest.raises(records.BenchmarkError, match="no random-policy return"):
        table1.normalized_scores([{"setting": "s", "env": "A", "return_mean": "1"}], {})
    with pytest.raises(records.BenchmarkError, match="beats the random policy"):
        table1.normalized_scores([{"setting": "s", "env": "A", "return_mean": "1"}], {"A": 5.0})


def test_write_table_keeps_the_paper_column_and_order(tmp_path):
    runs = []
    for name, _, _ in table1.SETTINGS:
        value = {"No clipping or penalty": 0.0, "Clipping, ε = 0.2": 200.0}.get(name, 100.0)
        runs.append(
            {
                "setting": name,
                "env": "A",
                "seed": 1,
                "steps": 4096,
                "return_mean": value,
                "wall_s": 1,
                "steps_per_s": 1,
                "commit": "x",
                "command": "c",
            }
        )
    write_csv(tmp_path / "runs.csv", runs)
    write_csv(tmp_path / "random.csv", [{"env": "A", "episodes": 100, "seed": 0, "return_mean": 0.0}])
    table = table1.write_table(tmp_path / "runs.csv", tmp_path / "random.csv", tmp_path / "t.csv", ["A"], [1], 5000)
    assert [row["setting"] for row in table] == [name for name, _, _ in table1.SETTINGS]
    written = records.read_rows(tmp_path / "t.csv")
    assert written[0]["score"] == "0.0" and written[0]["paper_score"] == "-0.39"
    assert written[2]["score"] == "1.0" and written[2]["paper_score"] == "0.82"
    assert written[1]["score"] == "0.5"
    assert "4,096 steps" in written[0]["scale"] and "paper: 7 tasks" in written[0]["scale"]


def test_write_table_scores_only_the_tasks_whose_runs_are_all_recorded(tmp_path):
    def run(setting, env_id, seed, value):
        return {
            "setting": setting,
            "env": env_id,
            "seed": seed,
            "steps": 4096,
            "return_mean": value,
            "wall_s": 1,
            "steps_per_s": 1,
            "commit": "x",
            "command": "c",
        }

    clip, cpi = "Clipping, ε = 0.2", "No clipping or penalty"
    runs = [run(clip, "A", 1, 100.0), run(cpi, "A", 1, 50.0), run(clip, "A", 2, 80.0), run(cpi, "A", 2, 40.0)]
    runs += [run(clip, "B", 1, 10.0)]  # B is still running: its best run may not have come yet
    write_csv(tmp_path / "runs.csv", runs)
    write_csv(tmp_path / "random.csv", [{"env": e, "episodes": 100, "seed": 0, "return_mean": 0.0} for e in "AB"])
    args = tmp_path / "runs.csv", tmp_path / "random.csv", tmp_path / "t.csv"
    table = table1.write_table(*args, ["A", "B"], [1, 2], 5000)
    assert {row["setting"]: row["score"] for row in table} == {cpi: round((0.5 + 0.4) / 2, 2), clip: 0.9}
    assert all(row["tasks"] == 1 and row["scale"].startswith("tasks A;") for row in table)
    assert all(row["task_ids"] == "A" for row in table)
    with pytest.raises(records.BenchmarkError, match="no task has all its runs"):
        table1.write_table(*args, ["B"], [1, 2], 5000)


def test_slug_makes_distinct_folder_names():
    slugs = [table1.slug(name) for name, _, _ in table1.SETTINGS]
    assert len(set(slugs)) == len(slugs)
    assert table1.slug("Adaptive KL, d_targ = 0.003") == "adaptive-kl-dtarg-0.003"
    assert table1.slug("Clipping, ε = 0.2") == "clipping-eps-0.2"


# records and the runners' sweeps


def test_append_row_writes_header_once_and_skips_duplicates(tmp_path):
    path = tmp_path / "r.csv"
    fields = ["env", "seed", "value"]
    assert records.append_row(path, fields, {"env": "A", "seed": 1, "value": 1.5}, unique=("env", "seed"))
    assert records.append_row(path, fields, {"env": "A", "seed": 2, "value": 2.5}, unique=("env", "seed"))
    assert not records.append_row(path, fields, {"env": "A", "seed": 1, "value": 9.9}, unique=("env", "seed"))
    lines = path.read_text().splitlines()
    assert lines == ["env,seed,value", "A,1,1.5", "A,2,2.5"]
    with pytest.raises(records.BenchmarkError, match="columns"):
        records.append_row(path, ["env", "other"], {"env": "A", "other": 1})


def test_compact_progress_rounds_floats_and_keeps_integers(tmp_path):
    fake_run(tmp_path / "run", 2, [1.23456789012, float("nan")])
    records.compact_progress(tmp_path / "run")
    rows = records.read_rows(tmp_path / "run" / "progress.csv")
    assert rows[0]["update"] == "1" and rows[1]["step"] == "4096"
    assert rows[0]["return_mean"] == "1.23457" and rows[1]["return_mean"] == "nan"
    assert rows[0]["steps_per_s"] == "3000.12"


@pytest.fixture
def stub_engine(monkeypatch, tmp_path):
    """Replace the engine's Ray tasks with a stub that hands back what a finished two-update training returns."""
    from minippo import sweep

    done = []
    fake_run(tmp_path / "made", 2, [10.0, 20.0])
    files = {path.name: path.read_bytes() for path in (tmp_path / "made").iterdir()}
    last = {"step": 4096, "return_mean": 20.0, "wall_s": 2.04, "steps_per_s": 2000.04}

    def execute(runs, on_result, workers=None, address=None, retries=0, progress=None):
        for run in runs:
            done.append(run)
            on_result(run, {"files": files, "last": last, "node": "n1", "host": "h"}, "", 1)

    monkeypatch.setattr(sweep, "execute", execute)
    return done


def test_seven_tasks_records_runs_and_skips_recorded_ones(tmp_path, stub_engine):
    csv_path, runs = tmp_path / "mujoco.csv", tmp_path / "runs"
    args = ["--envs", "Hopper-v5", "Swimmer-v5", "--seeds", "1", "2", "--steps", "4096"]
    args += ["--csv", str(csv_path), "--runs", str(runs), "--quiet"]
    assert seven_tasks.main(args) == 0
    rows = records.read_rows(csv_path)
    assert list(rows[0]) == seven_tasks.FIELDS
    assert [(row["env"], row["seed"]) for row in rows] == [
        ("Hopper-v5", "1"),
        ("Hopper-v5", "2"),
        ("Swimmer-v5", "1"),
        ("Swimmer-v5", "2"),
    ]
    assert rows[0]["return_mean"] == "20.0" and rows[0]["steps"] == "4096" and rows[0]["wall_s"] == "2.0"
    assert rows[0]["command"] == f"minippo train Hopper-v5 --steps 4096 --seed 1 --out {runs}/Hopper-v5-seed1 --quiet"
    assert rows[0]["commit"] == records.git_commit()
    assert [run.config.seed for run in stub_engine] == [1, 2, 1, 2]
    assert (runs / "Hopper-v5-seed1" / "curve.png").exists()
    sweep_rows = records.read_rows(runs / "sweep.csv")  # the engine's own log says where each run ran
    assert [(row["status"], row["node"]) for row in sweep_rows] == [("ok", "n1")] * 4
    assert seven_tasks.main(args) == 0  # everything recorded: nothing runs again
    assert len(stub_engine) == 4 and len(records.read_rows(csv_path)) == 4


def test_runners_skip_what_the_records_hold(tmp_path, stub_engine):
    csv_path = tmp_path / "mujoco.csv"
    write_csv(csv_path, [dict.fromkeys(seven_tasks.FIELDS, "x") | {"env": "Hopper-v5", "seed": "2"}])
    args = ["--envs", "Hopper-v5", "--seeds", "1", "2", "--steps", "4096", "--csv", str(csv_path)]
    assert seven_tasks.main([*args, "--runs", str(tmp_path / "runs"), "--quiet"]) == 0
    assert [run.config.seed for run in stub_engine] == [1]


def test_table1_sweep_makes_the_commands_of_its_records():
    """The runs the sweep describes are the trainings whose commands the 1M-step Table 1 records hold (the KL rows
    among the stale ones being rerun), which the earlier runner started with one BLAS thread set in the environment,
    which minippo sets itself."""
    recorded = {
        (row["setting"], row["env"], row["seed"]): row["command"]
        for path in (records.RESULTS / "table1_1m_runs.csv", records.RESULTS / "stale" / "table1_1m_runs.csv")
        for row in records.read_rows(path)
    }
    runs = table1.sweep_runs(table1.SETTINGS, ["HalfCheetah-v5", "Hopper-v5"], [1, 2], 1_000_000)
    assert len(runs) == 11 * 2 * 2 and runs[0].labels == {
        "setting": table1.SETTINGS[0][0],
        "env": "HalfCheetah-v5",
        "seed": 1,
    }
    for run in runs:
        command = recorded[tuple(str(v) for v in run.labels.values())]
        assert command.split("minippo ", 1)[1] == run.command("benchmarks/runs/table1_1m").split("minippo ", 1)[1]
    fixed = next(run for run in runs if run.labels["setting"] == "Fixed KL, β = 3")
    assert (fixed.config.objective, fixed.config.adaptive_kl, fixed.config.kl_beta) == ("klpen", False, 3.0)
    with pytest.raises(records.BenchmarkError, match="--objective and --config"):
        table1.setting_config(["--steps", "5"])


def test_table1_overrides_join_each_settings_config():
    cpi, clip = table1.SETTINGS[0], table1.SETTINGS[2]
    extra = ["grad_norm_clipping=false", "anneal_lr=false"]
    assert table1.with_overrides(cpi, extra)[1] == ["--objective", "cpi", "--config", *extra]
    assert table1.with_overrides(clip, extra)[1] == ["--objective", "clip", "--config", "clip_epsilon=0.2", *extra]
    assert table1.with_overrides(clip, []) == clip


def test_table1_rejects_a_setting_outside_the_table(capsys):
    with pytest.raises(SystemExit) as exit_info:
        table1.main(["--settings", "12", "--score"])
    assert exit_info.value.code != 0 and "from 1 to 11" in capsys.readouterr().err


# speed table and summary


def test_speed_ratios_use_medians():
    rounds = {"raw": [100.0, 300.0, 200.0], "minippo": [50.0, 150.0, 120.0], "sb3": [10.0, 30.0, 20.0]}
    rows = {row["contender"]: row for row in speed.summarize("E", rounds, {"raw": 5}, {})}
    assert rows["raw"]["steps_per_s"] == 200.0 and rows["minippo"]["steps_per_s"] == 120.0
    assert rows["minippo"]["vs_raw"] == pytest.approx(0.6) and rows["minippo"]["vs_sb3"] == pytest.approx(6.0)
    assert rows["minippo"]["rounds"] == "50.0;150.0;120.0"
    skipped = {
        row["contender"]: row for row in speed.summarize("E", {"raw": [1.0], "minippo": [2.0], "sb3": []}, {}, {})
    }
    assert skipped["sb3"]["steps_per_s"] == "" and skipped["minippo"]["vs_sb3"] == ""


def test_summary_from_a_tiny_fixture(tmp_path):
    results, runs = tmp_path / "results", tmp_path / "runs"
    mujoco = []
    for seed, final in zip((1, 2, 3), (2100.0, 2400.0, 2700.0)):
        fake_run(runs / f"Hopper-v5-seed{seed}", 3, [10.0, 1000.0, final])
        mujoco.append(
            {
                "env": "Hopper-v5",
                "seed": seed,
                "steps": 6144,
                "return_mean": final,
                "wall_s": 60,
                "steps_per_s": 3000,
                "commit": "abc",
                "command": "c",
            }
        )
    fake_run(runs / "Swimmer-v5-seed1", 3, [1, 2, 50.0])
    mujoco.append(
        {
            "env": "Swimmer-v5",
            "seed": 1,
            "steps": 6144,
            "return_mean": 50.0,
            "wall_s": 30,
            "steps_per_s": 4000,
            "commit": "abc",
            "command": "c",
        }
    )
    write_csv(results / "mujoco.csv", mujoco)
    assert summary.main(["--results", str(results), "--runs", str(runs)]) == 0
    text = (results / "summary.md").read_text()
    hopper = next(line for line in text.splitlines() if line.startswith("| Hopper-v5"))
    # mean 2400, sample std 300; the paper's low end 2200 is beaten
    assert "2400.0 ± 300.0 (n = 3)" in hopper and "| yes |" in hopper and "2383 ± 272" in hopper
    swimmer = next(line for line in text.splitlines() if line.startswith("| Swimmer-v5"))
    assert "50.0 ± 0.0 (n = 1)" in swimmer and "| no |" in swimmer
    assert "| Walker2d-v5 | not run yet" in text
    assert "1 of 7 tasks have 3 seeds recorded" in text and "on 1 of them (Hopper-v5)" in text
    assert "No Table 1 runs are recorded yet." in text and "has not been run yet" in text
    assert (results / "mujoco_curves.png").stat().st_size > 0
    assert not (results / "table1.png").exists()


# the README's results come from the records


def test_the_readme_shows_what_the_committed_records_say():
    readme = records.ROOT / "README.md"
    text = readme.read_text()
    blocks = summary.readme_blocks(records.RESULTS)
    assert set(blocks) == {"mujoco", "speed", "table1"}
    assert summary.fill_readme(text, blocks) == text, "run `python benchmarks/summary.py --readme`"


def test_readme_blocks_are_replaced_and_a_missing_block_is_named():
    text = "intro\n<!-- summary:speed -->\nold\nlines\n<!-- /summary:speed -->\nrest\n"
    expected = "intro\n<!-- summary:speed -->\nnew\n<!-- /summary:speed -->\nrest\n"
    assert summary.fill_readme(text, {"speed": "new"}) == expected
    with pytest.raises(records.BenchmarkError, match="table1"):
        summary.fill_readme(text, {"table1": "x"})


def test_table1_verdict_reads_the_ranks():
    def table(scores):
        return [{"setting": name, "score": score} for name, score in scores.items()]

    names = [name for name, _, _ in table1.SETTINGS]
    middle = {name: 0.5 for name in names[3:]}
    paper_like = table({"Clipping, ε = 0.2": 0.8, "Clipping, ε = 0.1": 0.7, **middle, "No clipping or penalty": -0.4})
    assert "ranks 1 of 11 and no clipping 11 of 11: the paper's ordering is reproduced." in summary.table1_verdict(
        paper_like
    )
    half = table({"Clipping, ε = 0.2": 0.7, "Clipping, ε = 0.1": 0.8, **middle, "No clipping or penalty": -0.4})
    half_reproduced = "half reproduced: no clipping is last, as in the paper, but ε = 0.2 is not first (0.70 against"
    assert half_reproduced in summary.table1_verdict(half)
    other = table({"Clipping, ε = 0.2": 0.7, "Clipping, ε = 0.1": 0.8, **middle, "No clipping or penalty": 0.6})
    assert "the paper's ordering is not reproduced at this scale" in summary.table1_verdict(other)
    with_errors = [dict(row, score_se="0.05") for row in half]
    assert "(0.70 ± 0.05 against 0.80 ± 0.05), a gap of 0.10, within twice its standard error (0.07): level" in (
        summary.table1_verdict(with_errors)
    )
    far = [dict(row, score_se="0.01") for row in half]
    assert "(0.70 ± 0.01 against 0.80 ± 0.01), a gap of 0.10, more than twice its standard error (0.01)." in (
        summary.table1_verdict(far)
    )
    partial = table({"Clipping, ε = 0.2": 0.8, "No clipping or penalty": -0.4})
    assert "is not settled: only 2 of the 11 settings are recorded" in summary.table1_verdict(partial)


def test_the_later_code_table_reads_only_the_default_objective_runs():
    def run(setting, seed, value):
        return {
            "setting": setting,
            "env": "Hopper-v5",
            "seed": str(seed),
            "steps": "999424",
            "return_mean": str(value),
            "wall_s": "60",
            "steps_per_s": "100",
            "commit": "abc1234",
        }

    rows = [run("Clipping, ε = 0.2", seed, value) for seed, value in ((1, 2100), (2, 2300), (3, 2500))]
    rows.append(run("No clipping or penalty", 1, 5))
    text = "\n".join(summary.current_code_lines(rows))
    assert "| Hopper-v5 | 2300.0 ± 200.0 (n = 3) | 2100, 2300, 2500 |" in text
    assert "commits abc1234" in text and "1 of 7 tasks have 3 seeds recorded" in text
    assert "on 1 of them (Hopper-v5)." in text
    assert summary.current_code_lines([run("No clipping or penalty", 1, 5)]) == []


def test_the_recheck_sentence_gives_each_seed_and_the_commit():
    rows = [
        {
            "env": "Hopper-v5",
            "seed": str(seed),
            "steps": "999424",
            "return_mean": str(value),
            "steps_per_s": "1",
            "wall_s": "1",
            "commit": "abc1234",
            "command": "c",
        }
        for seed, value in ((2, 2100.0), (1, 2300.0))
    ]
    (line,) = summary.recheck_lines(rows)
    assert "commit abc1234" in line and "seeds 1, 2): 2300, 2100, mean 2200.0 ± 141.4." in line


def test_the_same_math_sentence_says_where_the_runs_part():
    def row(env_id, update, difference):
        return {
            "env": env_id,
            "seed": "1",
            "dtype": "float64",
            "update": str(update),
            "earlier_commit": "abc1234",
            "commit": "def5678",
            "max_relative_difference": str(difference),
            "command": "python same_math.py",
        }

    rows = [row("Hopper-v5", 1, 1e-15), row("Hopper-v5", 2, 3e-3), row("Hopper-v5", 3, 0.2), row("Hopper-v5", 4, 0.01)]
    rows += [row("Swimmer-v5", 2, 2e-11), row("Swimmer-v5", 1, 4e-16)]
    hopper, swimmer = summary.same_math_lines(rows)
    assert "commit abc1234 against def5678" in hopper
    assert "4e-16 at update 1" not in hopper and "1e-15 at update 1; the runs part (above 1%) at update 3." in hopper
    assert swimmer.endswith("4e-16 at update 1; they stay within 2e-11 for all 2 updates.")


def test_same_math_finds_no_difference_between_a_commit_and_itself(tmp_path):
    """The real script, end to end: HEAD in a worktree against the working tree, two CartPole updates. The same code
    on the same machine gives the same numbers, so every difference is exactly zero."""
    import same_math

    if records.git_commit().endswith("+dirty"):
        pytest.skip("minippo/ has uncommitted edits, so HEAD is not the code that runs")
    record = tmp_path / "same.csv"
    assert same_math.main(["HEAD", "--env", "CartPole-v1", "--updates", "2", "--csv", str(record)]) == 0
    rows = records.read_rows(record)
    assert [row["update"] for row in rows] == ["1", "2"]
    assert all(float(row["max_relative_difference"]) == 0.0 for row in rows)
    assert rows[0]["return_mean_earlier"] == rows[0]["return_mean_current"] != ""


def test_same_math_refuses_an_unknown_commit_on_one_line(capsys, tmp_path):
    import same_math

    with pytest.raises(SystemExit) as stop:
        same_math.main(["no-such-commit", "--csv", str(tmp_path / "x.csv")])
    assert stop.value.code != 0
    error = capsys.readouterr().err.strip()
    assert error.endswith(": error: no commit named 'no-such-commit' in this repository") and "\n" not in error
    assert not (tmp_path / "x.csv").exists()


def test_table1_by_task_scores_each_task_as_the_table_does():
    run = table1_run
    runs = [
        run("Clipping, ε = 0.2", "A", 1, 50),
        run("Clipping, ε = 0.2", "A", 2, 30),
        run("Fixed KL, β = 3", "A", 1, 110),
        run("Fixed KL, β = 3", "A", 2, 90),
        run("Clipping, ε = 0.2", "B", 1, 10),
        run("Fixed KL, β = 3", "B", 1, 10),
        run("Fixed KL, β = 3", "C", 1, 999),  # not among the table's tasks
        run("Fixed KL, β = 3", "A", 3, 999, steps="2048"),  # another scale
    ]
    randoms = [
        {"env": env_id, "return_mean": value, "episodes": "100", "seed": "0"}
        for env_id, value in (("A", "10"), ("B", "0"), ("C", "10"))
    ]
    table = [
        {"setting": "Clipping, ε = 0.2", "task_ids": "A B", "steps": "4096"},
        {"setting": "Fixed KL, β = 3", "task_ids": "A B", "steps": "4096"},
    ]
    by_task = summary.table1_by_task(table, runs, randoms)
    # task A: random 10, best 110, so (50-10)/100 and (30-10)/100 average 0.3; task B: random 0, best 10
    assert by_task["Clipping, ε = 0.2"] == pytest.approx({"A": 0.3, "B": 1.0})
    assert by_task["Fixed KL, β = 3"] == pytest.approx({"A": 0.9, "B": 1.0})
    lines = summary.table1_task_lines(by_task)
    assert lines[0] == "| Setting | A | B |" and lines[2] == "| Clipping, ε = 0.2 | 0.30 | 1.00 |"
    assert lines[-1] == (
        "Task by task, against Clipping, ε = 0.2, Fixed KL, β = 3 scores higher on 1 (A), "
        "the same to two decimals on 1 (B) and lower on 0."
    )


def test_no_task_by_task_sentence_when_the_paper_setting_leads():
    by_task = {"Clipping, ε = 0.2": {"A": 0.9}, "Fixed KL, β = 3": {"A": 0.5}}
    assert summary.leader_sentence(by_task) is None
    assert summary.table1_task_lines(by_task)[-1] == "| Fixed KL, β = 3 | 0.50 |"


def test_two_implementations_are_scored_on_one_scale_over_complete_tasks():
    run = table1_run
    clip, beta, cpi = "Clipping, ε = 0.2", "Fixed KL, β = 3", "No clipping or penalty"
    default = [
        run(clip, "Hopper-v5", 1, 60),
        run(clip, "Hopper-v5", 2, 40),
        run(beta, "Hopper-v5", 1, 90),
        run(beta, "Hopper-v5", 2, 70),
        run(cpi, "Hopper-v5", 1, 110),
        run(cpi, "Hopper-v5", 2, 10),  # not run the other way, but sets the best
        run(clip, "Swimmer-v5", 1, 50),
        run(beta, "Swimmer-v5", 1, 50),
    ]
    other = [
        run(clip, "Hopper-v5", 1, 80),
        run(clip, "Hopper-v5", 2, 60),
        run(beta, "Hopper-v5", 1, 30),
        run(beta, "Hopper-v5", 2, 10),
        run(clip, "Swimmer-v5", 1, 99),  # Swimmer lacks β = 3 here: not scored, not even in the best
    ]
    randoms = random_rows(["Hopper-v5", "Swimmer-v5"])
    compared = summary.implementation_scores(default, other, randoms)
    assert list(compared) == [clip, beta]  # Table 1's order, only the settings run both ways
    # Hopper: random 10, best 110 (the defaults' unclipped seed 1), so a return r scores (r - 10) / 100
    assert compared[clip][0]["score"] == pytest.approx(0.4) and compared[clip][1]["score"] == pytest.approx(0.6)
    assert compared[beta][0]["score"] == pytest.approx(0.7) and compared[beta][1]["score"] == pytest.approx(0.1)
    assert compared[clip][1]["tasks"] == 1 and compared[clip][1]["runs"] == 2
    lines = summary.implementation_lines(compared)
    assert lines[0].startswith("2 of Table 1's 11 settings, 1 tasks, 2 runs each way.")
    whole = {setting: compared[clip] for setting in summary.TABLE1_PAPER}  # every row rerun: the text says so
    assert summary.implementation_lines(whole)[0].startswith("All of Table 1's 11 settings,")
    assert lines[4] == "| Clipping, ε = 0.2 | 0.40 ± 0.10 | 0.60 ± 0.10 | 0.82 |"
    assert lines[-1] == (
        "Among these settings Clipping, ε = 0.2 ranks 2 of 2 with minippo's defaults, behind Fixed KL, β = 3 (0.70); "
        "1 of 2 as the paper describes it."
    )  # ε = 0.2 leads as the paper describes it, so no task-by-task sentence follows
    third = {**compared, **{name: compared[beta] for name in ("Clipping, ε = 0.3", "Fixed KL, β = 1")}}
    assert summary.implementation_lines(third)[-1] == (  # every setting ahead of ε = 0.2 is named, with its score
        "Among these settings Clipping, ε = 0.2 ranks 4 of 4 with minippo's defaults, behind Fixed KL, β = 3 (0.70), "
        "Clipping, ε = 0.3 (0.70) and Fixed KL, β = 1 (0.70); 1 of 4 as the paper describes it."
    )
    behind = {**compared, beta: (compared[beta][0], {**compared[beta][1], "per_task": {"Hopper-v5": 0.9}})}
    assert summary.implementation_lines(behind)[-1] == (
        "As the paper describes it: task by task, against Clipping, ε = 0.2, Fixed KL, β = 3 scores higher on 1 "
        "(Hopper-v5), the same to two decimals on 0 and lower on 0."
    )
    assert summary.implementation_scores(default, [], randoms) == {}
    assert summary.implementation_scores(default, other[:1], randoms) == {}  # Hopper lacks the defaults' seed 2
    assert list(summary.implementation_scores(default, other[:2], randoms)) == [clip]  # one setting, all seeds


def test_more_seeds_are_scored_with_the_table_on_one_scale(tmp_path):
    run = table1_run
    clip, beta, cpi = "Clipping, ε = 0.2", "Fixed KL, β = 3", "No clipping or penalty"
    table = [
        run(clip, "Hopper-v5", 1, 60),
        run(clip, "Hopper-v5", 2, 40),
        run(beta, "Hopper-v5", 1, 90),
        run(beta, "Hopper-v5", 2, 70),
        run(cpi, "Hopper-v5", 1, 110),  # not rerun, but sets the best
        run(clip, "Swimmer-v5", 1, 50),
        run(beta, "Swimmer-v5", 1, 50),
    ]
    more = [
        run(clip, "Hopper-v5", 3, 80),
        run(clip, "Hopper-v5", 4, 60),
        run(beta, "Hopper-v5", 3, 50),
        run(beta, "Hopper-v5", 4, 10),
        run(clip, "Swimmer-v5", 3, 999),  # Swimmer lacks β = 3 and seed 4: not scored, not even in the best
    ]
    randoms = random_rows(["Hopper-v5", "Swimmer-v5"])
    scores = summary.more_seeds_scores(table, more, randoms)
    assert list(scores) == [clip, beta]  # Table 1's order, only the settings run again
    # Hopper: random 10, best 110, so a return r scores (r - 10) / 100
    assert [scores[clip][part]["score"] for part in ("table", "new", "all")] == pytest.approx([0.4, 0.6, 0.5])
    assert [scores[beta][part]["score"] for part in ("table", "new", "all")] == pytest.approx([0.7, 0.2, 0.45])
    assert scores[clip]["all"]["runs"] == 4 and scores[clip]["all"]["tasks"] == 1
    assert summary.more_seeds_scores(table, [], randoms) == {}
    assert summary.more_seeds_scores(table, more[:3], randoms) == {}  # Hopper lacks β = 3 at seed 4

    write_csv(tmp_path / summary.MORE_SEEDS_CSV, more)
    lines = summary.more_seeds_block(tmp_path, table, randoms)
    assert lines[2] == "| Setting | seeds 1, 2 | seeds 3, 4 | all seeds | paper (Table 1) |"
    assert lines[4] == "| Clipping, ε = 0.2 | 0.40 ± 0.10 | 0.60 ± 0.10 | 0.50 ± 0.08 | 0.82 |"
    # all seeds: ε = 0.2's variance over [0.5, 0.3, 0.7, 0.5] is 0.08/3, β = 3's over [0.8, 0.6, 0.4, 0.0] is 0.35/3,
    # so the difference 0.05 has standard error sqrt((0.08 + 0.35) / 12) = 0.189
    assert lines[-1] == (
        "Over all seeds Clipping, ε = 0.2 scores 0.05 above Fixed KL, β = 3 (4 runs each, 0.3 standard errors of the "
        "difference)."
    )
    assert summary.more_seeds_block(tmp_path / "nothing", table, randoms) == []
    assert summary.seed_range([{"seed": "4"}, {"seed": "6"}, {"seed": "5"}]) == "4–6"


def test_one_detail_table_puts_each_detail_between_all_on_and_all_off(tmp_path):
    def run(env_id, seed, value):
        return table1_run("No clipping or penalty", env_id, seed, value)

    assert summary.one_detail_lines(tmp_path) == []  # nothing recorded yet
    write_csv(tmp_path / "table1_1m_runs.csv", [run("IP", 1, 100), run("IP", 2, 200), run("Other", 1, 5)])
    write_csv(tmp_path / "cpi_without_clip_value_loss_runs.csv", [run("IP", 1, 1000), run("IP", 2, 900)])
    write_csv(tmp_path / "table1_1m_paperimpl_runs.csv", [run("IP", 1, 1000)])
    lines = summary.one_detail_lines(tmp_path)
    assert lines[0] == (
        "| Task | all on | grad_norm_clipping off | clip_value_loss off | scale_rewards off | all off |"
    )
    assert lines[2:] == ["| IP | 150 (2) | — | 950 (2) | — | 1000 (1) |"]  # only the tasks run one detail at a time


def test_three_details_block_names_its_settings_being_rerun(tmp_path):
    clip, beta, adaptive = "Clipping, ε = 0.2", "Fixed KL, β = 3", "Adaptive KL, d_targ = 0.01"

    def other(name, seed, value):  # a run of the three-details record, with its command's overrides
        return {**table1_run(name, "Hopper-v5", seed, value), "command": "minippo train --config scale_rewards=false"}

    default = [table1_run(name, "Hopper-v5", seed, 50 + seed) for name in (clip, beta, adaptive) for seed in (1, 2)]
    randoms = random_rows(["Hopper-v5"])
    write_csv(tmp_path / "table1_1m_paperimpl_runs.csv", [other(clip, s, 40) for s in (1, 2)])
    (tmp_path / "stale").mkdir()
    write_csv(
        tmp_path / "stale" / "table1_1m_paperimpl_runs.csv", [other(n, s, 70) for n in (beta, adaptive) for s in (1, 2)]
    )
    block = summary.implementation_block(tmp_path, default, randoms)
    assert block[-1].startswith(f"Not shown: 2 KL-penalty settings ({adaptive}, {beta}), being rerun")
    rerun = [other(beta, s, 60) for s in (1, 2)]  # β = 3 rerun: scored, and no longer named
    write_csv(tmp_path / "table1_1m_paperimpl_runs.csv", [other(clip, s, 40) for s in (1, 2)] + rerun)
    block = summary.implementation_block(tmp_path, default, randoms)
    assert any(line.startswith(f"| {beta} |") for line in block)
    assert block[-1].startswith(f"Not shown: 1 KL-penalty setting ({adaptive}), being rerun")


def test_table1_names_the_settings_being_rerun():
    table = [{"setting": "Clipping, ε = 0.2", "score": 0.8}, {"setting": "No clipping or penalty", "score": -0.4}]
    pending = ["Fixed KL, β = 3", "Adaptive KL, d_targ = 0.01"]
    text = summary.table1_verdict(table, pending)
    assert "Not shown: 2 KL-penalty settings (Fixed KL, β = 3, Adaptive KL, d_targ = 0.01), being rerun" in text
    assert "Not shown" not in summary.table1_verdict(table)
    stale = summary.stale_settings("table1_1m_runs.csv", table)  # the committed stale record names all seven
    assert stale == [name for name, _, _ in table1.SETTINGS if "KL" in name]
