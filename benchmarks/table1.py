"""Table 1 of the paper at a reduced scale: which surrogate objective works best.

    python benchmarks/table1.py            # random baselines, then every (setting, task, seed) not yet recorded, then
                                           # the scores in benchmarks/results/table1.csv
    python benchmarks/table1.py --score    # only recompute table1.csv from the records

The paper ran 11 settings × 7 tasks × 3 seeds × 1M steps (231M steps). Here: 11 settings × 3 tasks (HalfCheetah-v5,
Hopper-v5, InvertedDoublePendulum-v5) × 3 seeds × 250,000 steps (122 updates of 2048 steps = 249,856 steps), about
24.7M steps; the learning rate anneals to 0 over the 250,000 steps, as it would over 1M. Everything else is the
paper's MuJoCo defaults. Scoring as the paper's: per task, the random policy's mean return is 0 and the best final
return of any run on that task is 1; a setting's score is the mean over its tasks and seeds. Each run's return is
the mean of its last 100 episodes at the end of training.

Table 1 is a sweep on minippo sweep's engine: each run is what ``minippo train ENV --steps N --seed S --out
benchmarks/runs/table1/<setting>-ENV-seedS --quiet <the setting's options>`` runs, as a Ray task of one CPU (one per
core on this machine, or on a cluster with ``--address HOST:PORT``). Runs are recorded in
benchmarks/results/table1_runs.csv (one row per run, with that command); recorded runs are skipped, so the same
command resumes.
"""

from __future__ import annotations

import argparse
import csv
import math
import statistics
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import random_policy  # noqa: E402
import records  # noqa: E402

from minippo.errors import MinippoError  # noqa: E402

# (name, minippo train options, the paper's Table 1 score); the paper's numbers as quoted in ppo-facts.md
SETTINGS = [
    ("No clipping or penalty", ["--objective", "cpi"], -0.39),
    ("Clipping, ε = 0.1", ["--objective", "clip", "--config", "clip_epsilon=0.1"], 0.76),
    ("Clipping, ε = 0.2", ["--objective", "clip", "--config", "clip_epsilon=0.2"], 0.82),
    ("Clipping, ε = 0.3", ["--objective", "clip", "--config", "clip_epsilon=0.3"], 0.70),
    ("Adaptive KL, d_targ = 0.003", ["--objective", "klpen", "--config", "kl_target=0.003"], 0.68),
    ("Adaptive KL, d_targ = 0.01", ["--objective", "klpen", "--config", "kl_target=0.01"], 0.74),
    ("Adaptive KL, d_targ = 0.03", ["--objective", "klpen", "--config", "kl_target=0.03"], 0.71),
    ("Fixed KL, β = 0.3", ["--objective", "klpen", "--config", "adaptive_kl=false", "kl_beta=0.3"], 0.62),
    ("Fixed KL, β = 1", ["--objective", "klpen", "--config", "adaptive_kl=false", "kl_beta=1"], 0.71),
    ("Fixed KL, β = 3", ["--objective", "klpen", "--config", "adaptive_kl=false", "kl_beta=3"], 0.72),
    ("Fixed KL, β = 10", ["--objective", "klpen", "--config", "adaptive_kl=false", "kl_beta=10"], 0.69),
]
TASKS = ["HalfCheetah-v5", "Hopper-v5", "InvertedDoublePendulum-v5"]
SEEDS = [1, 2, 3]
STEPS = 250_000
RANDOM_EPISODES, RANDOM_SEED = 100, 0
RUN_FIELDS = ["setting", "env", "seed", "steps", "return_mean", "wall_s", "steps_per_s", "commit", "command"]
TABLE_FIELDS = ["setting", "score", "score_se", "paper_score", "runs", "tasks", "task_ids", "seeds", "steps", "scale"]
RUNS_CSV = records.RESULTS / "table1_runs.csv"
TABLE_CSV = records.RESULTS / "table1.csv"
RUN_ROOT = records.RUNS / "table1"


def slug(setting: str) -> str:
    """'Adaptive KL, d_targ = 0.003' -> 'adaptive-kl-dtarg-0.003' (a folder name)."""
    text = setting.lower().replace("ε", "eps").replace("β", "beta").replace("d_targ", "dtarg")
    words = "".join(c if c.isalnum() or c == "." else " " for c in text).split()
    return "-".join(words)


def normalized_scores(runs: list[dict], random_return: dict[str, float]) -> dict[str, dict]:
    """Table 1's scoring. ``runs``: dicts with setting, env, return_mean. Per task, the random policy's return maps
    to 0 and the best run's return (over every setting and seed on that task) to 1; each setting's score is the
    mean of its runs' normalised returns. Returns {setting: {"score", "se", "runs", "tasks", "per_task"}}, where
    ``per_task`` maps each task to the mean of the setting's normalised returns on it.

    ``se`` is the standard error of the score from seed to seed: each task's sample variance over its seeds, pooled
    as for a mean over tasks, √(Σ_k s_k²/n_k) / K for K tasks with n_k seeds each (None when a task has one seed)."""
    best: dict[str, float] = {}
    for run in runs:
        best[run["env"]] = max(best.get(run["env"], -float("inf")), float(run["return_mean"]))
    per_task = defaultdict(lambda: defaultdict(list))  # setting -> env -> normalised returns
    for run in runs:
        env_id = run["env"]
        if env_id not in random_return:
            raise records.BenchmarkError(f"no random-policy return recorded for {env_id}")
        span = best[env_id] - random_return[env_id]
        if span <= 0:
            raise records.BenchmarkError(f"on {env_id} no run beats the random policy, so the score is undefined")
        per_task[run["setting"]][env_id].append((float(run["return_mean"]) - random_return[env_id]) / span)
    scores = {}
    for setting, tasks in per_task.items():
        values = [value for task in tasks.values() for value in task]
        se = None
        if all(len(task) > 1 for task in tasks.values()):
            pooled = sum(statistics.variance(task) / len(task) for task in tasks.values())
            se = math.sqrt(pooled) / len(tasks)
        scores[setting] = {
            "score": sum(values) / len(values),
            "se": se,
            "runs": len(values),
            "tasks": len(tasks),
            "per_task": {env_id: sum(task) / len(task) for env_id, task in tasks.items()},
        }
    return scores


def with_overrides(setting: tuple, overrides: list[str]) -> tuple:
    """A row of SETTINGS with more ``--config`` overrides (KEY=VALUE) for its training."""
    name, options, paper = setting
    if not overrides:
        return setting
    if "--config" in options:
        return name, [*options, *overrides], paper
    return name, [*options, "--config", *overrides], paper


def complete_tasks(runs: list[dict], tasks, seeds) -> list[str]:
    """The tasks, in the order given, on which every recorded setting has a run for every seed: a task still being
    run would score its finished settings against a best run that may not have come yet, so it waits."""
    settings = {run["setting"] for run in runs}
    done = {(run["setting"], run["env"], int(run["seed"])) for run in runs}
    return [env_id for env_id in tasks if all((s, env_id, seed) in done for s in settings for seed in seeds)]


def complete_settings(runs: list[dict], tasks, seeds) -> list[str]:
    """The settings that have a run for every task and seed: when a setting is being rerun (after a fix to the code
    it trains), it is scored again only once all its runs are back; the others stay scored meanwhile."""
    done = {(run["setting"], run["env"], int(run["seed"])) for run in runs}
    settings = dict.fromkeys(run["setting"] for run in runs)
    return [s for s in settings if all((s, env_id, seed) in done for env_id in tasks for seed in seeds)]


def random_returns(rows: list[dict]) -> dict[str, float]:
    """{task: the random policy's mean return} from random.csv rows: the baselines Table 1 is scored with."""
    return {
        row["env"]: float(row["return_mean"])
        for row in rows
        if row["episodes"] == str(RANDOM_EPISODES) and row["seed"] == str(RANDOM_SEED)
    }


def write_table(runs_csv, random_csv, table_csv, tasks, seeds, steps) -> list[dict]:
    """Score the recorded runs of ``tasks`` × ``seeds`` and (re)write table1.csv, in the paper's row order. Only the
    settings whose runs are all recorded count (or, while no setting is, the tasks whose runs are all recorded), and
    the table's ``scale`` names the tasks."""
    randoms = random_returns(records.read_rows(random_csv))
    runs = [
        row
        for row in records.read_rows(runs_csv)
        if row["env"] in tasks and int(row["seed"]) in seeds and int(row["steps"]) == (steps // 2048) * 2048
    ]
    if not runs:
        raise records.BenchmarkError(f"no runs recorded in {records.relative(runs_csv)} yet")
    settings = complete_settings(runs, tasks, seeds)
    if settings:  # score the settings that have every run, on every task
        runs = [row for row in runs if row["setting"] in settings]
    else:  # a campaign in progress, task by task: score the tasks that have every run
        tasks = complete_tasks(runs, tasks, seeds)
    if not tasks:
        raise records.BenchmarkError(f"no task has all its runs recorded in {records.relative(runs_csv)} yet")
    runs = [row for row in runs if row["env"] in tasks]
    scores = normalized_scores(runs, randoms)
    scale = (
        f"tasks {' '.join(tasks)}; seeds {' '.join(str(seed) for seed in seeds)}; {(steps // 2048) * 2048:,} steps "
        "per run (paper: 7 tasks, 3 seeds, 1M steps)"
    )
    table = []
    for name, _, paper in SETTINGS:
        if name not in scores:
            continue
        table.append(
            {
                "setting": name,
                "score": round(scores[name]["score"], 2),
                "score_se": "" if scores[name]["se"] is None else round(scores[name]["se"], 2),
                "paper_score": paper,
                "runs": scores[name]["runs"],
                "tasks": scores[name]["tasks"],
                "task_ids": " ".join(tasks),
                "seeds": len(seeds),
                "steps": (steps // 2048) * 2048,
                "scale": scale,
            }
        )
    Path(table_csv).parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(table_csv).with_suffix(".tmp")
    with open(tmp, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=TABLE_FIELDS, lineterminator="\n")
        writer.writeheader()
        writer.writerows(table)
    tmp.replace(table_csv)
    return table


def setting_config(options: list[str]) -> tuple[str, dict]:
    """A setting's ``minippo train`` options -> (objective, {Config field: value}), typed as the command line types
    them: ['--objective', 'klpen', '--config', 'adaptive_kl=false', 'kl_beta=3'] -> ('klpen', {'adaptive_kl': False,
    'kl_beta': 3.0})."""
    from minippo.cli import parse_override
    from minippo.sweep import config_fields

    objective, overrides, words = "clip", {}, list(options)
    while words:
        word = words.pop(0)
        if word == "--objective":
            objective = words.pop(0)
        elif word == "--config":
            while words and not words[0].startswith("--"):
                key, value = parse_override(words.pop(0), config_fields())
                overrides[key] = value
        else:
            raise records.BenchmarkError(f"a setting's options are --objective and --config, not {word}")
    return objective, overrides


def sweep_runs(settings, envs, seeds, steps) -> list:
    """The sweep: task by task (so that a partial table already covers whole tasks), then seed, then setting."""
    from minippo.ppo import Config
    from minippo.sweep import Run

    runs = []
    for env_id in envs:
        for seed in seeds:
            for name, options, _ in settings:
                objective, overrides = setting_config(options)
                config = Config(env_id=env_id, total_steps=steps, seed=seed, objective=objective, **overrides)
                labels = {"setting": name, "env": env_id, "seed": seed}
                runs.append(Run(f"{slug(name)}-{env_id}-seed{seed}", config.validate(), labels, list(options)))
    return runs


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", nargs="+", default=TASKS, metavar="ENV")
    parser.add_argument("--seeds", nargs="+", type=int, default=SEEDS)
    parser.add_argument("--steps", type=int, default=STEPS)
    parser.add_argument("--settings", nargs="+", type=int, metavar="N", help="only these rows of Table 1 (1-11)")
    parser.add_argument(
        "--config", nargs="+", default=[], metavar="KEY=VALUE", help="extra Config overrides for every run"
    )
    parser.add_argument("--score", action="store_true", help="only rewrite table1.csv from the recorded runs")
    parser.add_argument("--runs-csv", default=str(RUNS_CSV))
    parser.add_argument("--random-csv", default=str(random_policy.CSV_PATH))
    parser.add_argument("--table-csv", default=str(TABLE_CSV))
    parser.add_argument("--runs", default=str(RUN_ROOT), help="the folder of run folders")
    records.add_sweep_options(parser)
    args = parser.parse_args(argv)
    if args.steps < 2048:
        records.fail(f"--steps must be at least one horizon (2048), not {args.steps}")
    numbers = args.settings or range(1, len(SETTINGS) + 1)
    if any(not 1 <= number <= len(SETTINGS) for number in numbers):
        records.fail(f"--settings are row numbers of Table 1, from 1 to {len(SETTINGS)}")
    settings = [with_overrides(SETTINGS[number - 1], args.config) for number in numbers]
    code = 0  # 1 when a training failed (it is logged in the runs folder's sweep.csv)
    try:
        if not args.score:
            missing = [
                env_id
                for env_id in args.envs
                if not records.is_recorded(
                    args.random_csv, {"env": env_id, "episodes": RANDOM_EPISODES, "seed": RANDOM_SEED}
                )
            ]
            if missing:
                script = str(Path(__file__).resolve().parent / "random_policy.py")
                subprocess.run(
                    [
                        sys.executable,
                        script,
                        *missing,
                        "--episodes",
                        str(RANDOM_EPISODES),
                        "--seed",
                        str(RANDOM_SEED),
                        "--csv",
                        args.random_csv,
                    ],
                    check=True,
                    cwd=records.ROOT,
                )
            runs = sweep_runs(settings, args.envs, args.seeds, args.steps)
            fields, key = RUN_FIELDS, ("setting", "env", "seed")
            code = records.run_sweep(runs, args.runs, args.runs_csv, fields, key, records.record_row, args)
            if code == 130:  # interrupted: the table waits for the next run of the command
                return code
        table = write_table(args.runs_csv, args.random_csv, args.table_csv, args.envs, args.seeds, args.steps)
    except (records.BenchmarkError, subprocess.CalledProcessError, MinippoError) as error:
        records.fail(str(error))
    for row in table:
        print(f"{row['setting']:<30} {row['score']:>6.2f}   paper {row['paper_score']:>5.2f}   ({row['runs']} runs)")
    return code


if __name__ == "__main__":
    raise SystemExit(main())
