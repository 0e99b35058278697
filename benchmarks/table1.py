"""Table 1 of the paper, scored as the paper scores it: which surrogate objective works best.

    python -m benchmarks.table1            # random baselines, every run not yet recorded, then results/table1.csv
    python -m benchmarks.table1 --score    # only recompute table1.csv from the records
    python -m benchmarks.table1 --random --envs MinAtar/Breakout-v1    # only the random policy's returns

By default 11 settings × 3 tasks × 3 seeds × 250,000 steps (benchmarks/README.md says what was reduced).
"""

from __future__ import annotations

import argparse
import itertools

from benchmarks import common, scoring
from minippo.records import append_row, read_rows

# (name, objective, Config overrides as --config takes them): the rows of Table 1, in its order
SETTINGS = [("No clipping or penalty", "cpi", [])]
SETTINGS += [(f"Clipping, ε = {eps}", "clip", [f"clip_epsilon={eps}"]) for eps in ("0.1", "0.2", "0.3")]
SETTINGS += [(f"Adaptive KL, d_targ = {d}", "klpen", [f"kl_target={d}"]) for d in ("0.003", "0.01", "0.03")]
SETTINGS += [(f"Fixed KL, β = {b}", "klpen", ["adaptive_kl=false", f"kl_beta={b}"]) for b in ("0.3", "1", "3", "10")]
TASKS = ["HalfCheetah-v5", "Hopper-v5", "InvertedDoublePendulum-v5"]
RUN_FIELDS = ["setting", "env", "seed", "steps", "return_mean", "wall_s", "steps_per_s", "commit", "command"]
RANDOM_FIELDS = ["env", "episodes", "seed", "return_mean", "return_std", "length_mean", "commit", "command"]
RANDOM_CSV = common.RESULTS / "random.csv"


def slug(setting: str) -> str:
    """'Adaptive KL, d_targ = 0.003' -> 'adaptive-kl-dtarg-0.003' (a folder name)."""
    text = setting.lower().replace("ε", "eps").replace("β", "beta").replace("d_targ", "dtarg")
    words = "".join(c if c.isalnum() or c == "." else " " for c in text).split()
    return "-".join(words)


def with_overrides(setting: tuple, overrides: list[str]) -> tuple:
    """A row of SETTINGS with more ``--config`` overrides (KEY=VALUE) for its training."""
    name, objective, own = setting
    return name, objective, [*own, *overrides]


def write_table(runs_csv, random_csv, table_csv, tasks, seeds, steps) -> list[dict]:
    """Score the recorded runs of ``tasks`` × ``seeds`` (``scoring.table1``) and (re)write ``table_csv``."""
    rows = read_rows(runs_csv)
    if not rows:
        raise common.BenchmarkError(f"no runs recorded in {common.relative(runs_csv)} yet")
    table = scoring.table1(rows, read_rows(random_csv), tasks, seeds, (steps // 2048) * 2048)
    common.write_rows(table_csv, table)
    return table


def random_policy(envs, random_csv) -> None:
    """The random policy's mean return (the 0 of each task's scale) on the ``envs`` that ``random_csv`` lacks: uniform
    random actions from the seeded action space, ``gym.make`` defaults, episode k reset with seed + k."""
    import gymnasium as gym
    import numpy as np

    from minippo.envs import check_env_id

    episodes, seed = scoring.RANDOM_EPISODES, scoring.RANDOM_SEED
    recorded = scoring.random_returns(read_rows(random_csv))
    for env_id in envs:
        check_env_id(env_id)  # registers the MinAtar games when asked for one
    for env_id in [env_id for env_id in envs if env_id not in recorded]:
        played = []  # (return, length) of each episode
        with gym.make(env_id) as env:
            env.action_space.seed(seed)
            for episode in range(episodes):
                env.reset(seed=seed + episode)
                total, length, done = 0.0, 0, False
                while not done:
                    _, reward, terminated, truncated, _ = env.step(env.action_space.sample())
                    total, length, done = total + float(reward), length + 1, terminated or truncated
                played.append((total, length))
        returns, lengths = np.array(played).T
        row = {"env": env_id, "episodes": episodes, "seed": seed, "return_mean": round(float(np.mean(returns)), 3)}
        row |= {"return_std": round(float(np.std(returns)), 3), "length_mean": round(float(np.mean(lengths)), 1)}
        row |= {"commit": common.git_commit(), "command": common.invocation("table1", ["--random", "--envs", env_id])}
        append_row(random_csv, RANDOM_FIELDS, row)
        print(f"{env_id}: random policy {row['return_mean']} ± {row['return_std']} over {episodes} episodes")


def sweep_runs(settings, envs, seeds, steps) -> list:
    """The sweep: task by task (so that a partial table already covers whole tasks), then seed, then setting."""
    from minippo.ppo import Config
    from minippo.sweep import Run

    runs = []
    for env_id, seed, setting in itertools.product(envs, seeds, settings):
        name, objective, overrides = setting
        config = Config(env_id=env_id, total_steps=steps, seed=seed, objective=objective).with_overrides(overrides)
        labels = {"setting": name, "env": env_id, "seed": seed}
        runs.append(Run(f"{slug(name)}-{env_id}-seed{seed}", config.validate(), labels))
    return runs


@common.one_line_errors
def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", nargs="+", default=TASKS, metavar="ENV")
    parser.add_argument("--seeds", nargs="+", type=int, default=[1, 2, 3])
    parser.add_argument("--steps", type=int, default=250_000)
    parser.add_argument("--settings", nargs="+", type=int, metavar="N", help="only these rows of Table 1 (1-11)")
    parser.add_argument("--config", nargs="+", default=[], metavar="KEY=VALUE", help="more overrides for every run")
    parser.add_argument("--score", action="store_true", help="only rewrite table1.csv from the recorded runs")
    parser.add_argument("--runs-csv", default=str(common.RESULTS / "table1_runs.csv"))
    parser.add_argument("--random", action="store_true", help="only record the random policy's returns on --envs")
    parser.add_argument("--table-csv", default=str(common.RESULTS / "table1.csv"))
    parser.add_argument("--runs", default=str(common.RUNS / "table1"), help="the folder of run folders")
    common.add_sweep_options(parser)
    args = parser.parse_args(argv)
    common.check_steps(args.steps)
    numbers = args.settings or range(1, len(SETTINGS) + 1)
    if any(not 1 <= number <= len(SETTINGS) for number in numbers):
        common.fail(f"--settings are row numbers of Table 1, from 1 to {len(SETTINGS)}")
    settings = [with_overrides(SETTINGS[number - 1], args.config) for number in numbers]
    if args.list:
        return common.show_list(sweep_runs(settings, args.envs, args.seeds, args.steps), args.runs_csv, RUN_FIELDS)
    code = 0  # 1 when a training failed (it is logged in the runs folder's sweep.csv)
    if args.random or not args.score:
        random_policy(args.envs, RANDOM_CSV)  # the 0 of each task's scale, once
    if args.random:
        return 0
    if not args.score:
        runs = sweep_runs(settings, args.envs, args.seeds, args.steps)
        code = common.run_sweep(runs, args.runs, args.runs_csv, RUN_FIELDS, args)
        if code == 130:  # interrupted: the table waits for the next run of the command
            return code
    table = write_table(args.runs_csv, RANDOM_CSV, args.table_csv, args.envs, args.seeds, args.steps)
    for row in table:
        print(f"{row['setting']:<30} {row['score']:>6.2f}   paper {row['paper_score']:>5.2f}   ({row['runs']} runs)")
    return code


if __name__ == "__main__":
    raise SystemExit(main())
