"""Runs for ``minippo doctor`` that no threshold was set on: healthy and broken PPO runs of three libraries, each
logged as its library logs it, split by the hashes of the runs' ids into a calibration part and a held-out part.

    python -m benchmarks.doctor_runs plan                  # results/doctor_manifest.csv, and the CPU time it costs
    python -m benchmarks.doctor_runs plan --measure        # first time a tiny run of each setting (doctor_speeds.csv)
    python -m benchmarks.doctor_runs run --part calibration --jobs 2
    python -m benchmarks.doctor_runs run --only sb3-zoo-Pendulum-v1-healthy-1x-seed1
    python -m benchmarks.doctor_runs run --part replication --jobs 2   # the held-out faults again, at a new seed

The manifest (``results/doctor_manifest.csv``: each run's id, part, library, settings, task, fault, the cause the
doctor should name, the setting changed, length, steps and seed) and with it the split are made from this code alone,
never from a run's results: thresholds are set on the calibration part and judged on the held-out part. Each run is
made in ``runs/doctor/<id>/``: minippo's run folder (config.json, progress.csv rounded to 6 digits), Stable-Baselines3's
logger output (its CSV and TensorBoard files, ``configure(folder, ["csv", "tensorboard"])``) with the hyperparameters
in a config.yml as rl-zoo saves them, or the TensorBoard events file of CleanRL's PPO (benchmarks/cleanrl_ppo.py); the
faults, each library's settings and the runners are in benchmarks/doctor_libraries.py. A run is recorded in
``results/doctor_runs.json`` with its command, commit, library versions and date; a recorded run is skipped, so the
same command resumes.

The replication part (``results/doctor_manifest_replication.csv``, recorded in ``results/doctor_runs_replication.json``)
was planned after the held-out part had been evaluated: its 48 broken runs again, each at seed 2, which no broken run
had. Nothing is calibrated on it. It asks whether the held-out figures hold on runs nobody has seen, and it judges,
on those runs, the count proposed after the held-out evaluation: the doctor's recall over the runs the fault harmed
(doctor_confusion.harmed: below all four healthy seeds of its setting in the other two parts), beside the recall
over every broken run; both against the same aims (at least 90% flagged, and the right cause first on at least 80%),
with the thresholds and rules unchanged since the held-out evaluation.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import hashlib
import json
import os
import tempfile
from collections import Counter
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path

from benchmarks import common
from benchmarks.doctor_libraries import (
    FAULTS,
    FIELDS,
    batch_of,
    cleanrl_settings,
    make_run,
    minippo_config,
    sb3_settings,
    updates_of,
    versions,
)
from minippo.records import read_rows

MANIFEST_CSV = common.RESULTS / "doctor_manifest.csv"
RECORD_JSON = common.RESULTS / "doctor_runs.json"
SPEEDS_CSV = common.RESULTS / "doctor_speeds.csv"
RUN_ROOT = common.RUNS / "doctor"
PARTS = ("calibration", "held-out")
REPLICATION, REPLICATION_SEED = "replication", 2
REPLICATION_CSV = common.RESULTS / "doctor_manifest_replication.csv"
REPLICATION_JSON = common.RESULTS / "doctor_runs_replication.json"

# steps of a 1x run: the atlas's CartPole (150 updates of 512) and MinAtar (200 of 8 × 128); the others, which the
# atlas does not have, about rl-zoo's n_timesteps for Pendulum (1e5), and LunarLander twice that
TASKS = {"CartPole-v1": 76_800, "Acrobot-v1": 102_400, "Pendulum-v1": 102_400, "LunarLander-v3": 204_800,
         "MinAtar/Breakout-v1": 204_800}  # fmt: skip
LENGTHS = {"1x": 1, "4x": 4}
HEALTHY_SEEDS = {"1x": (1, 2, 3, 4), "4x": (5, 6)}  # other seeds at 4x: a constant step size would repeat a 1x run
FAULT_TASKS = ("CartPole-v1", "Acrobot-v1", "Pendulum-v1", "LunarLander-v3")  # LunarLander: pip install box2d
HEALTHY = {  # library: (settings, task) of its healthy runs; the first settings a task has are its defaults
    "minippo": [("defaults", task) for task in FAULT_TASKS] + [("cartpole_ppo", "CartPole-v1"),
                                                               ("atari", "MinAtar/Breakout-v1")],
    "sb3": [(settings, task) for settings in ("defaults", "zoo") for task in FAULT_TASKS],
    "cleanrl": [("ppo_continuous_action" if task == "Pendulum-v1" else "ppo", task) for task in FAULT_TASKS],
}  # fmt: skip
# Stable-Baselines3 is left out of MinAtar (rl-zoo has no entry for it, and SB3's CnnPolicy needs frames of 36 pixels
# or more), and so is CleanRL (its ppo.py is for vector observations); minippo's a2c preset is not PPO.


@dataclass(frozen=True)
class Entry:
    library: str
    settings: str
    task: str
    fault: str  # "healthy" or a key of FAULTS
    length: str  # a key of LENGTHS
    seed: int
    part: str = ""  # calibration or held-out, from ``split``
    tiny: int = 0  # the steps of a smoke run of the same settings (not in the id); 0: the manifest's length

    @property
    def id(self) -> str:
        task = self.task.replace("/", "-")
        return f"{self.library}-{self.settings}-{task}-{self.fault}-{self.length}-seed{self.seed}"

    @property
    def steps(self) -> int:
        return self.tiny or TASKS[self.task] * LENGTHS[self.length]

    @property
    def cause(self) -> str:
        return FAULTS[self.fault][2] if self.fault in FAULTS else ""

    @property
    def section(self) -> str:
        return FAULTS[self.fault][3] if self.fault in FAULTS else ""

    @property
    def stratum(self) -> tuple:
        """The runs split half and half: a healthy setting at one length (its seeds), or a fault of a library (its
        tasks)."""
        healthy = self.fault == "healthy"
        return (self.library, self.settings, self.task, self.length) if healthy else (self.library, self.fault)


def manifest() -> list[Entry]:
    entries = [Entry(library, settings, task, "healthy", length, seed)
               for library, pairs in HEALTHY.items() for settings, task in pairs
               for length, seeds in HEALTHY_SEEDS.items() for seed in seeds]  # fmt: skip
    for library, pairs in HEALTHY.items():
        defaults = {task: settings for settings, task in reversed(pairs)}  # a task's first settings
        entries += [Entry(library, defaults[task], task, fault, "1x", 1) for task in FAULT_TASKS for fault in FAULTS]
    parts = split(entries)
    return [dataclasses.replace(entry, part=parts[entry.id]) for entry in entries]


def split(entries) -> dict[str, str]:
    """{id: part}, fixed by the ids alone: in each stratum, the ids in the order of their SHA-256, the even ranks in
    calibration and the odd ranks held out (every stratum has an even number of runs)."""
    strata: dict[tuple, list[str]] = {}
    for entry in entries:
        strata.setdefault(entry.stratum, []).append(entry.id)
    ranked = (sorted(ids, key=lambda name: hashlib.sha256(name.encode()).hexdigest()) for ids in strata.values())
    return {name: PARTS[rank % 2] for ids in ranked for rank, name in enumerate(ids)}


def replication() -> list[Entry]:
    """The held-out part's broken runs, each again at REPLICATION_SEED."""
    return [dataclasses.replace(entry, seed=REPLICATION_SEED, part=REPLICATION) for entry in manifest()
            if entry.part == "held-out" and entry.fault != "healthy"]  # fmt: skip


def by_id(entry_id: str) -> Entry:
    named = {entry.id: entry for entry in manifest() + replication()}
    if entry_id not in named:
        raise common.BenchmarkError(f"no run '{entry_id}' in the manifest (python -m benchmarks.doctor_runs plan)")
    return named[entry_id]



# ---- plan: the manifest and the time it costs


def speed_key(entry: Entry) -> tuple:
    """What a run's speed depends on: its library, settings and task, and 50 epochs where the fault sets them."""
    return entry.library, entry.settings, entry.task, "epochs_50" if entry.fault == "epochs_50" else "healthy"


def measure_speeds() -> None:
    """A tiny run (one batch, at least 4,096 steps) of each speed_key, into results/doctor_speeds.csv; its speed is
    steps per second of the process's CPU time, which other work on the machine slows less than its clock."""
    rows, commit = [], code_commit()
    for key, entry in {speed_key(e): e for e in reversed(manifest())}.items():
        with tempfile.TemporaryDirectory() as scratch:
            result = make_run(dataclasses.replace(entry, tiny=max(batch_of(entry), 4096)), Path(scratch) / "run")
        rows.append(dict(zip(("library", "settings", "task", "fault"), key), steps=result["steps"],
                         wall_s=result["wall_s"], cpu_s=result["cpu_s"],
                         steps_per_cpu_s=round(result["steps"] / result["cpu_s"], 1),
                         load_1min=round(os.getloadavg()[0], 2), date=datetime.date.today().isoformat(),
                         commit=commit))  # fmt: skip
        print(*rows[-1].values(), flush=True)
    common.write_rows(SPEEDS_CSV, rows)


def change_of(entry: Entry) -> str:
    """The setting the fault changes, as its library names it, with its value in the run."""
    if entry.fault in ("healthy", "reward_zero"):
        return "" if entry.fault == "healthy" else "the environment pays 0"
    name = FIELDS[entry.library][FAULTS[entry.fault][0]]
    library = {"minippo": lambda e: minippo_config(e).to_dict(), "sb3": sb3_settings, "cleanrl": cleanrl_settings}
    return f"{name}={library[entry.library](entry)[name]:g}"


def manifest_rows(entries: list[Entry]) -> list[dict]:
    return [{"id": e.id, "part": e.part, "library": e.library, "settings": e.settings, "task": e.task,
             "fault": e.fault, "cause": e.cause, "section": e.section, "change": change_of(e), "length": e.length,
             "steps": e.steps, "updates": updates_of(e), "seed": e.seed} for e in entries]  # fmt: skip


def plan(measure: bool) -> int:
    entries = manifest()
    rows = manifest_rows(entries)
    common.write_rows(MANIFEST_CSV, rows)
    common.write_rows(REPLICATION_CSV, manifest_rows(replication()))
    count = Counter((e.library, e.task, e.part, e.fault == "healthy") for e in entries)
    print(f"{len(rows)} runs -> {common.relative(MANIFEST_CSV)}")
    print(f"{'':28} calibration: healthy broken   held-out: healthy broken")
    for library, task in dict.fromkeys((e.library, e.task) for e in entries):
        numbers = [count[library, task, part, healthy] for part in PARTS for healthy in (True, False)]
        print(f"{library:8}{task:20}{'':13}{numbers[0]:7}{numbers[1]:7}{'':11}{numbers[2]:7}{numbers[3]:7}")
    total = Counter((e.part, e.fault == "healthy") for e in entries)
    print(*(f"{part}: {total[part, True]} healthy, {total[part, False]} broken" for part in PARTS), sep="; ")
    if measure:
        measure_speeds()
    if not SPEEDS_CSV.exists():
        print("no measured speeds yet: python -m benchmarks.doctor_runs plan --measure")
        return 0
    speeds = {tuple(r[k] for k in ("library", "settings", "task", "fault")): float(r["steps_per_cpu_s"])
              for r in read_rows(SPEEDS_CSV)}  # fmt: skip
    cpu = Counter()
    for e in entries:
        cpu[e.part] += updates_of(e) * batch_of(e) / speeds[speed_key(e)]
    for part in PARTS:
        print(f"{part}: {cpu[part] / 3600:.1f} CPU hours at the speeds of {common.relative(SPEEDS_CSV)}, "
              f"{cpu[part] / 7200:.1f} h on two cores")  # fmt: skip
    return 0


# ---- run: the runs not yet recorded


def code_commit() -> str:
    return common.git_commit(("minippo", "benchmarks/doctor_runs.py", "benchmarks/doctor_libraries.py",
                              "benchmarks/cleanrl_ppo.py"))


def run(part: str | None, only: list[str], jobs: int, argv) -> int:
    chosen = [by_id(name) for name in only] if only else [e for e in manifest() if part in (None, e.part)]
    chosen = replication() if part == REPLICATION and not only else chosen
    if len({e.part == REPLICATION for e in chosen}) > 1:
        raise common.BenchmarkError("the replication's runs have a record of their own: name them apart")
    record_json = REPLICATION_JSON if chosen and chosen[0].part == REPLICATION else RECORD_JSON
    record = json.loads(record_json.read_text()) if record_json.exists() else {"commands": [], "runs": []}
    done = {row["id"] for row in record["runs"]}
    left = [e for e in chosen if e.id not in done]
    print(f"{len(left)} runs to make, {len(chosen) - len(left)} of those chosen already recorded", flush=True)
    command = common.invocation("doctor_runs", argv)
    record["commands"] += [command] if left and command not in record["commands"] else []
    commit = code_commit()
    os.environ.update(common.THREAD_ENV)  # the workers inherit one math thread each
    with ProcessPoolExecutor(max_workers=jobs, mp_context=get_context("spawn")) as pool:
        futures = {pool.submit(make_run, e, RUN_ROOT / e.id): e for e in left}
        for future in as_completed(futures):
            entry, result = futures[future], future.result()
            result |= {"part": entry.part, "commit": commit, "versions": versions(entry),
                       "date": datetime.date.today().isoformat(),
                       "command": f"python -m benchmarks.doctor_runs run --only {entry.id}"}  # fmt: skip
            record["runs"].append(result)
            record_json.write_text(json.dumps(record, indent=1, ensure_ascii=False) + "\n")
            print(f"{entry.id:55} {result['outcome'][:40]:40} {result['wall_s']:7.0f} s", flush=True)
    return 0


@common.one_line_errors
def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.doctor_runs", description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    planned = commands.add_parser("plan", help="write the manifest and estimate the campaign's CPU time")
    planned.add_argument("--measure", action="store_true", help="time a tiny run of each setting first")
    making = commands.add_parser("run", help="make the runs not yet recorded")
    making.add_argument("--part", choices=(*PARTS, REPLICATION))
    making.add_argument("--only", nargs="+", default=[], metavar="ID")
    making.add_argument("--jobs", type=int, default=1)
    args = parser.parse_args(argv)
    if args.command == "plan":
        return plan(args.measure)
    return run(args.part, args.only, max(1, args.jobs), argv)


if __name__ == "__main__":
    raise SystemExit(main())
