"""The doctor's thresholds: set on calibration runs only, between the healthy runs and the broken ones, read back by
the doctor; its new rules on runs made of rows; evaluate's confusion counts."""

import csv
import hashlib
import json
import math

import numpy as np
import pytest

from benchmarks import doctor_calibrate as dc
from benchmarks import doctor_confusion
from minippo import doctor
from minippo.records import read_rows, write_rows
from minippo.run_folder import PROGRESS_FIELDS

N = 40  # updates of a synthetic run


def rows_of(n: int = N, **values) -> list[dict]:
    """n updates whose debug variables sit in the healthy ranges, a learning return and a slowly falling entropy,
    with ``values`` (a number or a list) instead."""
    rows = [{"update": i + 1, "step": 512 * (i + 1), "return_mean": 20.0 + 5 * i, "approx_kl": 0.004 + 0.001 * (i % 3),
             "clip_fraction": 0.05 + 0.01 * (i % 2), "entropy": 0.69 - 0.005 * i, "value_loss": 20.0,
             "explained_variance": 0.5} for i in range(n)]  # fmt: skip
    for key, value in values.items():
        for i, row in enumerate(rows):
            row[key] = value[i] if isinstance(value, (list, np.ndarray)) else value
    return rows


# (fault, part, rows): a small campaign, each fault's signature plain
CAMPAIGN = [
    ("healthy", "calibration", rows_of()),
    ("healthy", "calibration", rows_of(approx_kl=0.008, clip_fraction=0.1, entropy=list(np.linspace(0.69, 0.3, N)))),
    ("clip_10", "calibration", rows_of(approx_kl=0.5, clip_fraction=0.001)),
    ("lr_x30", "calibration", rows_of(approx_kl=0.09, clip_fraction=0.35)),
    ("ent_-0.05", "calibration", rows_of(entropy=list(np.linspace(0.69, 0.01, N)), return_mean=20.0)),
    ("reward_zero", "calibration", rows_of(return_mean=0.0, explained_variance=-3.0)),
    ("vf_0", "calibration", rows_of(explained_variance=-3.0)),
    ("healthy", "held-out", rows_of(approx_kl=0.9, clip_fraction=0.9, entropy=0.01, explained_variance=-50.0)),
]
CAUSES = {"healthy": "", "clip_10": "no-clip", "lr_x30": "kl-spike", "ent_-0.05": "entropy-collapse",
          "reward_zero": "not-ppo-reward", "vf_0": "critic-worse-than-constant"}  # fmt: skip


def campaign(root, runs=CAMPAIGN):
    """A manifest, a record and run folders (minippo's progress.csv) of ``runs`` under ``root``."""
    entries = []
    for number, (fault, part, rows, *library) in enumerate(runs):
        library = library[0] if library else "minippo"
        run_id = f"{library}-defaults-CartPole-v1-{fault}-1x-seed{number}"
        folder = root / "runs" / run_id
        folder.mkdir(parents=True)
        write_rows(folder / "progress.csv", PROGRESS_FIELDS,
                   [{key: row.get(key, 0) for key in PROGRESS_FIELDS} for row in rows])  # fmt: skip
        entries.append({"id": run_id, "part": part, "library": library, "settings": "defaults",
                        "task": "CartPole-v1", "fault": fault, "cause": CAUSES[fault]})  # fmt: skip
    write_rows(root / "manifest.csv", list(entries[0]), entries)
    (root / "record.json").write_text(json.dumps({"commands": [], "runs": [{"id": e["id"]} for e in entries]}))
    return root / "runs", root / "record.json", root / "manifest.csv"


def calibrated_rules(root, runs=CAMPAIGN) -> tuple:
    folder, record, manifest = campaign(root, runs)
    table = dc.calibrate(folder, record, manifest, None, root / "thresholds.json", [])
    return doctor.calibrated(doctor.SIGNATURES, table), table


def test_calibrate_never_opens_a_held_out_run_and_its_extremes_move_no_threshold(tmp_path, monkeypatch):
    opened = []
    read_log = dc.read_log
    monkeypatch.setattr(dc, "read_log", lambda path: opened.append(path.name) or read_log(path))
    _, with_held_out = calibrated_rules(tmp_path / "with")
    assert opened and not any("seed7" in name for name in opened)  # the held-out run's folder
    _, without = calibrated_rules(tmp_path / "without", CAMPAIGN[:-1])
    assert with_held_out["sources"] == without["sources"]
    assert with_held_out["runs"]["calibration"]["campaign healthy"] == 2
    assert with_held_out["runs"]["held-out"] == {"read": 0, "in the manifest": 1}


def test_thresholds_refuse_a_run_of_another_part():
    run = dc.Run("x", "campaign", "held-out", "minippo", "CartPole-v1", "healthy", "", rows_of())
    with pytest.raises(dc.common.BenchmarkError, match="calibration runs only"):
        dc.thresholds([run])


def test_a_cut_lies_between_the_healthy_extreme_and_the_nearest_broken_run():
    geometric = dc.cut([0.001, 0.01], [0.04, 0.5], ">", "log")
    assert geometric["threshold"] == pytest.approx(0.02) and geometric["basis"] == "midpoint"
    assert dc.cut([-0.1, 0.5], [-2.0, -3.0], "<", "linear")["threshold"] == pytest.approx(-1.05)
    near = dc.cut([0.001, 0.01], [0.015, 0.5], ">", "log")  # within a factor 2: the margin wins, 0.015 is missed
    assert near["threshold"] == pytest.approx(0.02) and near["basis"].startswith("margin")
    zero = dc.cut([0.02, 0.5], [0.0], "<", "log")  # 0 counts as FLOOR on a log scale
    assert zero["threshold"] == pytest.approx(math.sqrt(0.02 * dc.FLOOR))


def test_each_calibrated_threshold_lies_between_its_healthy_and_broken_runs(tmp_path):
    _, table = calibrated_rules(tmp_path)
    assert {"not-ppo-reward", "no-clip", "kl-spike", "entropy-collapse", "critic-worse-than-constant"} <= set(
        table["sources"]["minippo"])
    # the healthy run nearest the threshold is named: the second healthy run, whose KL is the higher throughout
    assert table["sources"]["minippo"]["kl-spike"]["healthy_extreme"] == "minippo-defaults-CartPole-v1-healthy-1x-seed1"
    for rule in doctor.SIGNATURES:
        entry = table["sources"]["minippo"].get(rule.id)
        for condition, part in zip(rule.conditions, [entry, entry and entry.get("also")]):
            if part is None:
                continue
            test = doctor.Condition(condition.variable, condition.window, condition.statistic, condition.comparison,
                                    part["threshold"])  # fmt: skip
            if part["nearest_negative"] is not None:  # what it must not flag, it does not
                assert not test.holds(part["nearest_negative"]), rule.id
            if part["basis"] == "midpoint":  # strictly between that and the nearest broken run, which it flags
                low, high = sorted([part["nearest_negative"], part["nearest_broken"]])
                assert low < part["threshold"] < high and test.holds(part["nearest_broken"]), rule.id
    kl = table["sources"]["minippo"]["kl-spike"]  # the healthy runs' largest KL 0.008, the step size's 0.09:
    # their geometric mean
    assert kl["threshold"] == pytest.approx(math.sqrt(0.008 * 0.09)) and kl["healthy"][1] == pytest.approx(0.008)


def test_the_shipped_thresholds_cover_every_rule_and_flag_no_healthy_extreme():
    table = doctor.load_thresholds()
    assert set(table["sources"]) == set(doctor.RULES_BY_SOURCE)  # each source calibrated on its own runs
    assert doctor.UNCALIBRATED["minippo"] == () and len(doctor.RULES) == len(doctor.SIGNATURES)
    assert {"command", "commit", "date", "runs", "principle"} <= set(table)
    assert table["runs"]["held-out"]["read"] == 0
    for rule in (rule for rules in doctor.RULES_BY_SOURCE.values() for rule in rules):
        assert all(math.isfinite(condition.threshold) for condition in rule.conditions), rule.id
        if rule.also is None:  # a relative signature's conditions hold on healthy runs one at a time, not together
            assert not any(rule.holds(x) for x in rule.healthy), rule.id


def test_the_thresholds_file_round_trips(tmp_path):
    rules, table = calibrated_rules(tmp_path)
    read = doctor.load_thresholds(tmp_path / "thresholds.json")
    assert read == json.loads(json.dumps(table))
    again = doctor.calibrated(doctor.SIGNATURES, read)
    named = read["sources"]["minippo"]
    assert again == rules and [rule.id for rule in again] == [r.id for r in doctor.SIGNATURES if r.id in named]
    for rule in again:
        entry = read["sources"]["minippo"][rule.id]
        assert rule.threshold == entry["threshold"] and list(rule.healthy) == entry["healthy"]
        if rule.also:
            assert rule.also.threshold == entry["also"]["threshold"]
    assert doctor.calibrated(doctor.SIGNATURES, {"rules": {}}) == ()  # no file: no rule claims a clean bill


@pytest.fixture(scope="module")
def rules(tmp_path_factory):
    return calibrated_rules(tmp_path_factory.mktemp("calibrated"))[0]


def first(rules, rows) -> str:
    found = doctor.diagnose(rows, rules)
    return found[0].rule.id if found else "none"


def test_a_high_kl_with_the_clip_fraction_near_0_is_no_clip_not_a_step_size(rules):
    assert first(rules, rows_of(approx_kl=0.6, clip_fraction=0.0005)) == "no-clip"
    assert first(rules, rows_of(approx_kl=0.12, clip_fraction=0.4)) == "kl-spike"  # the clip at work: a step size
    assert first(rules, rows_of(approx_kl=0.005, clip_fraction=0.0)) == "none"  # a clip fraction of 0 alone is fine


def test_entropy_falling_to_0_while_the_return_stays_flat_is_entropy_collapse(rules):
    collapse = rows_of(entropy=list(np.linspace(0.7, 0.005, N)), return_mean=list(20 + np.sin(np.arange(N))))
    assert first(rules, collapse) == "entropy-collapse"
    learning = rows_of(entropy=list(np.linspace(0.7, 0.005, N)))  # the same fall with a rising return
    assert "entropy-collapse" not in [f.rule.id for f in doctor.diagnose(learning, rules)]
    assert first(rules, rows_of()) == "none"


def test_a_return_that_never_changes_is_not_ppo(rules):
    assert first(rules, rows_of(return_mean=0.0)) == "not-ppo-reward"
    assert first(rules, rows_of(return_mean=-500.0)) == "not-ppo-reward"  # the same every update, whatever its level
    assert first(rules, rows_of(return_mean=list(-500.0 + 5 * (np.arange(N) % 2)))) == "none"


def test_kl_spike_reads_a_sustained_level_not_one_update_so_a_longer_run_does_not_trip_it(rules):
    long = rows_of(400)
    for i in (50, 180, 333):  # single updates far above every healthy KL
        long[i]["approx_kl"] = 0.5
    assert first(rules, long) == "none"
    burst = rows_of(400, approx_kl=[0.004] * 200 + [0.2] * 12 + [0.004] * 188)
    assert first(rules, burst) == "kl-spike"


def test_evaluate_counts_false_alarms_recall_and_the_right_cause_first(tmp_path):
    runs = [("healthy", "calibration", rows_of()),
            ("healthy", "calibration", rows_of(approx_kl=0.3, clip_fraction=0.4)),  # a false alarm: kl-spike
            ("clip_10", "calibration", rows_of(approx_kl=0.6, clip_fraction=0.001)),  # named right: no-clip
            ("clip_10", "calibration", rows_of(approx_kl=0.3, clip_fraction=0.4,  # flagged, the wrong cause; and
                                               return_mean=list(np.linspace(20, 10, N)))),  # harmed: ends lower
            ("vf_0", "calibration", rows_of()),  # missed
            ("lr_x30", "held-out", rows_of(approx_kl=0.3, clip_fraction=0.4))]  # of the other part: not counted
    folder, record, manifest = campaign(tmp_path, runs)
    table = {"rules": {
        "no-clip": {"threshold": 0.1, "healthy": [0.001, 0.01], "also": {"threshold": 0.01, "healthy": [0.0, 0.2]}},
        "kl-spike": {"threshold": 0.1, "healthy": [0.001, 0.01]},
        "critic-worse-than-constant": {"threshold": -1.0, "healthy": [0.0, 1.0]}}}  # fmt: skip
    (tmp_path / "thresholds.json").write_text(json.dumps(table))
    from minippo.config import Config

    vf_0 = folder / "minippo-defaults-CartPole-v1-vf_0-1x-seed4"  # its settings in the log: the check names it
    (vf_0 / "config.json").write_text(json.dumps(Config(env_id="CartPole-v1", value_coef=0.0).to_dict()))
    text = doctor_confusion.evaluate("calibration", folder, record, manifest, tmp_path / "thresholds.json",
                                     tmp_path / "out.csv")
    with open(tmp_path / "out.csv", newline="") as handle:
        rows = {(row["kind"], row["name"]): row for row in csv.DictReader(handle)}
    def overall(name):
        row = rows["overall", name]
        return tuple(row[key] for key in ("healthy_runs", "false_alarms", "broken_runs", "flagged", "first_right",
                                          "first_rule_expected"))  # fmt: skip

    assert overall("all runs, rules only") == ("2", "1", "3", "2", "1", "1")
    assert overall("all runs") == ("2", "1", "3", "3", "2", "1")  # vf_0 by its setting, not the manifest's rule
    assert (rows["check", "critic-not-trained"]["flagged"], rows["check", "critic-not-trained"]["false_alarms"]) == (
        "1", "0")
    assert (rows["fault", "vf_0"]["flagged"], rows["fault, rules only", "vf_0"]["flagged"]) == ("1", "0")
    # vf_0 ends where the healthy runs do: missed by the rules although no worse than healthy
    assert (rows["overall", "all runs, rules only"]["unharmed_missed"], rows["overall", "all runs"]["unharmed_missed"]
            ) == ("1", "0")  # fmt: skip
    assert (rows["overall", "all runs"]["harmed_runs"], rows["overall", "all runs"]["harmed_flagged"]) == ("1", "1")
    assert rows["overall", "all runs"]["harmed_first_right"] == "0"  # flagged, but kl-spike named first: not ε
    assert (rows["rule", "kl-spike"]["false_alarms"], rows["rule", "kl-spike"]["broken_runs"]) == ("1", "0")
    assert (rows["rule", "no-clip"]["flagged"], rows["rule", "no-clip"]["broken_runs"]) == ("1", "2")
    assert (rows["fault", "clip_10"]["flagged"], rows["fault", "clip_10"]["first_right"]) == ("2", "1")
    assert rows["rule", "critic-worse-than-constant"]["flagged"] == "0"
    assert "| healthy runs flagged (false alarms) | 1/2 (50%) | 1/2 (50%) |" in text
    assert "| the right cause named first | 2/3 (67%) | 1/3 (33%) |" in text
    assert doctor_confusion.verdicts_path(tmp_path / "out.csv").exists()
    made = json.loads((tmp_path / "out.json").read_text())  # how the table was made, and with which thresholds
    assert (made["part"], made["runs read"]) == ("calibration", 5)
    assert made["thresholds"]["sha256"] == hashlib.sha256((tmp_path / "thresholds.json").read_bytes()).hexdigest()
    held_out = doctor_confusion.verdicts_path(dc.common.RESULTS / "doctor_confusion_held-out.csv")
    assert held_out.name == "doctor_verdicts_held-out.csv"


def test_each_rule_names_faults_that_exist_and_each_campaign_fault_is_named_by_the_rule_it_expects():
    from benchmarks.doctor_libraries import FAULTS

    atlas_modes = set(json.loads((dc.common.RESULTS / "atlas_runs.json").read_text())["modes"])
    assert set(dc.FAULTS_NAMED) == {rule.id for rule in (*doctor.SIGNATURES, *doctor.CHECKS)}
    assert set().union(*dc.FAULTS_NAMED.values()) <= set(FAULTS) | atlas_modes
    for fault, (_, _, cause, _) in FAULTS.items():
        assert fault in dc.FAULTS_NAMED[cause], fault


def test_the_committed_rule_table_is_the_codes():
    """results/doctor_rules.csv, which `calibrate` writes beside the thresholds, is doctor.RULES as the code has them:
    a threshold changed in minippo/doctor_thresholds.json, or a rule changed in doctor.py, without calibrating again
    shows here."""
    rows = read_rows(dc.RULES_CSV)
    assert rows == dc.rule_rows(doctor.RULES_BY_SOURCE)
    assert [row["rule"] for row in rows if row["condition"] == "setting"] == [check.id for check in doctor.CHECKS]
    for source, rules in doctor.RULES_BY_SOURCE.items():
        mine = [row for row in rows if row["source"] == source]
        assert [row["rule"] for row in mine if row["condition"] == "first"] == [rule.id for rule in rules]
        assert [row["rule"] for row in mine if row["condition"] == "also"] == [r.id for r in rules if r.also]


def test_a_broken_run_is_harmed_when_it_ends_below_every_healthy_run_of_its_setting():
    def run(fault, last, library="sb3", task="Acrobot-v1", length="1x"):
        rows = [{"update": u, "return_mean": -500.0 + (last + 500.0) * min(u / 20, 1.0)} for u in range(40)]
        return dc.Run(f"{fault}-{last}", "campaign", "held-out", library, task, fault, "", rows, {}, "defaults", length)

    healthy = [run("healthy", -90.0), run("healthy", -80.0), run("healthy", -300.0, task="Pendulum-v1"),
               run("healthy", -400.0, length="4x")]  # fmt: skip
    assert doctor_confusion.final_return(healthy[0]) == -90.0  # the median of the last quarter, not the start
    below, within, zeroed = run("vf_0", -200.0), run("lr_x10", -85.0), run("reward_zero", 0.0)
    runs = healthy + [below, within, zeroed]
    assert [doctor_confusion.harmed(r, runs) for r in (below, within, zeroed)] == ["yes", "no", "n/a"]
    assert doctor_confusion.harmed(run("vf_0", -200.0, library="cleanrl"), runs) == "n/a"  # no healthy run to compare
    tuned = dc.Run("zoo", "campaign", "held-out", "sb3", "Acrobot-v1", "healthy", "", healthy[0].rows[:20] + [
        {"update": u, "return_mean": 0.0} for u in range(20, 40)], {}, "zoo", "1x")  # fmt: skip
    assert doctor_confusion.harmed(within, runs + [tuned]) == "no"  # a healthy run of other settings is no peer


def test_each_source_is_calibrated_on_its_own_runs(tmp_path):
    """A library that logs its KL 20 times larger (the same runs as another source) moves its own thresholds and
    leaves minippo's as they were."""
    louder = [(fault, part, [{**row, "approx_kl": 20 * row["approx_kl"]} for row in rows], "sb3")
              for fault, part, rows in CAMPAIGN]  # fmt: skip
    _, alone = calibrated_rules(tmp_path / "alone")
    _, both = calibrated_rules(tmp_path / "both", CAMPAIGN + louder)
    assert both["sources"]["minippo"] == alone["sources"]["minippo"]
    assert both["sources"]["sb3"]["kl-spike"]["threshold"] > 10 * alone["sources"]["minippo"]["kl-spike"]["threshold"]
    rules = doctor.calibrated(doctor.SIGNATURES, both, "sb3")
    assert next(r for r in rules if r.id == "kl-spike").threshold == both["sources"]["sb3"]["kl-spike"]["threshold"]


def test_the_replication_is_judged_for_harm_against_the_healthy_runs_of_the_other_parts(tmp_path):
    ending = {"healthy": (20.0, 30.0), "vf_0": (10.0,), "lr_x30": (25.0,)}  # vf_0 ends below both; lr_x30 between
    runs = [(fault, "replication" if fault != "healthy" else part, rows_of(return_mean=list(np.linspace(5, end, N))))
            for fault, ends in ending.items() for part, end in zip(("calibration", "held-out"), ends)]  # fmt: skip
    folder, record, manifest = campaign(tmp_path, runs)
    (tmp_path / "thresholds.json").write_text(json.dumps({"rules": {}}))
    doctor_confusion.evaluate("replication", folder, record, manifest, tmp_path / "thresholds.json",
                              tmp_path / "out.csv", peers=(manifest, record))  # fmt: skip
    verdicts = {row["fault"]: row for row in read_rows(doctor_confusion.verdicts_path(tmp_path / "out.csv"))}
    assert set(verdicts) == {"vf_0", "lr_x30"}  # the healthy runs are peers, not judged
    assert (verdicts["vf_0"]["harmed"], verdicts["lr_x30"]["harmed"]) == ("yes", "no")
