"""The atlas of how PPO fails: faults injected into minippo from outside, the runs they make, and their signatures.

    python -m benchmarks.atlas run                 # every (mode, task, seed) not yet recorded, one after the other
    python -m benchmarks.atlas run --tasks CartPole-v1 --modes healthy lr_10x --seeds 1
    python -m benchmarks.atlas summarize           # healthy ranges and one signature rule per (mode, task), as tables
    python -m benchmarks.atlas list                # the modes, each with what it injects, its cause and its fix

The tasks and the faults are in ``benchmarks/atlas_faults.py``; a fault is a change of Config fields, or a function of
minippo replaced for the length of a ``with fault.injected_into():`` block and put back after it. Records:
``results/atlas_runs.csv`` (every update of every run: mode, task, seed, then progress.csv's columns) and
``results/atlas_runs.json`` (the commands, the commit, the date, each mode's description, each run's outcome).
``summarize`` (``benchmarks/atlas_signatures.py``) writes ``results/atlas_healthy_ranges.csv``,
``results/atlas_signatures.csv``, the features of every run (``results/atlas_features.csv``) and what each feature
reads (``results/atlas_feature_legend.csv``).
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import time
from pathlib import Path

import minippo.ppo
from benchmarks import common
from benchmarks.atlas_faults import FAULT_TASKS, FAULTS, RUNS_CSV, TASKS, task_config
from benchmarks.atlas_signatures import summarize
from minippo.errors import NonFiniteError
from minippo.records import read_rows
from minippo.run_folder import PROGRESS_FIELDS

RUNS_JSON = common.RESULTS / "atlas_runs.json"
RUN_FOLDERS = Path("/tmp/atlas_runs")  # progress.csv, config.json and checkpoints of each run, outside the repository
SEEDS = (1, 2, 3)
CODE = ("minippo", "benchmarks/atlas.py", "benchmarks/atlas_faults.py")  # what a run's numbers depend on


def planned_runs(modes, tasks, seeds) -> list[tuple[str, str, int]]:
    runs = []
    for mode in modes:
        for task in tasks:
            healthy_only = task not in FAULT_TASKS
            if (mode != "healthy" and healthy_only) or task in FAULTS[mode].not_applicable:
                continue
            runs += [(mode, task, seed) for seed in seeds]
    return runs


def train_one(mode: str, task: str, seed: int, out: Path | None = None) -> tuple[list[dict], str]:
    """The progress rows of one run with ``mode`` injected, and its outcome: ok, or where it stopped."""
    fault = FAULTS[mode]
    config = fault.configure(task_config(task, seed))
    rows = []
    with fault.injected_into():
        try:
            minippo.ppo.train(config, out=out, on_update=rows.append)
        except NonFiniteError as error:
            return rows, f"stopped: {error}"
    return rows, "ok"


# ---- the record


def load_record() -> dict:
    if RUNS_JSON.exists():
        return json.loads(RUNS_JSON.read_text())
    return {"commands": [], "commit": None, "date": None, "tasks": {}, "modes": {}, "runs": []}


def describe(record: dict) -> None:
    record["tasks"] = {
        task: {
            "updates": updates,
            "config": {k: v for k, v in dataclasses.asdict(task_config(task, 1)).items() if k != "seed"},
        }
        for task, (_, updates) in TASKS.items()
    }
    record["modes"] = {
        name: {"injected": f.injected, "cause": f.cause, "fix": f.fix, "not_applicable": f.not_applicable}
        for name, f in FAULTS.items()
    }


def record_runs(modes, tasks, seeds, argv) -> int:
    record = load_record()
    commit = common.git_commit(CODE)
    if record["commit"] not in (None, commit):
        common.fail(f"{common.relative(RUNS_JSON)} holds runs of commit {record['commit']}, not {commit}")
    record.update(commit=commit, date=datetime.date.today().isoformat())
    command = common.invocation("atlas", argv)
    if command not in record["commands"]:
        record["commands"].append(command)
    describe(record)
    done = {(run["mode"], run["task"], run["seed"]) for run in record["runs"]}
    left = [run for run in planned_runs(modes, tasks, seeds) if run not in done]
    print(f"{len(left)} runs to make, {len(done)} recorded", flush=True)
    for mode, task, seed in left:
        started = time.perf_counter()
        folder = RUN_FOLDERS / f"{mode}-{task.replace('/', '-')}-seed{seed}"
        rows, outcome = train_one(mode, task, seed, folder)
        wall = time.perf_counter() - started
        labels = {"mode": mode, "task": task, "seed": seed}
        fields = list(labels) + list(rows[0] if rows else PROGRESS_FIELDS)
        old = read_rows(RUNS_CSV) if RUNS_CSV.exists() else []
        new = [{**labels, **{k: _short(v) for k, v in row.items()}} for row in rows]
        common.write_rows(RUNS_CSV, old + new, fields)
        last = rows[-1]["return_mean"] if rows else float("nan")
        record["runs"].append({**labels, "updates": len(rows), "outcome": outcome, "final_return_mean": _short(last),
                               "wall_s": round(wall, 1)})  # fmt: skip
        RUNS_JSON.write_text(json.dumps(record, indent=1, ensure_ascii=False) + "\n")
        print(f"{mode:28} {task:20} seed {seed}  {len(rows):3} updates  return {last:8.1f}  {wall:5.0f} s  {outcome}",
              flush=True)  # fmt: skip
    return 0


def _short(value):
    return value if isinstance(value, int) else float(f"{value:.6g}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.atlas", description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    run = commands.add_parser("run", help="make the runs not yet recorded, one after the other")
    run.add_argument("--modes", nargs="+", default=list(FAULTS), choices=list(FAULTS))
    run.add_argument("--tasks", nargs="+", default=list(TASKS), choices=list(TASKS))
    run.add_argument("--seeds", nargs="+", type=int, default=list(SEEDS))
    commands.add_parser("summarize", help="healthy ranges and a signature rule per mode, from the record")
    commands.add_parser("list", help="the modes: what each injects, its cause and its fix")
    args = parser.parse_args(argv)
    if args.command == "run":
        return record_runs(args.modes, args.tasks, args.seeds, argv)
    if args.command == "summarize":
        return summarize()
    for fault in FAULTS.values():
        print(f"{fault.name}\n  injects: {fault.injected}\n  cause: {fault.cause}\n  fix: {fault.fix}")
        for task, why in fault.not_applicable.items():
            print(f"  not on {task}: {why}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
