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

import shlex  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

from benchmarks import common  # noqa: E402
from benchmarks.speed import parser_for, race  # noqa: E402

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
    from minippo.errors import MinippoError
    from minippo.minatar import register_games

    parser = parser_for(__doc__.split("\n\n")[0], "MinAtar/Breakout-v1", 5, CSV_PATH)
    args = parser.parse_args(argv)
    try:
        register_games()
    except MinippoError as error:
        common.fail(str(error))
    command = "python -m benchmarks.speed_minatar " + shlex.join(argv if argv is not None else sys.argv[1:])
    return race(args, command, MinippoContender, StableBaselinesContender)


if __name__ == "__main__":
    raise SystemExit(main())
