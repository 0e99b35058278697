"""The paper's seven MuJoCo tasks (Gymnasium v5), 1,000,000 steps, 3 seeds, paper defaults.

    python benchmarks/seven_tasks.py                       # every (task, seed) not yet recorded, Hopper first
    python benchmarks/seven_tasks.py --envs Hopper-v5 --seeds 1 2 3
    python benchmarks/seven_tasks.py --list                # what is recorded, running, to do

Each training is ``minippo train ENV --steps 1000000 --seed S --out benchmarks/runs/mujoco/ENV-seedS --quiet``;
when it finishes, one row is appended to benchmarks/results/mujoco.csv with the command that made it. Recorded
(task, seed) pairs are skipped, so the script resumes where it stopped; start it twice to run two trainings at
once (each claims its run with a file lock). A run folder left with a checkpoint but no record is resumed.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import records  # noqa: E402

TASKS = [  # Hopper first (the core issue's check), then the cheap tasks, then the two like Hopper
    "Hopper-v5",
    "InvertedPendulum-v5",
    "InvertedDoublePendulum-v5",
    "Reacher-v5",
    "Swimmer-v5",
    "HalfCheetah-v5",
    "Walker2d-v5",
]
SEEDS = [1, 2, 3]
STEPS = 1_000_000
FIELDS = ["env", "seed", "steps", "return_mean", "wall_s", "steps_per_s", "commit", "command"]
CSV_PATH = records.RESULTS / "mujoco.csv"
RUN_ROOT = records.RUNS / "mujoco"


def run_dir(env_id: str, seed: int, root=None) -> Path:
    return Path(root or RUN_ROOT) / f"{env_id}-seed{seed}"


def record_row(env_id: str, seed: int, folder, commands: list[str], commit: str) -> dict:
    """The mujoco.csv row of a finished run folder: the last update's numbers from its progress.csv."""
    last = records.last_progress(folder)
    if last is None:
        raise records.BenchmarkError(f"{records.relative(folder)} has no progress.csv rows")
    return {
        "env": env_id,
        "seed": seed,
        "steps": int(last["step"]),
        "return_mean": round(float(last["return_mean"]), 2),
        "wall_s": round(float(last["wall_s"]), 1),
        "steps_per_s": round(float(last["steps_per_s"]), 1),
        "commit": commit,
        "command": " && ".join(commands),
    }


def pending(envs, seeds, csv_path) -> list[tuple[str, int]]:
    done = {(row["env"], row["seed"]) for row in records.read_rows(csv_path)}
    return [(env_id, seed) for env_id in envs for seed in seeds if (env_id, str(seed)) not in done]


def run_one(env_id: str, seed: int, steps: int, csv_path, root, claims) -> str:
    folder = run_dir(env_id, seed, root)
    with records.claim(folder.name, claims) as mine:
        if not mine:
            return "claimed by another runner"
        if records.is_recorded(csv_path, {"env": env_id, "seed": seed}):
            return "already recorded"
        commands = records.launch_or_resume(env_id, steps, seed, folder, [], claims)
        if commands is None:
            return "running outside this runner"
        records.compact_progress(folder)
        row = record_row(env_id, seed, folder, commands, records.launch_commit(folder, claims))
        records.append_row(csv_path, FIELDS, row, unique=("env", "seed"))
        return f"recorded: return {row['return_mean']}, {row['steps_per_s']} steps/s, {row['wall_s']} s"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", nargs="+", default=TASKS, metavar="ENV")
    parser.add_argument("--seeds", nargs="+", type=int, default=SEEDS)
    parser.add_argument("--steps", type=int, default=STEPS)
    parser.add_argument("--csv", default=str(CSV_PATH), help="where to append the records")
    parser.add_argument("--runs", default=str(RUN_ROOT), help="the folder of run folders")
    parser.add_argument("--list", action="store_true", help="show what is recorded and what is left, then stop")
    args = parser.parse_args(argv)
    unknown = [env_id for env_id in args.envs if env_id not in TASKS]
    if unknown:
        records.fail(f"unknown task {', '.join(unknown)}; the seven are {', '.join(TASKS)}")
    if args.steps < 2048:
        records.fail(f"--steps must be at least one horizon (2048), not {args.steps}")
    claims = Path(args.runs) / ".claims"
    todo = pending(args.envs, args.seeds, args.csv)
    if args.list:
        for row in records.read_rows(args.csv):
            print(f"recorded  {row['env']:<26} seed {row['seed']}  return {row['return_mean']:>9}")
        for env_id, seed in todo:
            print(f"to do     {env_id:<26} seed {seed}")
        return 0
    failures = 0
    for env_id, seed in todo:
        try:
            status = run_one(env_id, seed, args.steps, args.csv, args.runs, claims)
        except records.BenchmarkError as error:
            status, failures = f"failed: {error}", failures + 1
        print(f"{env_id} seed {seed}: {status}", flush=True)
    return 1 if failures else 0


if __name__ == "__main__":
    raise SystemExit(main())
