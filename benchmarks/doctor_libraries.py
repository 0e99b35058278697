"""Each library's part in the doctor's campaign (benchmarks/doctor_runs.py): the faults and how each library's setting
takes them, the settings of a run with its fault applied (minippo's Config, Stable-Baselines3's and rl-zoo's
hyperparameters, CleanRL's arguments), and the three runners, each of which trains a run and writes its library's log
into the run's folder."""

from __future__ import annotations

import importlib
import inspect
import math
import shutil
import time
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

import gymnasium as gym

from benchmarks import cleanrl_ppo, common
from minippo.errors import MinippoError

if TYPE_CHECKING:
    from benchmarks.doctor_runs import Entry

# fault: (the neutral setting it changes, how, the cause the doctor should name, its section of the atlas chapter).
# Causes are rule ids of minippo/doctor.py where a rule exists; the others name a rule that does not exist yet.
FAULTS = {
    "lr_x10": ("lr", lambda v: 10 * v, "kl-spike", "atlas-step-size"),
    "lr_x30": ("lr", lambda v: 30 * v, "kl-spike", "atlas-step-size"),
    "epochs_50": ("epochs", lambda v: 50, "kl-high", "atlas-step-size"),
    "clip_10": ("clip", lambda v: 10.0, "no-clip", "atlas-clip"),  # ε = 10: r_t never leaves [1 − ε, 1 + ε]
    "ent_-0.01": ("ent", lambda v: -0.01, "entropy-collapse", "atlas-entropy"),
    "ent_-0.05": ("ent", lambda v: -0.05, "entropy-collapse", "atlas-entropy"),
    "vf_0": ("vf", lambda v: 0.0, "critic-worse-than-constant", "atlas-value-loss"),
    "reward_zero": (None, None, "not-ppo-reward", "atlas-reward"),  # the environment pays 0 at every step (ZeroReward)
}
FIELDS = {  # each library's name for a neutral setting
    "minippo": dict(lr="lr", epochs="epochs", clip="clip_epsilon", ent="entropy_coef", vf="value_coef"),
    "sb3": dict(lr="learning_rate", epochs="n_epochs", clip="clip_range", ent="ent_coef", vf="vf_coef"),
    "cleanrl": dict(lr="learning_rate", epochs="update_epochs", clip="clip_coef", ent="ent_coef", vf="vf_coef"),
}

# rl-zoo's tuned PPO hyperparameters, copied from DLR-RM/rl-baselines3-zoo, hyperparams/ppo.yml at commit
# 22e3ff2450fd92033f7f032915e1f64894a09584 (2026-04-23); "lin_X" is rl-zoo's linear schedule, X × progress remaining.
# Their n_timesteps (1e5, 1e6, 1e5, 1e6) are replaced by this campaign's lengths.
ZOO = {
    "CartPole-v1": dict(n_envs=8, policy="MlpPolicy", n_steps=32, batch_size=256, gae_lambda=0.8, gamma=0.98,
                        n_epochs=20, ent_coef=0.0, learning_rate="lin_0.001", clip_range="lin_0.2"),
    "Acrobot-v1": dict(normalize=True, n_envs=16, policy="MlpPolicy", n_steps=256, gae_lambda=0.94, gamma=0.99,
                       n_epochs=4, ent_coef=0.0),
    "Pendulum-v1": dict(n_envs=4, policy="MlpPolicy", n_steps=1024, gae_lambda=0.95, gamma=0.9, n_epochs=10,
                        ent_coef=0.0, learning_rate=1e-3, clip_range=0.2, use_sde=True, sde_sample_freq=4),
    "LunarLander-v3": dict(n_envs=16, policy="MlpPolicy", n_steps=1024, batch_size=64, gae_lambda=0.98, gamma=0.999,
                           n_epochs=4, ent_coef=0.01),
}  # fmt: skip


# ---- each library's settings, with the fault applied


def faulted(entry: Entry, settings: dict) -> dict:
    """``settings`` (a library's field: value) with the entry's fault changed in it."""
    if entry.fault == "healthy" or FAULTS[entry.fault][0] is None:
        return settings
    neutral, change = FAULTS[entry.fault][:2]
    name = FIELDS[entry.library][neutral]
    return settings | {name: change(settings[name])}


def minippo_config(entry: Entry):
    from minippo.config import Config
    from minippo.presets import ATARI, CARTPOLE_PPO

    preset = {"defaults": {}, "cartpole_ppo": CARTPOLE_PPO, "atari": ATARI}[entry.settings]
    config = Config(**preset | dict(env_id=entry.task, total_steps=entry.steps, seed=entry.seed)).to_dict()
    return Config.from_dict(faulted(entry, config)).validate()


def sb3_settings(entry: Entry) -> dict:
    """rl-zoo's hyperparameters for the entry (SB3's own defaults where it sets none, as rl-zoo does too)."""
    from stable_baselines3 import PPO

    defaults = {name: p.default for name, p in inspect.signature(PPO.__init__).parameters.items()
                if name in FIELDS["sb3"].values()}  # fmt: skip
    tuned = ZOO[entry.task] if entry.settings == "zoo" else {"policy": "MlpPolicy"}
    return faulted(entry, defaults | tuned) | {"n_timesteps": entry.steps}


def cleanrl_settings(entry: Entry) -> dict:
    run = dict(env_id=entry.task, total_timesteps=entry.steps, seed=entry.seed)
    return faulted(entry, cleanrl_ppo.DEFAULTS[entry.settings] | run)


def batch_of(entry: Entry) -> int:
    if entry.library == "minippo":
        return minippo_config(entry).batch_size
    if entry.library == "sb3":
        settings = sb3_settings(entry)
        return settings.get("n_envs", 1) * settings.get("n_steps", 2048)  # SB3's default n_steps
    return cleanrl_ppo.DEFAULTS[entry.settings]["num_envs"] * cleanrl_ppo.DEFAULTS[entry.settings]["num_steps"]


def updates_of(entry: Entry) -> int:
    """minippo and CleanRL train whole batches within the steps asked for; SB3 trains until it has them."""
    rounding = math.ceil if entry.library == "sb3" else math.floor
    return max(1, rounding(entry.steps / batch_of(entry)))


class ZeroReward(gym.RewardWrapper):
    """The fault reward_zero: an environment that pays 0 at every step (episodes end as before)."""

    def reward(self, reward):
        return 0.0


def make_task(task: str, zero_reward: bool) -> gym.Env:
    env = gym.make(task)
    return ZeroReward(env) if zero_reward else env


# ---- the three runners: each writes its library's files into ``folder`` and returns (steps, updates)


def run_minippo(entry: Entry, folder: Path) -> tuple[int, int]:
    import minippo.ppo
    from benchmarks.atlas_faults import replaced

    def zero_rewards(make_env):
        return lambda *args, **kwargs: ZeroReward(make_env(*args, **kwargs))

    patches = [(minippo.ppo, "make_env", zero_rewards)] if entry.fault == "reward_zero" else []
    with replaced(*patches):  # the environment is at fault, not a setting: config.json does not show it
        rows = minippo.ppo.train(minippo_config(entry), out=folder)
    common.compact_progress(folder)  # 6 significant digits, as every committed run folder (benchmarks/README.md)
    return rows[-1]["step"], len(rows)


def run_sb3(entry: Entry, folder: Path) -> tuple[int, int]:
    from collections import OrderedDict

    import yaml
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.logger import configure
    from stable_baselines3.common.vec_env import VecNormalize

    hyper = sb3_settings(entry)
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / "config.yml", "w") as handle:  # as rl-zoo's ExperimentManager saves it
        yaml.dump(OrderedDict(sorted(hyper.items())), handle)
    kwargs = {k: v for k, v in hyper.items() if k not in ("policy", "n_envs", "normalize", "n_timesteps")}
    for key in ("learning_rate", "clip_range"):
        if isinstance(kwargs.get(key), str):  # rl-zoo's "lin_X": X × progress remaining
            kwargs[key] = partial(float.__mul__, float(kwargs[key].split("_")[1]))
    env = make_vec_env(partial(make_task, entry.task, entry.fault == "reward_zero"), hyper.get("n_envs", 1), entry.seed)
    if hyper.get("normalize"):
        env = VecNormalize(env, gamma=hyper.get("gamma", 0.99))  # rl-zoo passes the task's γ on
    model = PPO(hyper["policy"], env, seed=entry.seed, device="cpu", **kwargs)
    model.set_logger(configure(str(folder), ["csv", "tensorboard"]))
    model.learn(total_timesteps=entry.steps)
    env.close()
    return model.num_timesteps, model.num_timesteps // batch_of(entry)


def run_cleanrl(entry: Entry, folder: Path) -> tuple[int, int]:
    make_env = partial(make_task, entry.task, entry.fault == "reward_zero")
    return cleanrl_ppo.train(cleanrl_settings(entry), entry.settings == "ppo_continuous_action", make_env, folder)


RUNNERS = {"minippo": run_minippo, "sb3": run_sb3, "cleanrl": run_cleanrl}


def make_run(entry: Entry, folder: Path) -> dict:
    """Train ``entry`` into ``folder`` (made anew) with one math thread; its outcome, size and clock."""
    import torch
    from threadpoolctl import threadpool_limits

    shutil.rmtree(folder, ignore_errors=True)  # what an interrupted run left
    torch.set_num_threads(1)
    started, cpu_started = time.perf_counter(), time.process_time()
    with threadpool_limits(1):
        try:
            steps, updates = RUNNERS[entry.library](entry, folder)
            outcome = "ok"
        except (MinippoError, ValueError, RuntimeError) as error:  # NaN in minippo, in torch's distributions
            steps, updates, outcome = None, None, f"stopped: {str(error).splitlines()[0][:200]}"
    size = sum(path.stat().st_size for path in folder.rglob("*") if path.is_file() and path.suffix not in (".npz",))
    wall, cpu = round(time.perf_counter() - started, 1), round(time.process_time() - cpu_started, 1)
    return {"id": entry.id, "outcome": outcome, "steps": steps, "updates": updates, "folder_bytes": size,
            "wall_s": wall, "cpu_s": cpu}  # fmt: skip


def versions(entry: Entry) -> str:
    """The versions of what trained and logged the run, and of the files its settings were read from."""
    library = entry.library
    names = {"minippo": ("minippo", "numpy"), "sb3": ("stable_baselines3", "torch"), "cleanrl": ("torch",)}[library]
    names += ("gymnasium",) + (("tensorboard",) if library != "minippo" else ())
    text = ", ".join(f"{name.replace('_', '-')} {importlib.import_module(name).__version__}" for name in names)
    source = {"zoo": ", rl-baselines3-zoo 22e3ff2 (hyperparams/ppo.yml)", "ppo": ", CleanRL fe8d8a0 (ppo.py)",
              "ppo_continuous_action": ", CleanRL fe8d8a0 (ppo_continuous_action.py)"}  # fmt: skip
    return text + source.get(entry.settings, "")
