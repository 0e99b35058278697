"""The paper's seven MuJoCo tasks (Gymnasium v5), 1,000,000 steps, 3 seeds, paper defaults, on minippo sweep's engine.

    python -m benchmarks.seven_tasks                       # every (task, seed) not yet recorded, Hopper first
    python -m benchmarks.seven_tasks --envs Hopper-v5 --seeds 1 2 3
    python -m benchmarks.seven_tasks --list                # what is recorded, what is left

Each run is ``minippo train ENV --steps 1000000 --seed S``, recorded in results/mujoco.csv; recorded runs are skipped.
"""

from __future__ import annotations

import argparse
import itertools

from benchmarks import common
from benchmarks.scoring import SEVEN_TASKS as TASKS

FIELDS = ["env", "seed", "steps", "return_mean", "wall_s", "steps_per_s", "commit", "command"]


def sweep_runs(envs, seeds, steps) -> list:
    """The sweep: every task × seed at the paper's defaults, task by task."""
    from minippo.ppo import Config
    from minippo.sweep import Run

    runs = itertools.product(envs, seeds)
    return [Run(f"{e}-seed{s}", Config(env_id=e, total_steps=steps, seed=s), {"env": e, "seed": s}) for e, s in runs]


@common.one_line_errors
def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", nargs="+", default=TASKS, choices=TASKS, metavar="ENV", help="of the seven tasks")
    parser.add_argument("--seeds", nargs="+", type=int, default=[1, 2, 3])
    parser.add_argument("--steps", type=int, default=1_000_000)
    parser.add_argument("--csv", default=str(common.RESULTS / "mujoco.csv"), help="where to append the records")
    parser.add_argument("--runs", default=str(common.RUNS / "mujoco"), help="the folder of run folders")
    common.add_sweep_options(parser)
    args = parser.parse_args(argv)
    common.check_steps(args.steps)
    runs = sweep_runs(args.envs, args.seeds, args.steps)
    return common.run_sweep(runs, args.runs, args.csv, FIELDS, args)


if __name__ == "__main__":
    raise SystemExit(main())
