"""Chapter 10's ablations: each implementation detail of minippo off, one at a time, on minippo sweep's engine.

    python -m benchmarks.ablations              # every ablation, seeds 1 and 2, Hopper-v5, 163,840 steps
    python -m benchmarks.ablations --list       # what is recorded, what is left
    python -m benchmarks.ablations --only default anneal_lr --seeds 3

Each run is ``minippo train ... --config <the detail>=false``, recorded in results.csv with ``return_last10`` (the
mean of the last 10 updates' returns).
"""

from __future__ import annotations

import argparse
import itertools
from pathlib import Path

from benchmarks import common
from minippo.records import read_rows

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results.csv"
FIELDS = ["ablation", "override", "env", "seed", "steps", "return_mean", "return_last10", "wall_s", "steps_per_s"]
FIELDS += ["commit", "command"]
# The detail each run switches off; "default" is Config() as it is (the paper's MuJoCo settings).
ABLATIONS = ["default", "normalize_advantages", "clip_value_loss", "grad_norm_clipping", "anneal_lr"]
ABLATIONS += ["orthogonal_init", "normalize_observations", "scale_rewards", "use_gae", "shuffle_minibatches"]


def sweep_runs(names, env_id: str, steps: int, seeds) -> list:
    """Seed by seed, so that a partial sweep still covers every ablation once."""
    from minippo.ppo import Config
    from minippo.sweep import Run

    runs = []
    for seed, name in itertools.product(seeds, names):
        override = [] if name == "default" else [f"{name}=false"]
        config = Config(env_id=env_id, total_steps=steps, seed=seed).with_overrides(override)
        labels = {"ablation": name, "override": override[0] if override else "(none)", "env": env_id, "seed": seed}
        runs.append(Run(f"{name}-seed{seed}", config, labels))
    return runs


def last_ten(folder: Path) -> dict:
    tail = [float(row["return_mean"]) for row in read_rows(folder / "progress.csv")[-10:]]
    return {"return_last10": round(sum(tail) / len(tail), 2)}


@common.one_line_errors
def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="benchmarks.ablations", description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default="Hopper-v5")
    parser.add_argument("--steps", type=int, default=163_840, help="per run (80 updates of T = 2048 by default)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--only", nargs="+", choices=ABLATIONS, metavar="ABLATION", help="only these (default: all)")
    common.add_sweep_options(parser)
    args = parser.parse_args(argv)
    common.check_steps(args.steps)
    runs = sweep_runs(args.only or ABLATIONS, args.env, args.steps, args.seeds)
    return common.run_sweep(runs, HERE / "runs", RESULTS, FIELDS, args, more=last_ten)


if __name__ == "__main__":
    raise SystemExit(main())
