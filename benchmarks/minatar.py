"""The paper's Atari comparison (its Table 2) in miniature: PPO against A2C on MinAtar's five games.

    python -m benchmarks.minatar --steps N       # every (algorithm, game, seed) not yet recorded, then the table
    python -m benchmarks.minatar --score         # only recompute benchmarks/results/minatar.csv from the records
    python -m benchmarks.minatar --steps N --algorithms A2C --config lr=0.00025 --envs ... --runs-csv ... --runs ...
                                                 # an ablation: one algorithm with a setting changed, its own record

PPO runs ``minippo train --preset atari`` (the paper's Table 5), A2C ``--preset a2c``, on the same network. Both of
the paper's scores, from each run's ``episodes.csv``: the mean return over all of training and over the last 100
episodes; a game is won by the higher mean over seeds. --steps: hours × 3600 × workers × steps/s (``benchmarks.speed
--env MinAtar/Breakout-v1``) / 30.
"""

from __future__ import annotations

import argparse
import itertools
from pathlib import Path

import numpy as np

from benchmarks import common
from minippo.records import read_rows

GAMES = [f"MinAtar/{game}-v1" for game in ("Asterix", "Breakout", "Freeway", "Seaquest", "SpaceInvaders")]
ALGORITHMS = {"PPO": "atari", "A2C": "a2c"}  # name: preset
RUN_FIELDS = ["algorithm", "env", "seed", "steps", "return_mean", "wall_s", "steps_per_s", "commit", "command"]


def run_name(algorithm: str, env_id: str, seed: int, overrides=()) -> str:
    changed = "".join(f"-{text}" for text in overrides)  # an ablation's settings, as minippo sweep names its runs
    return f"{algorithm.lower()}-{env_id.replace('/', '-')}{changed}-seed{seed}"


def sweep_runs(algorithms, envs, seeds, steps, overrides=()) -> list:
    """Game by game (so that a partial table covers whole games), then seed, then algorithm; ``overrides``: KEY=VALUE
    texts, as ``minippo train --config`` takes them, applied over the preset of every run."""
    from minippo.ppo import Config
    from minippo.presets import PRESETS
    from minippo.sweep import Run

    runs = []
    for env_id, seed, algorithm in itertools.product(envs, seeds, algorithms):
        preset = Config(env_id=env_id, total_steps=steps, seed=seed, **PRESETS[ALGORITHMS[algorithm]])
        config = preset.with_overrides(overrides).validate()
        labels = {"algorithm": algorithm, "env": env_id, "seed": seed}
        runs.append(Run(run_name(algorithm, env_id, seed, overrides), config, labels))
    return runs


def write_episodes(run_dir: Path) -> None:
    """episodes.csv (return, length of every finished episode, in order) from the run's final checkpoint."""
    from minippo.checkpoint import load_checkpoint
    from minippo.run_folder import RunFolder

    target, checkpoint = run_dir / "episodes.csv", RunFolder(run_dir).checkpoint_npz
    if target.exists() or not checkpoint.exists():
        return
    rollout = load_checkpoint(checkpoint)["rollout"]  # the Trainer's state_dict: the rollout's finished episodes
    returns, lengths = rollout["returns"], rollout["lengths"]
    episodes = [{"return": f"{value:g}", "length": int(length)} for value, length in zip(returns, lengths)]
    common.write_rows(target, episodes, ["return", "length"])


def scores(run_dir: Path) -> tuple[float, float]:
    """(mean return over all of training, mean over the last 100 episodes) of one run."""
    returns = [float(row["return"]) for row in read_rows(run_dir / "episodes.csv")]
    if not returns:
        raise common.BenchmarkError(f"no finished episode in {common.relative(run_dir)}")
    return float(np.mean(returns)), float(np.mean(returns[-100:]))


def write_table(runs_csv, root, table_csv, envs, seeds) -> list[dict]:
    """Per game, each algorithm's mean over seeds of both scores, and the winner under each rule."""
    recorded = {(row["algorithm"], row["env"], int(row["seed"])) for row in read_rows(runs_csv)}
    table = []
    for env_id in envs:
        row, means = {"env": env_id}, {}
        for algorithm in ALGORITHMS:
            done = [seed for seed in seeds if (algorithm, env_id, seed) in recorded]
            both = np.array([scores(Path(root) / run_name(algorithm, env_id, seed)) for seed in done]).reshape(-1, 2)
            means[algorithm] = both.mean(axis=0) if len(both) else np.full(2, np.nan)
            row[f"{algorithm}_all_training"], row[f"{algorithm}_last_100"] = np.round(means[algorithm], 3).tolist()
            row[f"{algorithm}_seeds"] = len(done)
        for column, rule in enumerate(("all_training", "last_100")):  # decided on the means before rounding
            ppo, a2c = means["PPO"][column], means["A2C"][column]
            winner = "PPO" if ppo > a2c else "A2C" if a2c > ppo else "tie"
            row[f"winner_{rule}"] = "" if np.isnan(ppo) or np.isnan(a2c) else winner
        table.append(row)
    common.write_rows(table_csv, table)
    return table


@common.one_line_errors
def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", nargs="+", default=GAMES, metavar="ENV")
    parser.add_argument("--seeds", nargs="+", type=int, default=[1, 2, 3])
    parser.add_argument("--algorithms", nargs="+", choices=list(ALGORITHMS), default=list(ALGORITHMS))
    parser.add_argument(
        "--config",
        nargs="+",
        default=[],
        metavar="KEY=VALUE",
        help="settings over every run's preset (an ablation: give it its own --runs-csv and --runs)",
    )
    parser.add_argument("--steps", type=int, help="environment steps per run (required unless --score)")
    parser.add_argument("--score", action="store_true", help="only rewrite minatar.csv from the recorded runs")
    parser.add_argument("--runs-csv", default=str(common.RESULTS / "minatar_runs.csv"))
    parser.add_argument("--table-csv", default=str(common.RESULTS / "minatar.csv"))
    parser.add_argument("--runs", default=str(common.RUNS / "minatar"), help="the folder of run folders")
    common.add_sweep_options(parser)
    args = parser.parse_args(argv)
    if not args.score and (args.steps is None or args.steps < 1024):
        common.fail("--steps is required, at least one PPO batch (8 × 128 = 1024 steps)")
    code = 0
    if not args.score:
        runs = sweep_runs(args.algorithms, args.envs, args.seeds, args.steps, args.config)
        code = common.run_sweep(runs, args.runs, args.runs_csv, RUN_FIELDS, args)
        if code == 130 or args.list:  # interrupted, or only listed: the table waits
            return code
    for run_dir in sorted(Path(args.runs).glob("*-MinAtar-*")):
        write_episodes(run_dir)
    if args.config or set(args.algorithms) != set(ALGORITHMS):  # an ablation: its runs, no PPO-against-A2C table
        return code
    table = write_table(args.runs_csv, args.runs, args.table_csv, args.envs, args.seeds)
    for rule in ("all_training", "last_100"):
        won = sum(row[f"winner_{rule}"] == "PPO" for row in table)
        print(f"{rule}: PPO wins {won} of {sum(bool(row[f'winner_{rule}']) for row in table)} games")
    return code


if __name__ == "__main__":
    raise SystemExit(main())
