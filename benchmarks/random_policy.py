"""The random policy's mean return, the zero of Table 1's normalised score.

    python -m benchmarks.random_policy HalfCheetah-v5 Hopper-v5 --episodes 100 --seed 0

Uniform random actions from the action space (seeded), ``gym.make`` defaults, one row per task appended to
benchmarks/results/random.csv; a task already recorded with the same episodes and seed is skipped.
"""

from __future__ import annotations

import argparse

from benchmarks import common
from benchmarks.scoring import RANDOM_EPISODES, RANDOM_SEED
from minippo.records import append_row, read_rows

FIELDS = ["env", "episodes", "seed", "return_mean", "return_std", "length_mean", "commit", "command"]
CSV_PATH = common.RESULTS / "random.csv"


def random_returns(env_id: str, episodes: int, seed: int) -> tuple[list[float], list[int]]:
    import gymnasium as gym

    env = gym.make(env_id)
    env.action_space.seed(seed)
    returns, lengths = [], []
    for episode in range(episodes):
        env.reset(seed=seed + episode)
        total, length, done = 0.0, 0, False
        while not done:
            _, reward, terminated, truncated, _ = env.step(env.action_space.sample())
            total += float(reward)
            length += 1
            done = terminated or truncated
        returns.append(total)
        lengths.append(length)
    env.close()
    return returns, lengths


def main(argv=None) -> int:
    import numpy as np

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("envs", nargs="+", metavar="ENV")
    parser.add_argument("--episodes", type=int, default=RANDOM_EPISODES)
    parser.add_argument("--seed", type=int, default=RANDOM_SEED)
    parser.add_argument("--csv", default=str(CSV_PATH))
    args = parser.parse_args(argv)
    if args.episodes < 1:
        common.fail(f"--episodes must be at least 1, not {args.episodes}")
    from minippo.envs import check_env_id
    from minippo.errors import MinippoError

    for env_id in args.envs:
        try:
            check_env_id(env_id)  # registers the MinAtar games when asked for one
        except MinippoError as error:
            common.fail(str(error))
    for env_id in args.envs:
        key = {"env": env_id, "episodes": args.episodes, "seed": args.seed}
        if any(all(row[k] == str(v) for k, v in key.items()) for row in read_rows(args.csv)):
            print(f"{env_id}: already recorded")
            continue
        returns, lengths = random_returns(env_id, args.episodes, args.seed)
        argv = [env_id, "--episodes", str(args.episodes), "--seed", str(args.seed)]
        row = {**key, "return_mean": round(float(np.mean(returns)), 3), "return_std": round(float(np.std(returns)), 3)}
        row |= {"length_mean": round(float(np.mean(lengths)), 1), "commit": common.git_commit()}
        row["command"] = common.invocation("random_policy", argv)
        append_row(args.csv, FIELDS, row)
        print(f"{env_id}: random policy {row['return_mean']} ± {row['return_std']} over {args.episodes} episodes")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
