"""The speed race on one machine, in one process: raw environment stepping, minippo, and Stable-Baselines3 PPO.

    python -m benchmarks.speed                    # Hopper-v5, 5 interleaved rounds -> benchmarks/results/speed.csv

Each round measures, one after the other:
  raw        random actions in ``gym.make(ENV)`` (its defaults), resetting at episode ends: the ceiling, since any
             trainer has to step the environment too;
  minippo    training throughput with the paper's settings (T = 2048, K = 10, minibatch 64, Config defaults):
             ``--updates`` updates after one warm-up update, through the Python API (``minippo.ppo.Trainer``);
  sb3        Stable-Baselines3 PPO with the same settings, translated from minippo's Config as the side-by-side
             benchmark translates them (``peers.sb3_model``), one env, one torch thread, device cpu, after one
             warm-up rollout and update; skipped and recorded as skipped when it is not installed.
Both trainers get one math thread (OpenBLAS for NumPy, torch's intra-op pool for SB3). The rounds are interleaved
so that a change in the machine's load hits all three; the table keeps each round and reports the median.
Run it while no training is running: it wants the cores to itself, and the 1-minute load average goes in the CSV.
"""

from __future__ import annotations

import os

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"  # before NumPy (and torch) start their thread pools

import argparse  # noqa: E402
import csv  # noqa: E402
import platform  # noqa: E402
import shlex  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from benchmarks import common  # noqa: E402

FIELDS = [
    "env",
    "contender",
    "steps_per_s",
    "rounds",
    "steps_per_round",
    "vs_raw",
    "vs_sb3",
    "version",
    "load_before",
    "load_after",
    "machine",
    "date",
    "commit",
    "command",
]
CSV_PATH = common.RESULTS / "speed.csv"


def raw_stepping(env_id: str, steps: int, seed: int) -> float:
    """Steps per second of random actions in the bare environment."""
    import gymnasium as gym

    env = gym.make(env_id)
    env.action_space.seed(seed)
    env.reset(seed=seed)
    actions = [env.action_space.sample() for _ in range(steps)]  # sampled before the clock starts
    started = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    elapsed = time.perf_counter() - started
    env.close()
    return steps / elapsed


class MinippoContender:
    def __init__(self, env_id: str, seed: int):
        from minippo.ppo import Config, Trainer

        self.trainer = Trainer(Config(env_id=env_id, seed=seed, total_steps=1_000_000))
        self.trainer.run_update()  # warm-up: first touches of memory, caches, lazy imports

    def measure(self, updates: int) -> tuple[float, int]:
        steps_before = self.trainer.rollout.steps
        started = time.perf_counter()
        for _ in range(updates):
            self.trainer.run_update()
        elapsed = time.perf_counter() - started
        steps = self.trainer.rollout.steps - steps_before
        return steps / elapsed, steps


class StableBaselinesContender:
    def __init__(self, env_id: str, seed: int):
        from benchmarks.peers import sb3_model
        from minippo.ppo import Config

        self.model, _ = sb3_model(Config(env_id=env_id, seed=seed, total_steps=1_000_000))  # the peers' settings
        self.model.learn(total_timesteps=2048)  # warm-up: one rollout and one update

    def measure(self, updates: int) -> tuple[float, int]:
        steps_before = self.model.num_timesteps
        started = time.perf_counter()
        self.model.learn(total_timesteps=updates * 2048, reset_num_timesteps=False)
        elapsed = time.perf_counter() - started
        steps = self.model.num_timesteps - steps_before
        return steps / elapsed, steps


def sb3_version() -> str | None:
    try:
        import stable_baselines3
        import torch
    except ImportError:
        return None
    return f"stable-baselines3 {stable_baselines3.__version__}, torch {torch.__version__}"


def summarize(env_id: str, rounds: dict[str, list[float]], steps: dict[str, int], versions: dict[str, str]) -> list:
    """One row per contender: the median over rounds, and the ratios of the medians."""
    medians = {name: statistics.median(values) for name, values in rounds.items() if values}
    rows = []
    for name in ("raw", "minippo", "sb3"):
        median = medians.get(name)
        rows.append(
            {
                "env": env_id,
                "contender": name,
                "steps_per_s": round(median, 1) if median is not None else "",
                "rounds": ";".join(f"{value:.1f}" for value in rounds.get(name, [])),
                "steps_per_round": steps.get(name, ""),
                "vs_raw": round(median / medians["raw"], 3) if median is not None and "raw" in medians else "",
                "vs_sb3": round(median / medians["sb3"], 3) if median is not None and "sb3" in medians else "",
                "version": versions.get(name, ""),
            }
        )
    return rows


def parser_for(description: str, env_id: str, updates: int, csv_path) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--env", default=env_id)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--updates", type=int, default=updates, help="timed updates per round for each trainer")
    parser.add_argument("--raw-steps", type=int, default=20_000, help="random steps per round for raw stepping")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--no-sb3", action="store_true", help="leave Stable-Baselines3 out even if installed")
    parser.add_argument("--csv", default=str(csv_path))
    return parser


def race(args, command: str, minippo_contender, sb3_contender) -> int:
    """Interleaved rounds of raw stepping and the two trainers (made by the two contender classes), the medians
    written to ``args.csv`` with the machine, the load, the commit and ``command``."""
    if args.rounds < 1 or args.updates < 1 or args.raw_steps < 1:
        common.fail("--rounds, --updates and --raw-steps must be positive")
    import gymnasium as gym
    import numpy as np

    import minippo

    if args.env not in gym.registry:
        common.fail(f"unknown environment id '{args.env}'")
    load_before = os.getloadavg()[0]
    versions = {
        "raw": f"gymnasium {gym.__version__}",
        "minippo": f"minippo {minippo.__version__}, numpy {np.__version__}",
    }
    contenders = {"minippo": minippo_contender(args.env, args.seed)}
    sb3 = None if args.no_sb3 else sb3_version()
    if sb3:
        versions["sb3"] = sb3
        contenders["sb3"] = sb3_contender(args.env, args.seed)
    else:
        versions["sb3"] = "skipped: " + ("--no-sb3" if args.no_sb3 else "stable-baselines3 is not installed")
    rounds: dict[str, list[float]] = {name: [] for name in ("raw", "minippo", "sb3")}
    steps: dict[str, int] = {"raw": args.raw_steps}
    for number in range(1, args.rounds + 1):
        rounds["raw"].append(raw_stepping(args.env, args.raw_steps, args.seed + number))
        for name, contender in contenders.items():
            speed, steps[name] = contender.measure(args.updates)
            rounds[name].append(speed)
        shown = ", ".join(f"{name} {values[-1]:.0f}" for name, values in rounds.items() if values)
        print(f"round {number}: {shown} steps/s", flush=True)
    rows = summarize(args.env, rounds, steps, versions)
    extra = {
        "load_before": round(load_before, 2),
        "load_after": round(os.getloadavg()[0], 2),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d %H:%M"),
        "commit": common.git_commit(),
        "command": command.strip(),
    }
    path = Path(args.csv)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as handle:  # one race per file: all its numbers come from the same run
        writer = csv.DictWriter(handle, fieldnames=FIELDS, lineterminator="\n")
        writer.writeheader()
        writer.writerows({**row, **extra} for row in rows)
    for row in rows:
        print(f"{row['contender']:<8} {row['steps_per_s']!s:>9} steps/s   vs raw {row['vs_raw']!s:>6}   "
              f"vs sb3 {row['vs_sb3']!s:>6}   {row['version']}")  # fmt: skip
    return 0


def main(argv=None) -> int:
    args = parser_for(__doc__.split("\n\n")[0], "Hopper-v5", 3, CSV_PATH).parse_args(argv)
    command = "python -m benchmarks.speed " + shlex.join(argv if argv is not None else sys.argv[1:])
    return race(args, command, MinippoContender, StableBaselinesContender)


if __name__ == "__main__":
    raise SystemExit(main())
