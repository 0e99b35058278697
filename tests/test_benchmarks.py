"""The benchmarks package on small made-up records: Table 1's scoring and the other tables, the runners' sweeps and
their resumes, the speed table's ratios, summary.md and the README's tables. No training runs here except the
same-math script's two CartPole updates: the sweep engine's Ray tasks are replaced by a stub that returns what a
finished training leaves behind."""

import csv
import shlex

import numpy as np
import pytest

from benchmarks import common, report, scoring, seven_tasks, speed, table1
from minippo.cli import train_config
from minippo.records import append_row, read_rows


def write_csv(path, rows):
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def table1_run(setting, env_id, seed, value, steps="4096"):
    """One row of a Table 1 runs record, as the scoring reads it."""
    return {"setting": setting, "env": env_id, "seed": str(seed), "steps": steps, "return_mean": str(value)}


def recorded_run(setting, env_id, seed, value):
    """A whole row of a Table 1 runs record, as the runner writes it."""
    row = table1_run(setting, env_id, seed, value)
    return {**row, "wall_s": 1, "steps_per_s": 1, "commit": "x", "command": "c"}


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
    scores = scoring.normalized_scores(runs, randoms)
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
    score = scoring.normalized_scores(runs, randoms)["s"]
    # normalised: A 1.0, 0.6, 0.8 (variance 0.04 over 3 seeds); B 1/3, 1 (variance 2/9 over 2 seeds)
    assert score["score"] == pytest.approx((1.0 + 0.6 + 0.8 + 1 / 3 + 1.0) / 5)
    assert score["se"] == pytest.approx(((0.04 / 3 + (2 / 9) / 2) ** 0.5) / 2)


def test_normalized_scores_average_over_seeds():
    runs = [
        {"setting": "s", "env": "A", "return_mean": "10"},
        {"setting": "s", "env": "A", "return_mean": "30"},
        {"setting": "t", "env": "A", "return_mean": "50"},
    ]
    scores = scoring.normalized_scores(runs, {"A": 10.0})
    assert scores["s"]["score"] == pytest.approx((0.0 + 0.5) / 2)
    assert scores["t"]["score"] == pytest.approx(1.0)


def test_normalized_scores_refuse_missing_random_or_no_progress():
    with pytest.raises(common.BenchmarkError, match="no random-policy return"):
        scoring.normalized_scores([{"setting": "s", "env": "A", "return_mean": "1"}], {})
    with pytest.raises(common.BenchmarkError, match="beats the random policy"):
        scoring.normalized_scores([{"setting": "s", "env": "A", "return_mean": "1"}], {"A": 5.0})


def test_write_table_keeps_the_paper_column_and_order(tmp_path):
    runs = []
    for name, *_ in table1.SETTINGS:
        value = {"No clipping or penalty": 0.0, "Clipping, ε = 0.2": 200.0}.get(name, 100.0)
        runs.append(recorded_run(name, "A", 1, value))
    write_csv(tmp_path / "runs.csv", runs)
    write_csv(tmp_path / "random.csv", [{"env": "A", "episodes": 100, "seed": 0, "return_mean": 0.0}])
    table = table1.write_table(tmp_path / "runs.csv", tmp_path / "random.csv", tmp_path / "t.csv", ["A"], [1], 5000)
    assert [row["setting"] for row in table] == [name for name, *_ in table1.SETTINGS]
    written = read_rows(tmp_path / "t.csv")
    assert written[0]["score"] == "0.0" and written[0]["paper_score"] == "-0.39"
    assert written[2]["score"] == "1.0" and written[2]["paper_score"] == "0.82"
    assert written[1]["score"] == "0.5"


def test_write_table_scores_only_the_tasks_whose_runs_are_all_recorded(tmp_path):
    run = recorded_run
    clip, cpi = "Clipping, ε = 0.2", "No clipping or penalty"
    runs = [run(clip, "A", 1, 100.0), run(cpi, "A", 1, 50.0), run(clip, "A", 2, 80.0), run(cpi, "A", 2, 40.0)]
    runs += [run(clip, "B", 1, 10.0)]  # B is still running: its best run may not have come yet
    write_csv(tmp_path / "runs.csv", runs)
    write_csv(tmp_path / "random.csv", [{"env": e, "episodes": 100, "seed": 0, "return_mean": 0.0} for e in "AB"])
    args = tmp_path / "runs.csv", tmp_path / "random.csv", tmp_path / "t.csv"
    table = table1.write_table(*args, ["A", "B"], [1, 2], 5000)
    assert {row["setting"]: row["score"] for row in table} == {cpi: round((0.5 + 0.4) / 2, 2), clip: 0.9}
    assert all(row["tasks"] == 1 for row in table)
    assert all(row["task_ids"] == "A" for row in table)
    with pytest.raises(common.BenchmarkError, match="no setting or task has all its runs"):
        table1.write_table(*args, ["B"], [1, 2], 5000)


def test_slug_makes_distinct_folder_names():
    slugs = [table1.slug(name) for name, *_ in table1.SETTINGS]
    assert len(set(slugs)) == len(slugs)
    assert table1.slug("Adaptive KL, d_targ = 0.003") == "adaptive-kl-dtarg-0.003"
    assert table1.slug("Clipping, ε = 0.2") == "clipping-eps-0.2"


# records and the runners' sweeps


def test_compact_progress_rounds_floats_and_keeps_integers(tmp_path):
    fake_run(tmp_path / "run", 2, [1.23456789012, float("nan")])
    common.compact_progress(tmp_path / "run")
    rows = read_rows(tmp_path / "run" / "progress.csv")
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

    def execute(runs, on_result, workers=None, address=None, retries=0, progress=None, task=None):
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
    rows = read_rows(csv_path)
    assert list(rows[0]) == seven_tasks.FIELDS
    assert [(row["env"], row["seed"]) for row in rows] == [
        ("Hopper-v5", "1"),
        ("Hopper-v5", "2"),
        ("Swimmer-v5", "1"),
        ("Swimmer-v5", "2"),
    ]
    assert rows[0]["return_mean"] == "20.0" and rows[0]["steps"] == "4096" and rows[0]["wall_s"] == "2.0"
    assert rows[0]["command"] == f"minippo train Hopper-v5 --steps 4096 --seed 1 --out {runs}/Hopper-v5-seed1 --quiet"
    assert rows[0]["commit"] == common.git_commit()
    assert [run.config.seed for run in stub_engine] == [1, 2, 1, 2]
    assert (runs / "Hopper-v5-seed1" / "curve.png").exists()
    sweep_rows = read_rows(runs / "sweep.csv")  # the engine's own log says where each run ran
    assert [(row["status"], row["node"]) for row in sweep_rows] == [("ok", "n1")] * 4
    assert seven_tasks.main(args) == 0  # everything recorded: nothing runs again
    assert len(stub_engine) == 4 and len(read_rows(csv_path)) == 4


def test_runners_skip_what_the_records_hold(tmp_path, stub_engine):
    csv_path = tmp_path / "mujoco.csv"
    write_csv(csv_path, [dict.fromkeys(seven_tasks.FIELDS, "x") | {"env": "Hopper-v5", "seed": "2"}])
    args = ["--envs", "Hopper-v5", "--seeds", "1", "2", "--steps", "4096", "--csv", str(csv_path)]
    assert seven_tasks.main([*args, "--runs", str(tmp_path / "runs"), "--quiet"]) == 0
    assert [run.config.seed for run in stub_engine] == [1]


def test_ablations_record_each_detail_off_with_the_last_ten_updates(tmp_path, stub_engine, monkeypatch):
    import importlib

    ablations = importlib.import_module("benchmarks.ablations.__main__")
    monkeypatch.setattr(ablations, "HERE", tmp_path)
    monkeypatch.setattr(ablations, "RESULTS", tmp_path / "results.csv")
    assert ablations.main(["--only", "default", "use_gae", "--seeds", "3", "--steps", "4096", "--quiet"]) == 0
    rows = read_rows(tmp_path / "results.csv")
    assert list(rows[0]) == ablations.FIELDS and [row["ablation"] for row in rows] == ["default", "use_gae"]
    assert (rows[0]["override"], rows[1]["override"]) == ("(none)", "use_gae=false")
    assert rows[1]["return_last10"] == "15.0" and rows[1]["return_mean"] == "20.0"  # the stub's updates: 10, 20
    assert rows[1]["command"].endswith(f"--out {tmp_path}/runs/use_gae-seed3 --no-use-gae --quiet")
    assert stub_engine[1].config.use_gae is False and stub_engine[0].config.use_gae is True
    assert ablations.main(["--only", "default", "--seeds", "3", "--steps", "4096", "--quiet"]) == 0
    assert len(stub_engine) == 2  # recorded: not run again


def test_runs_an_interrupted_runner_finished_are_recorded_once(tmp_path):
    """The engine logged two ok runs and a failed one in sweep.csv before the record was written: the next invocation
    copies the ok ones that the record lacks, and only once."""
    runs = seven_tasks.sweep_runs(["Hopper-v5"], [1, 2, 3], 4096)
    for seed in (1, 2):
        fake_run(tmp_path / f"Hopper-v5-seed{seed}", 2, [1.23456789, 2.0 + seed])
    row = {"env": "Hopper-v5", "steps": "4096", "wall_s": "2.04", "steps_per_s": "2000.04", "commit": "c"}
    log = [{**row, "seed": str(seed), "return_mean": str(2.0 + seed), "status": status, "command": f"train {seed}"}
           for seed, status in ((1, "ok"), (2, "ok"), (3, "failed"))]  # fmt: skip
    write_csv(tmp_path / "sweep.csv", log)
    record = tmp_path / "mujoco.csv"
    append_row(record, seven_tasks.FIELDS, {**row, "seed": 2, "return_mean": 4.0, "command": "train 2"})
    assert common.record_sweep(runs, tmp_path, record, seven_tasks.FIELDS) == 1
    assert common.record_sweep(runs, tmp_path, record, seven_tasks.FIELDS) == 0
    recorded = [(r["seed"], r["return_mean"], r["command"]) for r in read_rows(record)]
    assert recorded == [("2", "4.0", "train 2"), ("1", "3.0", "train 1")]
    assert read_rows(tmp_path / "Hopper-v5-seed1" / "progress.csv")[0]["return_mean"] == "1.23457"  # rounded
    assert [run.labels["seed"] for run in common.todo(runs, record, seven_tasks.FIELDS)] == [3]


def test_table1_sweep_makes_the_commands_of_its_records():
    """The runs the sweep describes are the trainings whose commands the 1M-step Table 1 records hold (the KL rows
    among the stale ones being rerun), which the earlier runner started with one BLAS thread set in the environment,
    which minippo sets itself, and with the setting's words (--objective, --config), where the sweep now writes every
    changed field's own option: the same Config, into the same folder."""
    recorded = {
        (row["setting"], row["env"], row["seed"]): row["command"]
        for path in (common.RESULTS / "table1_1m_runs.csv", common.RESULTS / "stale" / "table1_1m_runs.csv")
        for row in read_rows(path)
    }
    runs = table1.sweep_runs(table1.SETTINGS, ["HalfCheetah-v5", "Hopper-v5"], [1, 2], 1_000_000)
    assert len(runs) == 11 * 2 * 2 and runs[0].labels == {
        "setting": table1.SETTINGS[0][0],
        "env": "HalfCheetah-v5",
        "seed": 1,
    }
    for run in runs:
        recorded_words = shlex.split(recorded[tuple(str(v) for v in run.labels.values())].split("minippo train ")[1])
        words = shlex.split(run.command("benchmarks/runs/table1_1m"))[2:]
        assert train_config(recorded_words) == train_config(words) == run.config
        assert recorded_words[recorded_words.index("--out") + 1] == words[words.index("--out") + 1]
    fixed = next(run for run in runs if run.labels["setting"] == "Fixed KL, β = 3")
    assert (fixed.config.objective, fixed.config.adaptive_kl, fixed.config.kl_beta) == ("klpen", False, 3.0)


def test_table1_overrides_join_each_settings_config():
    cpi, clip = table1.SETTINGS[0], table1.SETTINGS[2]
    extra = ["grad_norm_clipping=false", "anneal_lr=false"]
    assert table1.with_overrides(cpi, extra) == ("No clipping or penalty", "cpi", extra)
    assert table1.with_overrides(clip, extra) == ("Clipping, ε = 0.2", "clip", ["clip_epsilon=0.2", *extra])
    assert table1.with_overrides(clip, []) == clip
    (run,) = table1.sweep_runs([table1.with_overrides(cpi, extra)], ["Hopper-v5"], [1], 4096)
    assert run.command("runs").endswith("--objective cpi --no-anneal-lr --no-grad-norm-clipping --quiet")


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


@pytest.mark.slow  # two training runs, one from a checkout
def test_same_math_finds_no_difference_between_a_commit_and_itself(tmp_path):
    """The real script, end to end: HEAD in a worktree against the working tree, two CartPole updates. The same code
    on the same machine gives the same numbers, so every difference is exactly zero."""
    from benchmarks import same_math

    if common.git_commit().endswith("+dirty"):
        pytest.skip("minippo/ has uncommitted edits, so HEAD is not the code that runs")
    record = tmp_path / "same.csv"
    assert same_math.main(["HEAD", "--env", "CartPole-v1", "--updates", "2", "--csv", str(record)]) == 0
    rows = read_rows(record)
    assert [row["update"] for row in rows] == ["1", "2"]
    assert all(float(row["max_relative_difference"]) == 0.0 for row in rows)
    assert rows[0]["return_mean_earlier"] == rows[0]["return_mean_current"] != ""


def test_same_math_refuses_an_unknown_commit_on_one_line(capsys, tmp_path):
    from benchmarks import same_math

    with pytest.raises(SystemExit) as stop:
        same_math.main(["no-such-commit", "--csv", str(tmp_path / "x.csv")])
    assert stop.value.code != 0
    error = capsys.readouterr().err.strip()
    assert error.endswith(": error: no commit named 'no-such-commit' in this repository") and "\n" not in error
    assert not (tmp_path / "x.csv").exists()


# the other tables and the report


def test_records_on_one_scale_share_the_best_run_over_tasks_complete_in_each():
    run = table1_run
    clip, beta, cpi = "Clipping, ε = 0.2", "Fixed KL, β = 3", "No clipping or penalty"
    default = [run(clip, "Hopper-v5", 1, 60), run(clip, "Hopper-v5", 2, 40), run(beta, "Hopper-v5", 1, 90)]
    default += [run(beta, "Hopper-v5", 2, 70), run(cpi, "Hopper-v5", 1, 110), run(cpi, "Hopper-v5", 2, 10)]
    default += [run(clip, "Swimmer-v5", 1, 50), run(beta, "Swimmer-v5", 1, 50)]  # Swimmer lacks seed 2 and cpi
    other = [run(clip, "Hopper-v5", 1, 80), run(clip, "Hopper-v5", 2, 60), run(beta, "Hopper-v5", 1, 30)]
    other += [run(beta, "Hopper-v5", 2, 10), run(clip, "Swimmer-v5", 1, 999)]  # Swimmer incomplete: not in the best
    rows = scoring.on_one_scale({"defaults": default, "other": other}, random_rows(["Hopper-v5", "Swimmer-v5"]))
    got = {(row["setting"], row["record"]): row["score"] for row in rows}
    # Hopper only: random 10, best 110 (the defaults' unclipped seed 1), so a return r scores (r − 10) / 100
    assert got == {(cpi, "defaults"): 0.5, (clip, "defaults"): 0.4, (clip, "other"): 0.6,
                   (beta, "defaults"): 0.7, (beta, "other"): 0.1}  # fmt: skip
    assert [row["setting"] for row in rows] == [cpi, clip, clip, beta, beta]  # Table 1's order
    assert all(row["tasks"] == 1 for row in rows)
    assert scoring.on_one_scale({"defaults": default, "other": []}, random_rows(["Hopper-v5"])) == []


def test_the_one_detail_table_reads_each_record_on_the_tasks_run_one_detail_at_a_time():
    def run(env_id, seed, value):
        return table1_run("No clipping or penalty", env_id, seed, value)

    records = {"all on": [run("Hopper-v5", 1, 100), run("Hopper-v5", 2, 200), run("Swimmer-v5", 1, 5)]}
    records["clip_value_loss off"] = [run("Hopper-v5", 1, 1000), run("Hopper-v5", 2, 900)]
    records["all off"] = [run("Hopper-v5", 1, 1000)]
    (row,) = scoring.one_detail(records)
    assert row["task"] == "Hopper-v5" and row["all on"] == 150.0 and row["all on seeds"] == 2
    assert row["clip_value_loss off"] == 950.0 and row["all off"] == 1000.0 and row["all off seeds"] == 1


def test_the_seven_task_table_compares_with_the_paper_and_cleanrl():
    rows = [{"env": "Hopper-v5", "seed": str(s), "return_mean": str(v), "wall_s": "60", "commit": "abc"}
            for s, v in ((2, 2400.0), (1, 2100.0), (3, 2700.0))]  # fmt: skip
    rows.append({"env": "Swimmer-v5", "seed": "1", "return_mean": "50", "wall_s": "30", "commit": "def"})
    hopper, swimmer = scoring.seven_tasks(rows, "r.csv")
    assert (hopper["mean"], hopper["sd"], hopper["returns"]) == (2400.0, 300.0, "2100.0 2400.0 2700.0")
    assert hopper["at_or_above_paper"] == "yes" and hopper["cleanrl"] == "2383 ± 272" and hopper["minutes"] == 1.0
    assert swimmer["at_or_above_paper"] == "no" and swimmer["cleanrl"] == "—" and swimmer["sd"] == 0.0


def test_welch_interval_against_scipys_welch_test():
    from scipy import stats

    first, second = [10.0, 12.0, 15.0, 11.0], [4.0, 9.0, 5.0]
    interval = scoring.welch_interval(first, second)
    # the interval's edges are where Welch's two-sided test of the shifted difference has p = 0.05
    for edge in (interval["low"], interval["high"]):
        shifted = [value - edge for value in first]
        assert stats.ttest_ind(shifted, second, equal_var=False).pvalue == pytest.approx(0.05, rel=1e-6)
    assert interval["diff"] == pytest.approx(12.0 - 6.0) and interval["standing"] == "ahead"
    assert scoring.welch_interval(second, first)["standing"] == "behind"
    assert scoring.welch_interval([1.0, 2.0], [1.5, 1.6])["standing"] == "level"
    with pytest.raises(ValueError):
        scoring.welch_interval([1.0], [2.0, 3.0])


def test_same_math_table_says_where_the_runs_part():
    def row(update, difference):
        return {"env": "Hopper-v5", "seed": "1", "dtype": "float64", "update": str(update), "earlier_commit": "a",
                "commit": "b", "max_relative_difference": str(difference), "command": "c"}  # fmt: skip

    (parted,) = scoring.same_math([row(2, 3e-3), row(1, 1e-15), row(3, 0.2), row(4, 0.01)])
    assert parted["difference_at_update_1"] == "1e-15" and parted["parted_at_update"] == 3 and parted["updates"] == 4
    (together,) = scoring.same_math([row(1, 4e-16), row(2, 2e-11)])
    assert together["parted_at_update"] == ""


def test_the_report_writes_a_paragraph_and_a_table_for_each_section():
    tables = {name: [] for name in report.COLUMNS}
    tables["same_math"] = [{"env": "E", "seed": "1", "dtype": "float64", "earlier_commit": "a", "commit": "b",
                            "difference_at_update_1": "1e-15", "parted_at_update": 3}]  # fmt: skip
    text = report.summary_text(tables)
    assert text.count("\n## ") == len(report.COLUMNS) and "<!-- table:" not in text
    assert "| E | 1 | float64 | a → b | 1e-15 | 3 |" in text
    assert text.count("No complete record yet.") == len(report.COLUMNS) - 1


def test_the_readme_shows_what_the_committed_records_say(tmp_path):
    text = (common.ROOT / "README.md").read_text()
    tables = scoring.score_all(folder=tmp_path)  # the committed tables are not touched
    blocks = report.readme_blocks(tables, read_rows(common.RESULTS / "speed.csv"))
    assert set(blocks) == {"mujoco", "speed"}
    assert report.fill_readme(text, blocks) == text, "run `python -m benchmarks.report`"
    for path in tmp_path.iterdir():  # and the committed tables are what the records give
        assert path.read_text() == (scoring.TABLES / path.name).read_text(), f"{path.name}: run the report"


def test_readme_blocks_are_replaced_and_a_missing_block_is_named():
    text = "intro\n<!-- summary:speed -->\nold\nlines\n<!-- /summary:speed -->\nrest\n"
    expected = "intro\n<!-- summary:speed -->\nnew\n<!-- /summary:speed -->\nrest\n"
    assert report.fill_readme(text, {"speed": "new"}) == expected
    with pytest.raises(ValueError, match="table1"):
        report.fill_readme(text, {"table1": "x"})


def test_the_one_commit_rerun_reproduces_table1s_default_runs():
    """The seven tasks at one commit, seeds 1-3, are the ε = 0.2 runs of Table 1's record, to the recorded digit:
    the same command, the same machine kind, code that computes the same training."""
    rerun = {(r["env"], r["seed"]): r for r in read_rows(common.RESULTS / "seven_tasks_runs.csv")}
    table = [r for r in read_rows(common.RESULTS / "table1_1m_runs.csv") if r["setting"] == "Clipping, ε = 0.2"]
    shared = [(row, rerun[(row["env"], row["seed"])]) for row in table if (row["env"], row["seed"]) in rerun]
    assert len(shared) >= 12 and len({row["commit"] for _, row in shared}) == 1
    assert all(old["return_mean"] == new["return_mean"] for old, new in shared)


# the MinAtar campaign


def test_minatar_sweep_runs_each_game_with_both_presets():
    from benchmarks import minatar

    runs = minatar.sweep_runs(["PPO", "A2C"], ["MinAtar/Breakout-v1"], [1, 2], 20_480)
    assert [run.labels["algorithm"] for run in runs] == ["PPO", "A2C", "PPO", "A2C"]
    ppo, a2c = runs[0].config, runs[1].config
    assert (ppo.objective, ppo.num_envs, ppo.horizon, ppo.epochs, ppo.anneal_clip) == ("clip", 8, 128, 3, True)
    assert (a2c.objective, a2c.epochs, a2c.minibatch_size) == ("pg", 1, a2c.num_envs * a2c.horizon)
    assert "Breakout-v1" in runs[0].name and "--network minatar_cnn" in runs[0].command("runs")


def test_minatar_ablation_changes_one_setting_over_the_preset_and_names_it():
    from benchmarks import minatar

    runs = minatar.sweep_runs(["A2C"], ["MinAtar/Breakout-v1"], [3], 20_480, ["lr=0.00025"])
    (run,) = runs
    assert run.config.lr == 2.5e-4 and (run.config.objective, run.config.horizon) == ("pg", 5)  # the rest is A2C's
    assert run.name == "a2c-MinAtar-Breakout-v1-lr=0.00025-seed3"
    words = shlex.split(run.command("runs"))[2:]  # every field A2C and the ablation change, by its own option
    assert train_config(words) == run.config and words[words.index("--lr") + 1] == "0.00025"
    assert minatar.sweep_runs(["A2C"], ["MinAtar/Breakout-v1"], [3], 20_480)[0].name == "a2c-MinAtar-Breakout-v1-seed3"


def test_minatar_table_scores_both_ways_and_counts_wins(tmp_path):
    from benchmarks import minatar
    from minippo.checkpoint import save_checkpoint

    def fake(algorithm, seed, returns):
        folder = tmp_path / "runs" / minatar.run_name(algorithm, "MinAtar/Breakout-v1", seed)
        folder.mkdir(parents=True)
        episodes = {"returns": np.array(returns, float), "lengths": np.ones(len(returns), int)}
        save_checkpoint(folder / "checkpoint.npz", {"update": 1, "rollout": episodes})  # a Trainer's, in part
        minatar.write_episodes(folder)
        return {"algorithm": algorithm, "env": "MinAtar/Breakout-v1", "seed": seed}

    # PPO ahead over all of training (mean 2 against 1.75), A2C over the last 100 episodes (3.5 against 3)
    rows = [fake("PPO", 1, [1.0] * 100 + [3.0] * 100), fake("A2C", 1, [0.0] * 100 + [3.5] * 100)]
    write_csv(tmp_path / "runs.csv", rows)
    table = minatar.write_table(
        tmp_path / "runs.csv", tmp_path / "runs", tmp_path / "t.csv", ["MinAtar/Breakout-v1"], [1]
    )
    row = table[0]
    assert (row["PPO_all_training"], row["PPO_last_100"]) == (2.0, 3.0)
    assert (row["A2C_all_training"], row["A2C_last_100"]) == (1.75, 3.5)
    assert (row["winner_all_training"], row["winner_last_100"]) == ("PPO", "A2C")
    assert read_rows(tmp_path / "t.csv")[0]["winner_last_100"] == "A2C"
