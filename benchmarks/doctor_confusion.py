"""The doctor's confusion table on one part of its campaign: ``python -m benchmarks.doctor_calibrate evaluate --part
PART`` runs ``minippo doctor``, with the thresholds of minippo/doctor_thresholds.json, on every recorded run of the part
(benchmarks/doctor_calibrate.py reads them, opening no folder of another part), and writes per rule its false alarms
on healthy runs and its recall on the broken runs of the faults it names, and overall the healthy runs flagged, the
broken runs flagged, and those whose first finding names their fault among its causes; each once with the checks of
the settings the logs carry and once with the rules alone. Beside the table it writes how it was made
(doctor_confusion_PART.json): the command, the commit, the date, the runs read, and the thresholds file's SHA-256 and
commit, so that a page can check that both parts were judged with the same thresholds as the doctor has now. It also
renders the table ``calibrate`` prints of the thresholds it set (calibration_table).
"""

from __future__ import annotations

import datetime
import hashlib
import json
import math
from pathlib import Path

import numpy as np

from benchmarks import common
from benchmarks.doctor_calibrate import CODE, FAULTS_NAMED, MANIFEST_CSV, read_part
from minippo import doctor


def names_fault(rule_id: str, fault: str) -> bool:
    return fault in FAULTS_NAMED.get(rule_id, ())


def verdicts_path(out_csv: Path) -> Path:
    """Where evaluate writes each run's findings: beside the confusion table, doctor_verdicts_PART.csv."""
    stem = out_csv.stem
    return out_csv.with_name((stem.replace("confusion", "verdicts") if "confusion" in stem else stem + "_verdicts")
                             + ".csv")  # fmt: skip


def final_return(run) -> float:
    """Where the run ended up: the median logged return over its last quarter of updates."""
    returns = np.array([row.get("return_mean", math.nan) for row in run.rows], dtype=float)
    returns = returns[np.isfinite(returns)]
    return float(np.median(returns[-max(1, len(returns) // 4) :])) if len(returns) else math.nan


def harmed(run, runs) -> str:
    """Whether a broken run's fault cost it return: "yes" when it ended below every healthy run of ``runs`` of its
    library, settings, task and length (its part's; for the replication, both other parts': four seeds), "no" when it
    did not, "n/a" when there is no such healthy run or the logged return is not the task's (a zeroed reward logs the
    zeroed return)."""
    peers = [final_return(other) for other in runs if other.healthy and (other.library, other.preset, other.task,
             other.length) == (run.library, run.preset, run.task, run.length)]  # fmt: skip
    if run.fault == "reward_zero" or not peers:
        return "n/a"
    return "yes" if final_return(run) < min(peers) else "no"


def _overall(name: str, healthy: list, broken: list, verdicts: dict, harm: dict) -> dict:
    return {"kind": "overall", "name": name, "healthy_runs": len(healthy),
            "false_alarms": sum(bool(verdicts[run.id]) for run in healthy), "broken_runs": len(broken),
            "flagged": sum(bool(verdicts[run.id]) for run in broken),
            "first_right": sum(bool(verdicts[run.id]) and names_fault(verdicts[run.id][0], run.fault)
                               for run in broken),
            "first_rule_expected": sum(verdicts[run.id][:1] == [run.cause] for run in broken),
            "unharmed_missed": sum(not verdicts[run.id] and harm[run.id] == "no" for run in broken),
            "harmed_runs": sum(harm[run.id] == "yes" for run in broken),
            "harmed_flagged": sum(bool(verdicts[run.id]) and harm[run.id] == "yes" for run in broken),
            "harmed_first_right": sum(bool(verdicts[run.id]) and harm[run.id] == "yes"
                                      and names_fault(verdicts[run.id][0], run.fault) for run in broken)}  # fmt: skip


def evaluate(part: str, runs_dir: Path, record_json: Path | None, manifest_csv: Path, thresholds_json: Path,
             out_csv: Path, argv=None, peers: tuple[Path, Path | None] = (MANIFEST_CSV, None)) -> str:  # fmt: skip
    """The doctor on every recorded run of ``part``: the checks of the settings its log carries, then the rules; and
    again with the rules alone (what the doctor makes of a log without settings). A part without healthy runs (the
    replication) is judged for harm against the healthy runs of the calibration and held-out parts of ``peers`` (a
    manifest and its record; by default the campaign's), read from ``runs_dir``."""
    table = doctor.load_thresholds(thresholds_json)
    rules = {source: doctor.calibrated(doctor.SIGNATURES, table, source) for source in doctor.SOURCES}
    runs, left_out = read_part(part, runs_dir, manifest_csv, record_json)
    verdicts = {run.id: [f.rule.id for f in doctor.diagnose(run.rows, rules[run.library], run.settings)]
                for run in runs}  # fmt: skip
    logs_only = {run.id: [f.rule.id for f in doctor.diagnose(run.rows, rules[run.library], checks=())] for run in runs}
    healthy = [run for run in runs if run.healthy]
    broken = [run for run in runs if not run.healthy]
    peers = runs if healthy else [run for spent in ("calibration", "held-out") for run in
                                  read_part(spent, runs_dir, *peers)[0] if run.healthy]  # fmt: skip
    harm = {run.id: harmed(run, peers) for run in broken}
    rows = []
    every = {rule.id: rule for source_rules in rules.values() for rule in source_rules}  # each rule once
    for rule in (*doctor.CHECKS, *every.values()):
        check = isinstance(rule, doctor.Check)
        sources = {source for source, source_rules in rules.items()
                   if check or any(r.id == rule.id for r in source_rules)}  # the sources it has thresholds for
        mine = [run for run in broken if names_fault(rule.id, run.fault) and run.library in sources]
        judged = [run for run in healthy if run.library in sources]
        rows.append({"kind": "check" if check else "rule", "name": rule.id, "healthy_runs": len(judged),
                     "false_alarms": sum(rule.id in verdicts[run.id] for run in judged), "broken_runs": len(mine),
                     "flagged": sum(rule.id in verdicts[run.id] for run in mine),
                     "first_right": sum(verdicts[run.id][:1] == [rule.id] for run in mine)})  # fmt: skip
    for fault in dict.fromkeys(run.fault for run in broken):
        mine = [run for run in broken if run.fault == fault]
        for kind, found in (("fault", verdicts), ("fault, rules only", logs_only)):
            rows.append({"kind": kind, "name": fault, "broken_runs": len(mine),
                         "unharmed_missed": sum(not found[run.id] and harm[run.id] == "no" for run in mine),
                         "flagged": sum(bool(found[run.id]) for run in mine),
                         "first_right": sum(bool(found[run.id]) and names_fault(found[run.id][0], fault)
                                            for run in mine),
                         "first_rule_expected": sum(found[run.id][:1] == [run.cause] for run in mine)})  # fmt: skip
    rows.append(_overall("all runs", healthy, broken, verdicts, harm))
    rows.append(_overall("all runs, rules only", healthy, broken, logs_only, harm))
    fields = ["kind", "name", "healthy_runs", "false_alarms", "broken_runs", "flagged", "first_right",
              "first_rule_expected", "unharmed_missed", "harmed_runs", "harmed_flagged",
              "harmed_first_right"]  # fmt: skip
    common.write_rows(out_csv, rows, fields)
    per_run = [{"id": run.id, "library": run.library, "task": run.task, "fault": run.fault, "updates": len(run.rows),
                "settings": "yes" if run.settings else "no", "final_return": f"{final_return(run):.4g}",
                "harmed": harm.get(run.id, ""), "findings": " ".join(verdicts[run.id]) or "none",
                "rules_only": " ".join(logs_only[run.id]) or "none"} for run in runs]  # fmt: skip
    common.write_rows(verdicts_path(out_csv), per_run)
    made = {"command": common.invocation("doctor_calibrate", argv),
            "commit": common.git_commit((*CODE, "benchmarks/doctor_confusion.py")),
            "date": datetime.date.today().isoformat(), "part": part, "runs read": len(runs), "left out": left_out,
            "thresholds": {"file": common.relative(thresholds_json), "commit": table.get("commit"),
                           "sha256": hashlib.sha256(thresholds_json.read_bytes()).hexdigest()}}  # fmt: skip
    out_csv.with_suffix(".json").write_text(json.dumps(made, indent=1) + "\n")
    return confusion_markdown(part, rows, left_out, table)


def _share(count: int, total: int) -> str:
    return f"{count}/{total}" + (f" ({count / total:.0%})" if total else "")


def confusion_markdown(part: str, rows: list[dict], left_out: dict, table: dict) -> str:
    by_rule = [[f"`{r['name']}`" + " (setting)" * (r["kind"] == "check"), _share(r["false_alarms"], r["healthy_runs"]),
                _share(r["flagged"], r["broken_runs"]), str(r["first_right"])]
               for r in rows if r["kind"] in ("check", "rule")]  # fmt: skip
    alone = {r["name"]: r for r in rows if r["kind"] == "fault, rules only"}
    by_fault = [[f"`{r['name']}`", _share(r["flagged"], r["broken_runs"]), _share(r["first_right"], r["broken_runs"]),
                 _share(alone[r["name"]]["flagged"], r["broken_runs"]),
                 _share(alone[r["name"]]["first_right"], r["broken_runs"]), str(alone[r["name"]]["unharmed_missed"])]
                for r in rows if r["kind"] == "fault"]  # fmt: skip
    total, rules_only = (next(r for r in rows if r["name"] == name) for name in ("all runs", "all runs, rules only"))
    skipped = ", ".join(f"{n} {why}" for why, n in left_out.items())

    def measures(r):
        return [_share(r["false_alarms"], r["healthy_runs"]), _share(r["flagged"], r["broken_runs"]),
                _share(r["first_right"], r["broken_runs"]), _share(r["first_rule_expected"], r["broken_runs"]),
                str(r["unharmed_missed"]), _share(r["harmed_flagged"], r["harmed_runs"]),
                _share(r["harmed_first_right"], r["harmed_runs"])]

    return "\n\n".join([
        f"{part}: {total['healthy_runs']} healthy and {total['broken_runs']} broken runs"
        + (f" ({skipped}, left out)" if skipped else "")
        + f"; thresholds of {table.get('date', '?')}, commit {table.get('commit', '?')}",
        common.markdown_table(["rule", "false alarms (healthy runs)", "recall (runs of the faults it names)",
                         "named first"], by_rule),
        common.markdown_table(["fault", "flagged", "right cause first", "flagged, rules only",
                         "right cause first, rules only", "missed by the rules, return no worse than healthy"],
                        by_fault),
        common.markdown_table(["measure", "with the settings checks", "rules only"], [
            [name, *pair] for name, *pair in zip(
                ["healthy runs flagged (false alarms)", "broken runs flagged", "the right cause named first",
                 "the manifest's rule named first", "broken runs missed whose return is no worse than healthy",
                 "broken runs flagged, of those the fault cost return",
                 "the right cause named first, of those the fault cost return"],
                measures(total), measures(rules_only))]),
    ])  # fmt: skip


def calibration_table(record: dict) -> str:
    """What ``calibrate`` prints: per source, rule and condition, its threshold, the healthy range, the nearest runs on
    either side, which of them set it, and the runs of its faults it catches."""
    rows = []
    for source, entries in record["sources"].items():
        for rule_id, entry in entries.items():
            rule = next(r for r in doctor.SIGNATURES if r.id == rule_id)
            for condition, part in zip(rule.conditions, [entry, entry.get("also")]):
                rows.append([source, f"`{rule_id}`" if part is entry else "  and", f"{condition.statistic} of "
                             f"`{condition.variable}`", f"{condition.comparison} {part['threshold']:.4g}",
                             "–".join(f"{x:.3g}" for x in part["healthy"]), _number(part["nearest_negative"]),
                             _number(part["nearest_broken"]), part["basis"],
                             f"{entry['caught']}/{entry['broken_samples']}" if part is entry else ""])  # fmt: skip
    return common.markdown_table(["source", "rule", "reads", "flags", "healthy runs", "nearest kept clear",
                                  "nearest broken", "set by", "its faults caught"], rows)  # fmt: skip


def _number(value) -> str:
    return "—" if value is None else f"{value:.4g}"
