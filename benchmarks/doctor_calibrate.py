"""The thresholds of ``minippo doctor``'s rules, set on the calibration runs only, and the doctor's confusion table on
either part of the campaign (benchmarks/doctor_runs.py).

    python -m benchmarks.doctor_calibrate calibrate [--runs DIR]      # thresholds, rule table, the atlas's record
    python -m benchmarks.doctor_calibrate evaluate --part calibration  # results/doctor_confusion_calibration.csv
    python -m benchmarks.doctor_calibrate evaluate --part held-out     # once, at the end: runs no threshold saw

``calibrate`` reads the runs whose manifest part is "calibration" (a held-out run's folder is never opened, and the
thresholds refuse a run of another part) and the atlas's record (results/atlas_runs.csv, every run of which counts as
calibration). A healthy run is measured whole and cut to its first 10, 15 and 40 updates, since the doctor reads runs
still in progress; a broken run whole. Each condition of a rule gets its threshold by one principle:

- on the condition's scale: log10 for a positive quantity (a KL, a clip fraction, a value loss, their ratios, a
  relative spread), where 0 counts as FLOOR, the precision of a log rounded to 6 digits; linear otherwise (explained
  variance, changes in nats, shares);
- between the runs it must not flag (a one-condition rule: the healthy runs) and the runs of the faults the rule names
  (FAULTS_NAMED) beyond their extreme: the midpoint between that extreme and the nearest such run beyond it;
- never nearer the runs it must not flag than MARGIN (a factor 2 on a log scale, 0.1 on a linear one): when the
  nearest broken run lies within it, or none lies beyond, the threshold is the extreme plus the margin, and the doctor
  misses that run rather than risk a false alarm on a healthy run the calibration did not see.

Each library (each log source) gets its own thresholds, set on its own runs alone: the libraries log the same names
for different measurements (minippo/doctor_logs.py), so a healthy range of one is not a healthy range of another.

A rule with a second condition (a relative signature: the KL high while the clip fraction stays low) is there to tell
its cause from others that share the first variable, so it must flag no healthy run and no run of another fault that
the rules before it (the doctor reads them in order) do not already flag; where a condition has no such run to keep
clear of, it is set against the healthy runs, as a one-condition rule is.
Its second condition's cut is tried at each run of the rule's faults in turn; at each, the first condition's
threshold is set by the principle above against the other runs the second lets through, and the cut that lets the
rule catch the most runs of its faults is kept (the tightest, on a tie). The second condition's threshold is then set
by the principle against the other runs that meet the first.

``calibrate`` writes, in one go, everything the chapter's tables are made from: minippo/doctor_thresholds.json, the
rule table as the code then has it (results/doctor_rules.csv: a row per check of the settings in doctor.CHECKS, then per
condition of each rule of each source in doctor.RULES_BY_SOURCE) and the atlas's record summarised from its runs
(``benchmarks.atlas summarize``: results/atlas_healthy_ranges.csv, atlas_signatures.csv, atlas_features.csv).

``evaluate`` runs the doctor, with the thresholds of the file, on every recorded run of a part: per rule its false
alarms on healthy runs and its recall on the broken runs of the faults it names, and overall the healthy runs
flagged, the broken runs flagged, and those whose first finding names their fault among its causes.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from benchmarks import common
from minippo import doctor
from minippo.doctor_logs import read_log
from minippo.errors import MinippoError
from minippo.records import read_rows

MANIFEST_CSV = common.RESULTS / "doctor_manifest.csv"  # benchmarks/doctor_runs.py plan
RUN_ROOT = common.RUNS / "doctor"
ATLAS_CSV = common.RESULTS / "atlas_runs.csv"
RULES_CSV = common.RESULTS / "doctor_rules.csv"  # the rule table, as doctor.RULES_BY_SOURCE has it after calibrate
RULE_FIELDS = ["source", "rule", "condition", "variable", "window", "statistic", "level", "comparison", "threshold",
               "healthy_low", "healthy_high", "anchor", "causes"]  # fmt: skip
PARTS = ("calibration", "held-out", "replication")  # the replication: doctor_runs.replication, a manifest of its own
CALIBRATION = "calibration"
CODE = ("minippo", "benchmarks/doctor_calibrate.py", ":(exclude)minippo/doctor_thresholds.json")  # what sets them
PREFIXES = (10, 15, 40)  # a healthy run is also measured cut to its first updates
FLOOR = 1e-6  # 0 on a log scale: the precision of a progress.csv rounded to 6 significant digits
MARGIN = {"log": math.log10(2), "linear": 0.1}
POSITIVE = {"approx_kl", "clip_fraction", "value_loss"}  # variables that are never negative
LOG_STATISTICS = {"max", "min", "median", "mean", "largest rolling median", "last over first",
                  "last quarter over first"}

# the faults each rule names among its causes: the campaign's (doctor_runs.FAULTS) and the atlas's modes
# (atlas.FAULTS). The step-size rules name the same three causes in different orders
STEP_SIZE = ("lr_x10", "lr_x30", "epochs_50", "lr_10x", "lr_100x_epochs_40", "minibatch_4")
FAULTS_NAMED = {
    "entropy-bonus-negative": ("ent_-0.01", "ent_-0.05"),  # the checks of the settings (doctor.CHECKS)
    "critic-not-trained": ("vf_0",),
    "clip-cannot-bind": ("clip_10",),
    "not-ppo-reward": ("reward_zero",),
    "policy-never-moves": ("ratio_vs_current_policy",),
    "no-clip": ("clip_10",),
    "entropy-rises": ("entropy_too_large", "log_prob_wrong_axis"),
    "kl-spike": STEP_SIZE,
    "kl-high": STEP_SIZE,
    "clip-high": STEP_SIZE,
    "entropy-collapse": ("ent_-0.01", "ent_-0.05", "entropy_wrong_sign") + STEP_SIZE,
    "policy-barely-moves": ("minibatch_whole",),
    "critic-worse-than-constant": ("vf_0", "value_loss_sign", "stale_value_targets"),
    "value-loss-grows": ("value_loss_sign", "no_reward_scaling", "gamma_1"),
}


@dataclass
class Run:
    id: str
    source: str  # "campaign" (benchmarks/doctor_runs.py) or "atlas" (results/atlas_runs.csv)
    part: str  # the manifest's part; every atlas run is calibration
    library: str
    task: str
    fault: str  # "healthy", a key of doctor_runs.FAULTS or a mode of the atlas
    cause: str  # the rule the manifest expects first ("" for healthy runs and the atlas)
    rows: list
    settings: dict = field(default_factory=dict)  # the settings its log carries (doctor_logs.SETTINGS)
    preset: str = ""  # the manifest's settings (defaults, zoo, ...) and length (1x, 4x)
    length: str = ""

    @property
    def healthy(self) -> bool:
        return self.fault == "healthy"


# ---- reading the runs of one part


def recorded_ids(record_json: Path) -> dict:
    """{id: outcome} of the runs the campaign's record holds ("ok", or "stopped: ..." by a non-finite loss): a run
    folder without a line there is still being written."""
    if not record_json.exists():
        raise common.BenchmarkError(f"no record {record_json}: which run folders are finished is not known")
    return {run["id"]: run.get("outcome", "ok") for run in json.loads(record_json.read_text())["runs"]}


def read_part(part: str, runs_dir: Path, manifest_csv: Path = MANIFEST_CSV, record_json: Path | None = None):
    """(the recorded runs of the manifest's ``part``, a count of those left out by reason). Only the folders of that
    part are opened."""
    if part not in PARTS:
        raise common.BenchmarkError(f"no part {part!r}: the parts are {', '.join(PARTS)}")
    runs_dir = Path(runs_dir)
    done = recorded_ids(record_json or runs_dir.parent.parent / "results" / "doctor_runs.json")
    runs, left_out = [], {}
    for entry in read_rows(manifest_csv):
        if entry["part"] != part:
            continue
        if entry["id"] not in done:
            left_out["not made yet"] = left_out.get("not made yet", 0) + 1
            continue
        try:
            log = read_log(runs_dir / entry["id"])
            rows, settings = log.rows, log.settings
        except MinippoError as error:
            if done[entry["id"]] == "ok":
                raise common.BenchmarkError(f"run {entry['id']} is recorded but its log cannot be read: "
                                            f"{error}") from None  # fmt: skip
            rows, settings = [], {}  # stopped before its log had a row
        if len(rows) < doctor.MIN_UPDATES:  # a run stopped early by a non-finite loss: too short to judge
            left_out["under 10 updates"] = left_out.get("under 10 updates", 0) + 1
            continue
        runs.append(Run(entry["id"], "campaign", entry["part"], entry["library"], entry["task"], entry["fault"],
                        entry["cause"], rows, settings, entry.get("settings", ""),
                        entry.get("length", "")))  # fmt: skip
    return runs, left_out


def atlas_runs(path: Path = ATLAS_CSV) -> list[Run]:
    """The atlas's runs (benchmarks/atlas.py: minippo on CartPole, Hopper and MinAtar Breakout), each a calibration
    run: they set the doctor's first thresholds and none is held out."""
    grouped = {}
    for row in read_rows(path):
        key = (row["mode"], row["task"], row["seed"])
        grouped.setdefault(key, []).append({k: float(v) for k, v in row.items() if k not in ("mode", "task", "seed")})
    return [Run(f"atlas-{mode}-{task.replace('/', '-')}-seed{seed}", "atlas", CALIBRATION, "minippo", task, mode, "",
                rows) for (mode, task, seed), rows in grouped.items()]  # fmt: skip


# ---- thresholds


def scale_of(condition: doctor.Condition) -> str:
    if condition.statistic == "relative spread":
        return "log"
    return "log" if condition.variable in POSITIVE and condition.statistic in LOG_STATISTICS else "linear"


def _to_scale(values, scale: str) -> np.ndarray:
    values = np.asarray(values, dtype=float)
    return np.log10(np.maximum(values, FLOOR)) if scale == "log" else values


def _from_scale(value: float, scale: str) -> float:
    return float(10**value) if scale == "log" else float(value)


def cut(negatives, positives, comparison: str, scale: str) -> dict:
    """A threshold between ``negatives`` (values it must not flag) and ``positives`` (values of the faults it names),
    by the module's principle; with what it was set from."""
    sign = 1.0 if comparison == ">" else -1.0  # flagged: sign · value above sign · threshold
    neg = sign * _to_scale(negatives, scale)
    pos = sign * _to_scale(positives, scale)
    margin = MARGIN[scale]
    if len(neg) == 0:  # nothing to keep clear of: just inside the least extreme run of its faults
        edge = float(pos.min()) - margin
        return {"threshold": _from_scale(sign * edge, scale), "basis": "no other run to separate from",
                "nearest_negative": None, "nearest_broken": _from_scale(sign * float(pos.min()), scale)}  # fmt: skip
    extreme = float(neg.max())
    beyond = pos[pos > extreme]
    nearest = float(beyond.min()) if len(beyond) else None
    if nearest is not None and (nearest - extreme) / 2 >= margin:
        edge, basis = (extreme + nearest) / 2, "midpoint"
    else:
        edge = extreme + margin
        basis = "margin: nearest broken run within it" if nearest is not None else "margin: no broken run beyond"
    return {"threshold": _from_scale(sign * edge, scale), "basis": basis,
            "nearest_negative": _from_scale(sign * extreme, scale),
            "nearest_broken": None if nearest is None else _from_scale(sign * nearest, scale)}  # fmt: skip


def _flags(values: np.ndarray, threshold: float, comparison: str) -> np.ndarray:
    return values > threshold if comparison == ">" else values < threshold


def samples(runs: list[Run]) -> list[tuple[Run, list]]:
    """(run, rows) to measure: each run whole, and each healthy run cut to its first PREFIXES updates too."""
    cut_runs = [(run, run.rows[:n]) for run in runs if run.healthy for n in PREFIXES if n < len(run.rows)]
    return [(run, run.rows) for run in runs] + cut_runs


def _range(values) -> list:
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    return [float(values.min()), float(values.max())] if len(values) else [math.nan, math.nan]


def calibrate_rule(rule: doctor.Rule, measured: list[tuple[Run, list[float]]], earlier=None,
                   labels=None) -> dict | None:  # fmt: skip
    """The thresholds of ``rule`` from ``measured`` ((run, the statistic of each condition) per sample), or None when
    no sample of its faults has its statistics. ``earlier``: per sample, whether a rule before this one flags it (a
    broken run so flagged is not one a relative signature must keep clear of); ``labels``: per sample, its name."""
    named = set(FAULTS_NAMED[rule.id])
    conditions = rule.conditions
    earlier = [False] * len(measured) if earlier is None else earlier
    finite = [(run, values, before) for (run, values), before in zip(measured, earlier)
              if all(math.isfinite(v) for v in values)]  # fmt: skip
    healthy = np.array([values for run, values, _ in finite if run.healthy]).reshape(-1, len(conditions))
    broken = np.array([values for run, values, _ in finite if run.fault in named]).reshape(-1, len(conditions))
    others = np.array([values for run, values, before in finite if run.fault not in named
                       and (run.healthy or not before)]).reshape(-1, len(conditions))  # fmt: skip
    if len(broken) == 0 or len(healthy) == 0:
        return None
    first, scale = conditions[0], scale_of(conditions[0])
    if len(conditions) == 1:
        entry = cut(healthy[:, 0], broken[:, 0], first.comparison, scale)
        caught = _flags(broken[:, 0], entry["threshold"], first.comparison)
    else:
        second = conditions[1]
        second_scale = scale_of(second)
        sign = 1.0 if second.comparison == ">" else -1.0
        order = sorted(set(sign * _to_scale(broken[:, 1], second_scale)), reverse=True)  # the tightest first

        def trial(edge):
            lets = sign * _to_scale(others[:, 1], second_scale) >= edge
            keeps = sign * _to_scale(broken[:, 1], second_scale) >= edge
            # against the other runs the cut lets through; when it lets none, against the healthy runs, so that the
            # first condition still tests something (a threshold beyond every healthy run's value)
            negatives = others[lets, 0] if lets.any() else healthy[:, 0]
            entry = cut(negatives, broken[keeps, 0], first.comparison, scale)
            return keeps & _flags(broken[:, 0], entry["threshold"], first.comparison), entry

        tried = [(int(trial(edge)[0].sum()), -index, edge) for index, edge in enumerate(order)]
        edge = max(tried)[2]
        caught, entry = trial(edge)
        meet = _flags(others[:, 0], entry["threshold"], first.comparison)
        if caught.any() and meet.any():  # the second condition against the other runs that meet the first
            also = cut(others[meet, 1], broken[caught, 1], second.comparison, second_scale)
        elif caught.any():  # none meets the first: against the healthy runs, as a one-condition rule
            also = cut(healthy[:, 1], broken[caught, 1], second.comparison, second_scale)
        else:  # no cut lets the first condition catch a run: the second is set against every other run
            also = cut(others[:, 1], broken[:, 1], second.comparison, second_scale)
        caught = _flags(broken[:, 0], entry["threshold"], first.comparison) & _flags(
            broken[:, 1], also["threshold"], second.comparison)
        entry["also"] = {**also, "scale": second_scale, "healthy": _range(healthy[:, 1])}
    entry.update(scale=scale, healthy=_range(healthy[:, 0]), broken_samples=len(broken), caught=int(caught.sum()))
    if labels is not None:  # the healthy sample nearest the threshold, to name in the chapter
        kept = [label for label, (run, values) in zip(labels, measured)
                if run.healthy and all(math.isfinite(v) for v in values)]  # fmt: skip
        sign = 1.0 if first.comparison == ">" else -1.0
        entry["healthy_extreme"] = kept[int(np.argmax(sign * healthy[:, 0]))]
    return entry


def thresholds(runs: list[Run], signatures=doctor.SIGNATURES) -> dict:
    """{rule id: its thresholds, healthy ranges and what they were set from}, from calibration runs only."""
    foreign = sorted({run.id for run in runs if run.part != CALIBRATION})
    if foreign:
        raise common.BenchmarkError(f"thresholds are set on calibration runs only; {len(foreign)} runs of another "
                                    f"part were given ({foreign[0]}, ...)")  # fmt: skip
    table = {}
    sampled = samples(runs)
    labels = [run.id + (f" (its first {len(rows)} updates)" if len(rows) < len(run.rows) else "")
              for run, rows in sampled]  # fmt: skip
    earlier = [False] * len(sampled)  # per sample: flagged by a rule before the one being set
    for rule in signatures:
        measured = [(run, [condition.measure(rows)[0] for condition in rule.conditions]) for run, rows in sampled]
        entry = calibrate_rule(rule, measured, earlier, labels)
        if entry is None:
            continue
        table[rule.id] = entry
        (set_rule,) = doctor.calibrated([rule], {"rules": {rule.id: entry}})
        earlier = [before or set_rule.holds(*values) for before, (_, values) in zip(earlier, measured)]
    return table


def calibrate(runs_dir: Path, record_json: Path | None, manifest_csv: Path, atlas_csv: Path | None, out: Path,
              argv) -> dict:  # fmt: skip
    runs, left_out = read_part(CALIBRATION, runs_dir, manifest_csv, record_json)
    atlas = atlas_runs(atlas_csv) if atlas_csv else []
    sources = {source: thresholds([run for run in runs + atlas if run.library == source])
               for source in dict.fromkeys(run.library for run in runs + atlas)}  # fmt: skip
    manifest = read_rows(manifest_csv)
    counts = {"campaign healthy": sum(r.healthy for r in runs), "campaign broken": sum(not r.healthy for r in runs),
              "atlas healthy": sum(r.healthy for r in atlas), "atlas broken": sum(not r.healthy for r in atlas),
              "in the manifest": sum(e["part"] == CALIBRATION for e in manifest), **left_out}  # fmt: skip
    record = {
        "command": common.invocation("doctor_calibrate", argv),
        "commit": common.git_commit(CODE),
        "date": datetime.date.today().isoformat(),
        "runs": {CALIBRATION: counts, "held-out": {"read": 0, "in the manifest": len(manifest) - counts[
            "in the manifest"]}},  # fmt: skip
        "principle": " ".join(" ".join(__doc__.split("\n\n")[2:6]).split()),
        "calibration runs": sorted(run.id for run in runs),
        "sources": sources,  # a log's source: {rule id: its thresholds}, set on that library's runs alone
    }
    out.write_text(json.dumps(record, indent=1, ensure_ascii=False) + "\n")
    return record


def rule_rows(rules_by_source: dict, checks=doctor.CHECKS) -> list[dict]:
    """The rule table: a row per check of the settings (its bound, by definition, for every source), then per source a
    row per condition of each rule (the first, then ``also``), its threshold and healthy range in the 4 significant
    digits the doctor prints, its section and its causes."""
    rows = [{"source": "any", "rule": check.id, "condition": "setting", "variable": check.setting, "window": "",
             "statistic": "", "level": "", "comparison": check.comparison, "threshold": f"{check.bound:.4g}",
             "healthy_low": "", "healthy_high": "", "anchor": check.anchor, "causes": " | ".join(check.causes)}
            for check in checks]  # fmt: skip
    for source, rules in rules_by_source.items():
        for rule in rules:
            rows += _condition_rows(source, rule)
    return rows


def _condition_rows(source: str, rule) -> list[dict]:
    """A rule's rows of the rule table: its condition, and its second one (``also``) for a relative signature."""
    rows = []
    for which, condition in zip(("first", "also"), rule.conditions):
        rows.append({"source": source, "rule": rule.id, "condition": which, "variable": condition.variable,
                     "window": condition.window, "statistic": condition.statistic,
                     "level": "" if condition.level is None else f"{condition.level:.4g}",
                     "comparison": condition.comparison, "threshold": f"{condition.threshold:.4g}",
                     "healthy_low": f"{condition.healthy[0]:.4g}", "healthy_high": f"{condition.healthy[1]:.4g}",
                     "anchor": rule.anchor if which == "first" else "",
                     "causes": " | ".join(rule.causes) if which == "first" else ""})  # fmt: skip
    return rows


@common.one_line_errors
def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.doctor_calibrate", description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    calibrating = commands.add_parser("calibrate", help="set the thresholds on the calibration runs")
    evaluating = commands.add_parser("evaluate", help="the doctor's confusion table on one part")
    evaluating.add_argument("--part", choices=PARTS, required=True)
    for sub in (calibrating, evaluating):
        sub.add_argument("--runs", type=Path, default=RUN_ROOT, help="the campaign's run folders")
        sub.add_argument("--record", type=Path, help="the campaign's record (default: RUNS/../../results/"
                         "doctor_runs.json)")  # fmt: skip
        sub.add_argument("--manifest", type=Path, default=MANIFEST_CSV)
        sub.add_argument("--thresholds", type=Path, default=doctor.THRESHOLDS_JSON)
    calibrating.add_argument("--no-atlas", action="store_true", help="leave the atlas's record out (and do not "
                             "summarise it again)")  # fmt: skip
    calibrating.add_argument("--rules", type=Path, default=RULES_CSV, help="the rule table (default: "
                             "results/doctor_rules.csv)")  # fmt: skip
    evaluating.add_argument("--out", type=Path, help="default: results/doctor_confusion_PART.csv")
    args = parser.parse_args(argv)
    from benchmarks.doctor_confusion import calibration_table, evaluate

    if args.command == "calibrate":
        if not args.no_atlas:
            from benchmarks import atlas_signatures

            atlas_signatures.summarize()  # the atlas's record, from its runs
        record = calibrate(args.runs, args.record, args.manifest, None if args.no_atlas else ATLAS_CSV,
                           args.thresholds, argv)  # fmt: skip
        by_source = {source: doctor.calibrated(doctor.SIGNATURES, record, source) for source in doctor.SOURCES
                     if source in record["sources"]}  # fmt: skip
        common.write_rows(args.rules, rule_rows(by_source), RULE_FIELDS)
        print(f"{common.relative(args.thresholds)}: the rules of {len(record['sources'])} sources from "
              + ", ".join(f"{n} {what}" for what, n in record["runs"][CALIBRATION].items()))
        print(calibration_table(record))
        print(f"{common.relative(args.rules)}: the rule table")
        return 0
    out = args.out or common.RESULTS / f"doctor_confusion_{args.part}.csv"
    if args.part == "replication" and args.manifest == MANIFEST_CSV:
        from benchmarks.doctor_runs import REPLICATION_CSV, REPLICATION_JSON

        args.manifest, args.record = REPLICATION_CSV, args.record or REPLICATION_JSON
    print(evaluate(args.part, args.runs, args.record, args.manifest, args.thresholds, out, argv))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
