"""minippo doctor: the broken CartPole run is named, healthy runs are not, SB3's log is read, bad input exits 2."""

import json
import math
from pathlib import Path

import pytest

from minippo.cli import main
from minippo.config import Config
from minippo.doctor import ANCHORS, MIN_UPDATES, RULES, RULES_BY_SOURCE, UNCALIBRATED, WINDOWS, Rule, diagnose, read_run
from minippo.errors import MinippoError
from minippo.ppo import train
from minippo.presets import CARTPOLE_PPO
from minippo.records import write_rows
from minippo.run_folder import PROGRESS_FIELDS

SB3_RUN = Path(__file__).resolve().parent / "data" / "sb3_cartpole"  # made by tests/data/make_sb3_log.py
STEP_SIZE_CAUSES = ("step size", "epochs")
STEP_SIZE_RULES = {"kl-spike", "kl-high", "clip-high"}  # the rules whose likeliest causes are α, K or M


def cartpole(folder: Path, seed: int, **changes) -> Path:
    """The book's CartPole setting for 20,480 steps (40 updates of 512), with ``changes``; its run folder."""
    train(Config(**{**CARTPOLE_PPO, **changes}, total_steps=20480, seed=seed), folder)
    return folder


@pytest.fixture(scope="module")
def broken_run(tmp_path_factory):  # a step size 100× the book's (2.5e-4) and 40 epochs on each batch
    return cartpole(tmp_path_factory.mktemp("broken"), seed=1, lr=0.025, epochs=40)


def progress(folder: Path, rows: list[dict]) -> Path:
    """A minippo progress.csv of ``rows`` (the unnamed columns 0) in ``folder``."""
    folder.mkdir(exist_ok=True)
    write_rows(folder / "progress.csv", PROGRESS_FIELDS, [{key: row.get(key, 0) for key in PROGRESS_FIELDS}
                                                          for row in rows])  # fmt: skip
    return folder


def steady(n: int, **values) -> list[dict]:
    """n updates of a run whose debug variables sit in the healthy ranges, with ``values`` (a number or a list)."""
    base = dict(approx_kl=0.003, clip_fraction=0.05, entropy=0.6, value_loss=20.0, explained_variance=0.5)
    rows = [{"update": i + 1, "step": 512 * (i + 1), "return_mean": 20.0 + i, **base} for i in range(n)]
    for key, value in values.items():
        for i, row in enumerate(rows):
            row[key] = value[i] if isinstance(value, list) else value
    return rows


def test_the_rule_table_is_well_formed():
    assert len({rule.id for rule in RULES}) == len(RULES)
    for rule in RULES:
        assert rule.window in WINDOWS and rule.anchor in ANCHORS and rule.comparison in "<>" and rule.causes
        assert (rule.level is not None) == (rule.statistic == "fraction above")
        assert not rule.holds(rule.healthy[0]) and not rule.holds(rule.healthy[1]), rule.id


def test_the_evaluator_reads_the_window_and_the_statistic():
    rows = steady(40, approx_kl=[0.0] * 30 + [0.5] * 10)
    late = Rule("late", "approx_kl", "the last quarter", "min", ">", 0.1, ("x",), "atlas-step-size", (0, 0.1))
    early = Rule("early", "approx_kl", "updates 1-10", "max", ">", 0.1, ("x",), "atlas-step-size", (0, 0.1))
    share = Rule("share", "approx_kl", "all updates", "fraction above", ">", 0.2, ("x",), "atlas-step-size",
                 (0, 0.1), level=0.1)  # fmt: skip
    found = diagnose(rows, rules=(late, early, share))
    assert [f.rule.id for f in found] == ["late", "share"]
    assert (found[0].first_update, found[0].last_update, found[0].value) == (31, 40, 0.5)
    assert found[1].value == pytest.approx(0.25)


@pytest.mark.slow  # trains the broken run (broken_run)
def test_the_broken_cartpole_run_names_the_step_size_or_the_epochs_first(broken_run, capsys):
    kind, rows = read_run(broken_run)
    assert kind == "minippo" and len(rows) == 40
    findings = diagnose(rows)
    assert findings and any(word in findings[0].rule.causes[0] for word in STEP_SIZE_CAUSES)
    assert main(["doctor", str(broken_run)]) == 1
    out = capsys.readouterr().out
    assert findings[0].rule.causes[0] in out and f"#{findings[0].rule.anchor}" in out


# one seed in the quick tier, the other two (training runs of 40 updates each) in the slow one
@pytest.mark.parametrize("seed", [1, pytest.param(2, marks=pytest.mark.slow), pytest.param(3, marks=pytest.mark.slow)])
def test_healthy_short_cartpole_runs_raise_no_alarm(tmp_path, seed, capsys):
    run = cartpole(tmp_path / "healthy", seed)
    assert diagnose(read_run(run)[1]) == []
    assert main(["doctor", str(run)]) == 0
    out = capsys.readouterr().out
    assert "no failure signature found in 40 updates" in out and "healthy runs:" in out


def test_a_stable_baselines3_log_is_read_in_minippos_names_and_units():
    kind, rows = read_run(SB3_RUN)
    assert kind == "sb3" and len(rows) == 19  # 20 iterations logged; the last one's update was never logged
    assert [row["update"] for row in rows] == list(range(1, 20))
    assert [row["step"] for row in rows] == [256 * i for i in range(1, 20)]
    import csv

    with open(SB3_RUN / "progress.csv", newline="") as handle:
        table = list(csv.DictReader(handle))
    assert rows[0]["entropy"] == pytest.approx(-float(table[1]["train/entropy_loss"]))  # update 1: logged in row 2
    assert rows[0]["value_loss"] == pytest.approx(float(table[1]["train/value_loss"]) / 2)
    assert rows[0]["return_mean"] == pytest.approx(float(table[0]["rollout/ep_rew_mean"]))  # its own rollout's
    assert 0.6 < rows[0]["entropy"] < math.log(2) + 1e-6


def test_the_doctor_reads_a_stable_baselines3_log_from_the_command_line(capsys):
    assert main(["doctor", str(SB3_RUN), "--json"]) in (0, 1)
    report = json.loads(capsys.readouterr().out)
    assert report["format"] == "sb3" and report["updates"] == 19
    assert {check["id"] for check in report["checked"]} == {rule.id for rule in RULES_BY_SOURCE["sb3"]}
    assert set(report["uncalibrated"]) == set(UNCALIBRATED["sb3"])  # said, not passed over in silence


def test_json_names_each_finding_with_its_section(tmp_path, capsys):
    run = progress(tmp_path / "run", steady(40, approx_kl=0.0))  # a policy whose logged KL is exactly 0
    assert main(["doctor", str(run), "--json"]) == 1
    report = json.loads(capsys.readouterr().out)
    first = report["findings"][0]
    assert first["variable"] == "approx_kl" and first["read"].endswith("#" + first["anchor"])


def bad_inputs(tmp_path: Path) -> dict:
    (tmp_path / "empty").mkdir()
    (tmp_path / "garbage").mkdir()
    (tmp_path / "garbage" / "progress.csv").write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\xff\xfe")
    (tmp_path / "zero").mkdir()
    (tmp_path / "zero" / "progress.csv").write_text("")
    (tmp_path / "unknown").mkdir()
    (tmp_path / "unknown" / "progress.csv").write_text("epoch,loss,accuracy\n1,0.5,0.9\n")
    (tmp_path / "words").mkdir()
    write_rows(tmp_path / "words" / "progress.csv", PROGRESS_FIELDS, [dict.fromkeys(PROGRESS_FIELDS, "many")])
    progress(tmp_path / "short", steady(MIN_UPDATES - 1))
    return {
        "missing": ("no run folder",),
        "empty": ("has no progress.csv", "TensorBoard"),
        "garbage": ("cannot read",),
        "zero": ("is empty",),
        "unknown": ("none of the columns",),
        "words": ("'many' is not a number",),
        "short": (f"{MIN_UPDATES - 1} updates are too few", f"at least {MIN_UPDATES}"),
    }


@pytest.mark.parametrize("name", ["missing", "empty", "garbage", "zero", "unknown", "words", "short"])
def test_bad_input_exits_2_with_one_line(tmp_path, name, capsys):
    fragments = bad_inputs(tmp_path)[name]
    with pytest.raises(MinippoError):
        diagnose(read_run(tmp_path / name)[1])
    assert main(["doctor", str(tmp_path / name)]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert captured.out == "" and len(lines) == 1 and lines[0].startswith("minippo: error: "), captured
    assert all(fragment in lines[0] for fragment in fragments), lines[0]


def test_an_empty_column_is_reported_as_missing_not_as_healthy(tmp_path, capsys):
    run = progress(tmp_path / "run", steady(40, explained_variance=""))  # a log whose explained variance is blank
    assert main(["doctor", str(run)]) == 3  # no finding, but not every rule checked: not the clean bill of 0
    out = capsys.readouterr().out
    assert "not enough data for rule critic-worse-than-constant: column explained_variance is empty" in out
    assert f"by the {len(RULES) - 1} rules of {len(RULES)} that could be checked" in out and "nan" not in out.lower()
    assert "note: explained_variance has no value on any of the 40 updates" in out
    assert main(["doctor", str(run), "--json"]) == 3
    text = capsys.readouterr().out
    report = json.loads(text, parse_constant=lambda name: pytest.fail(f"{name} in the JSON"))  # strict JSON
    assert report["not_checked"] == ["critic-worse-than-constant"]
    check = next(c for c in report["checked"] if c["id"] == "critic-worse-than-constant")
    assert check["value"] is None and check["missing"].endswith("is empty") and check["found"] is False


def test_a_log_with_no_data_for_any_rule_is_bad_input(tmp_path, capsys):
    empty = dict.fromkeys(("return_mean", "approx_kl", "clip_fraction", "entropy", "value_loss", "explained_variance"),
                          "")  # fmt: skip
    run = progress(tmp_path / "run", steady(20, **empty))
    assert main(["doctor", str(run)]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1
    assert captured.err.startswith("minippo: error: ") and "not enough data for any rule" in captured.err
    assert "column approx_kl is empty" in captured.err and "column explained_variance is empty" in captured.err


def test_a_last_line_cut_short_is_not_counted(tmp_path, capsys):
    run = progress(tmp_path / "run", steady(12))
    with open(run / "progress.csv", "a") as handle:
        handle.write("13,6656,0,32.0,32.0,0.0")  # a run killed while it wrote update 13's row
    kind, rows = read_run(run)
    assert len(rows) == 12 and rows[-1]["update"] == 12
    assert main(["doctor", str(run)]) == 0
    out = capsys.readouterr().out
    assert "12 updates" in out and "has no line end (the run stopped mid-write): dropped, not counted" in out


def test_a_short_row_inside_the_file_is_bad_input(tmp_path):
    run = progress(tmp_path / "run", steady(12))
    lines = (run / "progress.csv").read_text().splitlines(keepends=True)
    lines[5] = "5,2560,0\n"
    (run / "progress.csv").write_text("".join(lines))
    with pytest.raises(MinippoError, match=r"line 6: 3 fields, the header has 15"):
        read_run(run)


def test_a_reader_that_goes_away_ends_the_doctor_quietly(tmp_path):
    import os
    import subprocess
    import sys

    run = progress(tmp_path / "run", steady(40))
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    doctor = subprocess.Popen([sys.executable, "-m", "minippo", "doctor", str(run)], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE)  # fmt: skip
    doctor.stdout.close()  # the reader is gone before the report is written, as after `| head -1`'s line
    errors = doctor.stderr.read().decode()
    assert doctor.wait(timeout=120) == 141 and errors == ""  # 128 + SIGPIPE, as a command SIGPIPE ends


# the atlas (benchmarks/atlas.py): what the doctor says of its recorded runs, and of short CartPole runs with its faults

ATLAS_RUNS = Path(__file__).resolve().parents[1] / "benchmarks" / "results" / "atlas_runs.csv"
# (mode, task): the rule the doctor must name first on each of the mode's three recorded seeds (whole runs)
FIRST_RULE = {
    ("lr_10x", "Hopper-v5"): "kl-spike",
    ("lr_100x_epochs_40", "CartPole-v1"): "kl-spike",
    ("minibatch_whole", "CartPole-v1"): "policy-barely-moves",
    ("value_loss_sign", "CartPole-v1"): "value-loss-grows",
    ("value_loss_sign", "Hopper-v5"): "critic-worse-than-constant",
    ("entropy_too_large", "Hopper-v5"): "entropy-rises",
    ("log_prob_wrong_axis", "Hopper-v5"): "entropy-rises",
    ("no_reward_scaling", "Hopper-v5"): "value-loss-grows",
    ("ratio_vs_current_policy", "CartPole-v1"): "policy-never-moves",
    ("ratio_vs_current_policy", "Hopper-v5"): "policy-never-moves",
}


def atlas_runs() -> dict:
    from minippo.records import read_rows

    runs = {}
    for row in read_rows(ATLAS_RUNS):
        numbers = {key: float(value) for key, value in row.items() if key not in ("mode", "task", "seed")}
        runs.setdefault((row["mode"], row["task"], row["seed"]), []).append(numbers)
    return runs


def test_the_atlas_runs_are_named_by_their_rule_and_no_healthy_run_is_flagged():
    runs = atlas_runs()
    healthy = [key for key in runs if key[0] == "healthy"]
    assert {task for _, task, _ in healthy} == {"CartPole-v1", "Hopper-v5", "MinAtar/Breakout-v1"}
    for key in healthy:
        for cut in (10, 15, 40, None):  # short runs too: a healthy start must not look like a failure
            assert diagnose(runs[key][:cut]) == [], (key, cut)
    for (mode, task), rule in FIRST_RULE.items():
        seeds = [key for key in runs if key[:2] == (mode, task)]
        assert len(seeds) == 3, (mode, task)
        for key in seeds:
            found = diagnose(runs[key])
            assert found and found[0].rule.id == rule, (key, [f.rule.id for f in found])


@pytest.mark.parametrize(
    "mode, updates, rules",
    [
        ("lr_100x_epochs_40", 25, STEP_SIZE_RULES),  # over 10 updates its KL (about 0.02) is within the margin
        ("ratio_vs_current_policy", 10, {"policy-never-moves"}),
        ("minibatch_whole", 10, {"policy-barely-moves"}),
        # the value loss grows slowly: the atlas's length (150 updates of training: a slow test)
        pytest.param("value_loss_sign", 150, {"value-loss-grows"}, marks=pytest.mark.slow),
    ],
)
def test_a_short_cartpole_run_with_a_fault_is_named_by_its_rule(mode, updates, rules, tmp_path):
    from benchmarks import atlas

    fault = atlas.FAULTS[mode]
    config = fault.configure(Config(**CARTPOLE_PPO, seed=4, total_steps=updates * 512))
    with fault.injected_into():
        train(config, tmp_path)
    found = diagnose(read_run(tmp_path)[1])
    assert found and found[0].rule.id in rules, [f.rule.id for f in found]
