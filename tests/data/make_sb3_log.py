"""Regenerate tests/data/sb3_cartpole/progress.csv: Stable-Baselines3's CSV log of a short PPO run on CartPole-v1.

    python tests/data/make_sb3_log.py

Made with stable-baselines3 2.9.2 and torch on the CPU; the doctor's tests read it as a log from another library.
"""

from pathlib import Path

import torch
from stable_baselines3 import PPO
from stable_baselines3.common.logger import configure

FOLDER = Path(__file__).resolve().parent / "sb3_cartpole"
STEPS = 5120  # 20 iterations of n_steps = 256, so 19 rows that carry the train/ columns


def main() -> None:
    torch.set_num_threads(1)
    FOLDER.mkdir(exist_ok=True)
    (FOLDER / "progress.csv").unlink(missing_ok=True)
    model = PPO("MlpPolicy", "CartPole-v1", n_steps=256, batch_size=64, n_epochs=4, seed=0, device="cpu")
    model.set_logger(configure(str(FOLDER), ["csv"]))
    model.learn(total_timesteps=STEPS)


if __name__ == "__main__":
    main()
