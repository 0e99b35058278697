"""The speed race on a MinAtar game: raw stepping, minippo and Stable-Baselines3 PPO, same network, same settings.

    python -m benchmarks.speed_minatar            # MinAtar/Breakout-v1, 5 interleaved rounds
                                                  # -> benchmarks/results/speed_minatar.csv

As benchmarks/speed.py races on Hopper, with the paper's Atari settings (``--preset atari``: N = 8, T = 128, K = 3,
minibatches of 256, c1 = 1, c2 = 0.01, ε and the step size annealed) on both sides, and on both sides the network
conv(16, 3×3) → ReLU → dense 128 → ReLU under a policy head and a value head (for SB3 a custom features extractor
shared by both heads, ``net_arch=[]``). SB3 steps its 8 environments in a DummyVecEnv, in one process, as minippo
does; one torch thread, device cpu. Run it while no training is running.
"""

from __future__ import annotations

import os

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"  # before NumPy (and torch) start their thread pools

import argparse  # noqa: E402
import csv  # noqa: E402
import platform  # noqa: E402
import shlex  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from benchmarks import common  # noqa: E402
from benchmarks.speed import FIELDS, raw_stepping, sb3_version, summarize  # noqa: E402

CSV_PATH = common.RESULTS / "speed_minatar.csv"


def atari_config(env_id: str, seed: int):
    from minippo.ppo import Config
    from minippo.presets import ATARI

    return Config(env_id=env_id, seed=seed, total_steps=10_000_000, **ATARI).validate()


class MinippoContender:
    def __init__(self, env_id: str, seed: int):
        from minippo.ppo import Trainer

        self.trainer = Trainer(atari_config(env_id, seed))
        self.trainer.run_update()  # warm-up

    def measure(self, updates: int) -> tuple[float, int]:
        steps_before, started = self.trainer.rollout.steps, time.perf_counter()
        for _ in range(updates):
            self.trainer.run_update()
        steps = self.trainer.rollout.steps - steps_before
        return steps / (time.perf_counter() - started), steps


def sb3_model(env_id: str, seed: int):
    """SB3 PPO with minippo's ATARI preset translated, on minippo's MinAtar trunk written in torch."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

    class MinAtarTrunk(BaseFeaturesExtractor):
        def __init__(self, observation_space):
            super().__init__(observation_space, features_dim=128)
            height, width, channels = observation_space.shape
            self.conv = torch.nn.Conv2d(channels, 16, 3)
            self.dense = torch.nn.Linear((height - 2) * (width - 2) * 16, 128)

        def forward(self, observations):
            images = observations.permute(0, 3, 1, 2)  # NHWC, as MinAtar gives them, to torch's NCHW
            return torch.relu(self.dense(torch.relu(self.conv(images)).flatten(1)))

    torch.set_num_threads(1)
    config = atari_config(env_id, seed)

    def annealed(initial):
        return lambda progress_remaining: initial * progress_remaining  # α falls linearly from 1 to 0

    env = make_vec_env(env_id, config.num_envs, seed)
    return PPO(
        "MlpPolicy",
        env,
        n_steps=config.horizon,
        batch_size=config.minibatch_size,
        n_epochs=config.epochs,
        learning_rate=annealed(config.lr),
        clip_range=annealed(config.clip_epsilon),
        clip_range_vf=annealed(config.clip_epsilon),
        gamma=config.gamma,
        gae_lambda=config.gae_lambda,
        ent_coef=config.entropy_coef,
        vf_coef=config.value_coef,
        max_grad_norm=config.max_grad_norm,
        policy_kwargs=dict(features_extractor_class=MinAtarTrunk, net_arch=[], share_features_extractor=True),
        device="cpu",
        seed=seed,
        verbose=0,
    )


class StableBaselinesContender:
    def __init__(self, env_id: str, seed: int):
        self.model = sb3_model(env_id, seed)
        self.batch = self.model.n_steps * self.model.n_envs
        self.model.learn(total_timesteps=self.batch)  # warm-up: one rollout and one update

    def measure(self, updates: int) -> tuple[float, int]:
        steps_before, started = self.model.num_timesteps, time.perf_counter()
        self.model.learn(total_timesteps=updates * self.batch, reset_num_timesteps=False)
        steps = self.model.num_timesteps - steps_before
        return steps / (time.perf_counter() - started), steps


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default="MinAtar/Breakout-v1")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--updates", type=int, default=5, help="timed updates (8 × 128 steps) per round and trainer")
    parser.add_argument("--raw-steps", type=int, default=20_000, help="random steps per round for raw stepping")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--no-sb3", action="store_true", help="leave Stable-Baselines3 out even if installed")
    parser.add_argument("--csv", default=str(CSV_PATH))
    args = parser.parse_args(argv)
    if args.rounds < 1 or args.updates < 1 or args.raw_steps < 1:
        common.fail("--rounds, --updates and --raw-steps must be positive")
    import gymnasium as gym
    import numpy as np

    import minippo
    from minippo.errors import MinippoError
    from minippo.minatar import register_games

    try:
        register_games()
    except MinippoError as error:
        common.fail(str(error))
    if args.env not in gym.registry:
        common.fail(f"unknown environment id '{args.env}'")
    load_before = os.getloadavg()[0]
    versions = {
        "raw": f"gymnasium {gym.__version__}",
        "minippo": f"minippo {minippo.__version__}, numpy {np.__version__}",
    }
    contenders = {"minippo": MinippoContender(args.env, args.seed)}
    sb3 = None if args.no_sb3 else sb3_version()
    if sb3:
        versions["sb3"] = sb3
        contenders["sb3"] = StableBaselinesContender(args.env, args.seed)
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
        "command": "python -m benchmarks.speed_minatar " + shlex.join(argv if argv is not None else sys.argv[1:]),
    }
    path = Path(args.csv)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as handle:  # one race per file: all its numbers come from the same run
        writer = csv.DictWriter(handle, fieldnames=FIELDS, lineterminator="\n")
        writer.writeheader()
        writer.writerows(
            {**row, **{k: v.strip() if isinstance(v, str) else v for k, v in extra.items()}} for row in rows
        )
    for row in rows:
        print(f"{row['contender']:<8} {row['steps_per_s']!s:>9} steps/s   vs raw {row['vs_raw']!s:>6}   "
              f"vs sb3 {row['vs_sb3']!s:>6}   {row['version']}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
