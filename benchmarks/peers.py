"""Learning quality beside Stable-Baselines3: both libraries' PPO on the same tasks, settings (``sb3_settings``;
benchmarks/README.md tabulates each match), seeds and machine, on minippo sweep's engine.

    python -m benchmarks.peers                       # 3 tasks × seeds 1–5 × 2 libraries × 1M steps: 30 runs
    python -m benchmarks.peers --tasks Hopper-v5 --seeds 1 2 --libraries sb3
    python -m benchmarks.peers --list                # what is recorded, what is left
"""

from __future__ import annotations

import argparse
import functools
import importlib
import importlib.util
import itertools
import json
import os
import shlex
import socket
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from benchmarks import common
from minippo.ppo import Config
from minippo.records import append_row, read_rows
from minippo.run_folder import RunFolder
from minippo.sweep import Run, Sweep

TASKS = ["Hopper-v5", "HalfCheetah-v5", "Walker2d-v5"]
LIBRARIES = ["minippo", "sb3"]
EVAL_EPISODES, EVAL_SEED = 10, 0  # minippo eval's defaults: episode k is reset with seed EVAL_SEED + k
FIELDS = ["library", "version", "task", "seed", "steps", "return_mean", "eval_mean", "wall_s", "commit", "command"]
RUN_ROOT = common.RUNS / "peers"


def sb3_settings(config: Config) -> dict:
    """The arguments of ``stable_baselines3.PPO`` and ``VecNormalize`` that make SB3 train as minippo does with
    ``config``, as JSON (``sb3_model`` makes the torch objects); comments say where SB3 cannot do as minippo does."""
    ppo = dict(n_steps=config.horizon, batch_size=config.minibatch_size, n_epochs=config.epochs)
    # minippo's update k (1-based) of K steps at lr·(1 − (k − 1)/K). SB3 calls the schedule with the progress
    # remaining after update k's rollout, 1 − k/K, so lr·(p + 1/K) gives the same step size.
    ppo["learning_rate"] = {"initial": config.lr, "anneal": config.anneal_lr, "plus": 1 / config.num_updates}
    ppo |= dict(gamma=config.gamma, gae_lambda=config.gae_lambda, clip_range=config.clip_epsilon)
    # SB3 can clip the value only by replacing it (no max with the unclipped loss, as minippo's): left off
    ppo |= dict(clip_range_vf=None, normalize_advantage=config.normalize_advantages, ent_coef=config.entropy_coef)
    # minippo's value loss is ½·mean((V − V^targ)²), SB3's mean((V − V^targ)²): half the coefficient is the same
    # loss, hence the same gradient and the same global-norm clip
    ppo["vf_coef"] = config.value_coef / 2
    ppo["max_grad_norm"] = config.max_grad_norm if config.grad_norm_clipping else float("inf")
    ppo["target_kl"] = config.target_kl  # None in both (the paper has no early stop); SB3's rule would differ
    net = dict(net_arch={"pi": list(config.hidden_sizes), "vf": list(config.hidden_sizes)}, activation_fn="tanh")
    net["share_features_extractor"] = True  # a flatten: no parameters to share; the two MLPs are separate
    net["ortho_init"] = config.orthogonal_init  # gains √2 hidden, 0.01 policy output, 1 value output
    net |= dict(log_std_init=config.log_std_init, optimizer_kwargs={"eps": config.adam_eps})
    ppo |= dict(policy_kwargs=net, device="cpu", seed=config.seed)
    normalize = dict(norm_obs=config.normalize_observations, norm_reward=config.scale_rewards, clip_obs=config.obs_clip)
    normalize |= dict(clip_reward=config.reward_clip, gamma=config.gamma, epsilon=1e-8)
    steps = config.num_updates * config.num_envs * config.horizon
    return {"ppo": ppo, "vec_normalize": normalize, "total_timesteps": steps, "n_envs": config.num_envs}


def version(library: str) -> str:
    """The library's version and its array library's, as the records and the speed race keep them."""
    names = ("stable_baselines3", "torch") if library == "sb3" else ("minippo", "numpy")
    return ", ".join(f"{name.replace('_', '-')} {importlib.import_module(name).__version__}" for name in names)


def minippo_run(config_dict: dict, name: str = "", board=None, resume: dict | None = None) -> dict:
    """The sweep engine's ``train_run``, then ``minippo eval RUN --episodes 10 --seed 0`` of the final policy."""
    from threadpoolctl import threadpool_limits

    from minippo.evaluate import evaluate
    from minippo.sweep import train_run

    result = train_run(config_dict, name, board, resume)
    with threadpool_limits(1), tempfile.TemporaryDirectory(prefix="minippo-eval-") as scratch:
        folder = RunFolder(scratch)
        folder.write_files({RunFolder.POLICY: result["files"][RunFolder.POLICY]})
        result["eval"] = evaluate(folder.policy_npz, EVAL_EPISODES, EVAL_SEED)
    result["version"] = version("minippo")
    return result


def sb3_model(config: Config):
    """SB3's PPO and its VecNormalize environment from ``sb3_settings(config)``, one torch thread (the speed race's
    too)."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    torch.set_num_threads(1)
    settings = sb3_settings(config)
    rate = settings["ppo"]["learning_rate"]
    schedule = (lambda left: rate["initial"] * (left + rate["plus"])) if rate["anneal"] else rate["initial"]
    net = {**settings["ppo"]["policy_kwargs"], "activation_fn": torch.nn.Tanh}
    env = VecNormalize(make_vec_env(config.env_id, settings["n_envs"], config.seed), **settings["vec_normalize"])
    return PPO("MlpPolicy", env, verbose=0, **settings["ppo"] | {"learning_rate": schedule, "policy_kwargs": net}), env


def sb3_run(config_dict: dict, name: str = "", board=None) -> dict:
    """``train_run`` for SB3 PPO, then the same evaluation as minippo's; progress.csv in minippo's columns."""
    import numpy as np
    from stable_baselines3.common.callbacks import BaseCallback
    from threadpoolctl import threadpool_limits

    config = Config.from_dict(config_dict)
    settings = sb3_settings(config)
    rate = settings["ppo"]["learning_rate"]
    total = settings["total_timesteps"]
    rows: list[dict] = []

    class Progress(BaseCallback):
        """One row per update, added once the update is done: when the next rollout starts, or after training."""

        def _on_training_start(self) -> None:
            self.started, self.episodes = time.perf_counter(), 0

        def _on_step(self) -> bool:
            self.episodes += sum(1 for info in self.locals["infos"] if "episode" in info)  # Monitor's episode ends
            return True

        def _on_rollout_start(self) -> None:
            if self.model.num_timesteps:  # not before the first rollout
                self.add_row()

        def add_row(self) -> None:
            returns = [info["r"] for info in self.model.ep_info_buffer]  # the last 100 episodes, original rewards
            wall, step = time.perf_counter() - self.started, self.model.num_timesteps
            row = {"update": len(rows) + 1, "step": step, "episodes": self.episodes}
            row["return_mean"] = float(np.mean(returns)) if returns else float("nan")
            row |= {"lr": self.model.policy.optimizer.param_groups[0]["lr"], "steps_per_s": step / wall, "wall_s": wall}
            rows.append(row)
            if board is not None:
                board.report.remote(name, step, total, row["return_mean"])

    with threadpool_limits(1):
        model, env = sb3_model(config)
        progress = Progress()
        model.learn(total_timesteps=total, callback=progress)
        progress.add_row()
        episodes = sb3_evaluate(model, env, config.env_id, EVAL_EPISODES, EVAL_SEED)
        env.close()
    columns = ["update", "step", "episodes", "return_mean", "lr", "steps_per_s", "wall_s"]
    lines = [",".join(columns)] + [",".join(repr(row[key]) for key in columns) for row in rows]
    described = {"library": "stable-baselines3", "env_id": config.env_id, "seed": config.seed, **settings}
    plain = f"{rate['initial']} * (progress_remaining + {rate['plus']:.6g})" if rate["anneal"] else rate["initial"]
    described["ppo"]["learning_rate"] = plain
    import ray  # a task of the sweep engine

    node = ray.get_runtime_context().get_node_id()[:12] if ray.is_initialized() else ""
    files = {RunFolder.CONFIG: json.dumps(described, indent=2) + "\n", RunFolder.PROGRESS: "\n".join(lines) + "\n"}
    result = {"files": {key: text.encode() for key, text in files.items()}, "last": rows[-1], "eval": episodes}
    return result | {"version": version("sb3"), "node": node, "host": socket.gethostname(), "pid": os.getpid()}


def sb3_evaluate(model, venv, env_id: str, episodes: int, seed: int) -> list[float]:
    """minippo's evaluation for an SB3 model: episodes reset with seeds seed, seed + 1, ..., the mean action (clipped
    by ``predict``), observations normalised with frozen statistics, original rewards summed."""
    import gymnasium as gym
    import numpy as np

    venv.training, venv.norm_reward = False, False
    returns = []
    with gym.make(env_id, disable_env_checker=True) as env:
        for episode in range(episodes):
            obs, _ = env.reset(seed=seed + episode)
            total, done = 0.0, False
            while not done:
                action, _ = model.predict(venv.normalize_obs(np.asarray(obs, dtype=np.float64)), deterministic=True)
                obs, reward, terminated, truncated, _ = env.step(action)
                total, done = total + float(reward), terminated or truncated
            returns.append(total)
    return returns


def peer_run(config_dict: dict, name: str = "", board=None, resume: dict | None = None) -> dict:
    """The engine's task for both libraries, by the run's name; only minippo's runs keep checkpoints to resume."""
    if name.startswith("sb3-"):
        return sb3_run(config_dict, name, board)
    return minippo_run(config_dict, name, board, resume)


@dataclass
class PeerRun(Run):
    """A run of either library; its command is this runner's for that one run."""

    def command(self, out_dir) -> str:
        labels, config = self.labels, self.config
        argv = ["python", "-m", "benchmarks.peers", "--libraries", labels["library"], "--tasks", config.env_id]
        argv += ["--seeds", str(config.seed), "--steps", str(config.total_steps)]
        if str(out_dir) != common.relative(RUN_ROOT):
            argv += ["--runs", str(out_dir)]
        return shlex.join(argv)


def sweep_runs(tasks, seeds, steps, libraries=LIBRARIES) -> list[PeerRun]:
    """Task by task, seed by seed, the libraries side by side (a campaign stopped halfway compares like with like)."""
    runs = []
    for env_id, seed, library in itertools.product(tasks, seeds, libraries):
        config, labels = Config(env_id=env_id, total_steps=steps, seed=seed), {"library": library, "task": env_id}
        runs.append(PeerRun(f"{library}-{env_id}-seed{seed}", config, labels | {"seed": seed}))
    return runs


class PeerSweep(Sweep):
    """The engine with ``peer_run`` as its task, each finished run also recorded in peers.csv (with the evaluation and
    the version, which the engine's sweep.csv lacks)."""

    def __init__(self, runs, root, record_csv, **options):
        super().__init__(runs, root, task=peer_run, **options)
        self.record_csv, self.commit = record_csv, code_commit()

    def finish(self, run, result, error, attempts) -> dict:
        row = super().finish(run, result, error, attempts)
        if result is not None:
            common.compact_progress(self.out / run.name)
            append_row(self.record_csv, FIELDS, peer_row(run, row, result))
        return row


def peer_row(run, row: dict, result: dict) -> dict:
    """A peers.csv row from the engine's sweep row and the task's result."""
    train, evaluation = round(float(row["return_mean"]), 2), round(statistics.fmean(result["eval"]), 2)
    record = {"library": run.labels["library"], "version": result["version"], "task": run.labels["task"]}
    record |= {"seed": run.labels["seed"], "steps": int(row["steps"]), "return_mean": train, "eval_mean": evaluation}
    return record | {"wall_s": round(float(row["wall_s"]), 1), "commit": row["commit"], "command": row["command"]}


def code_commit() -> str:
    """The short commit, with "+dirty" when minippo/ or this file (which sets SB3 up) has uncommitted edits."""
    return common.git_commit(("minippo", "benchmarks/peers.py"))


def evaluate_record(runs_csv, runs_root, record_csv, tasks=TASKS) -> int:
    """minippo's side from another record's runs of the same command (the seven tasks'): each run of ``tasks`` in
    ``runs_csv`` not yet in ``record_csv`` gets the evaluation of its ``runs_root/<task>-seed<S>/policy.npz`` and a
    row with its own command and commit. Returns how many rows were added."""
    from minippo.evaluate import evaluate

    done = {(row["task"], row["seed"]) for row in read_rows(record_csv)}
    added = 0
    for run in read_rows(runs_csv):
        if run["env"] not in tasks or (run["env"], run["seed"]) in done:
            continue
        folder = RunFolder(Path(runs_root) / f"{run['env']}-seed{run['seed']}")
        if not folder.policy_npz.exists():
            where = "the final policies stay on the machine that trained them"
            common.fail(f"no {folder.POLICY} in {folder.path}: {where}")
        returns = evaluate(folder.path, EVAL_EPISODES, EVAL_SEED)
        row = {"library": "minippo", "version": version("minippo"), "task": run["env"], **run}
        row["eval_mean"] = round(statistics.fmean(returns), 2)
        append_row(record_csv, FIELDS, row)
        added += 1
    return added


@common.one_line_errors
def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", nargs="+", default=TASKS, metavar="TASK", help="Gymnasium ids (continuous actions)")
    parser.add_argument("--seeds", nargs="+", type=int, default=[1, 2, 3, 4, 5])
    parser.add_argument("--steps", type=int, default=1_000_000)
    parser.add_argument("--libraries", nargs="+", default=LIBRARIES, choices=LIBRARIES)
    parser.add_argument("--csv", default=str(common.RESULTS / "peers.csv"), help="where to append the records")
    parser.add_argument("--runs", default=str(RUN_ROOT), help="the folder of run folders")
    parser.add_argument("--evaluate", metavar="RUNS_CSV", help="record minippo's side from these runs (in --runs)")
    common.add_sweep_options(parser)
    args = parser.parse_args(argv)
    if args.evaluate:
        added = evaluate_record(args.evaluate, args.runs, args.csv, args.tasks)
        print(f"{added} minippo runs evaluated -> {common.relative(args.csv)}")
        return 0
    common.check_steps(args.steps)
    if len(set(args.seeds)) != len(args.seeds) or len(set(args.tasks)) != len(args.tasks):
        common.fail("a task or a seed is named twice")
    runs = sweep_runs(args.tasks, args.seeds, args.steps, [name for name in LIBRARIES if name in args.libraries])
    if args.list:
        return common.show_list(runs, args.csv, FIELDS)
    import gymnasium as gym

    for env_id in args.tasks:
        if env_id not in gym.registry:
            common.fail(f"unknown task '{env_id}'")
        with gym.make(env_id, disable_env_checker=True) as env:
            if not isinstance(env.action_space, gym.spaces.Box):
                common.fail(f"{env_id} has discrete actions; this comparison is set up for continuous control")
    if "sb3" in args.libraries and importlib.util.find_spec("stable_baselines3") is None:
        install = 'pip install torch==2.13.0 (the CPU wheel) and then pip install -e ".[bench]"'
        common.fail(f"Stable-Baselines3 is not installed: {install}")
    if importlib.util.find_spec("ray"):  # Ray pickles the task by value: on a cluster this module is only here
        importlib.import_module("ray.cloudpickle").register_pickle_by_value(sys.modules[__name__])
    engine = functools.partial(PeerSweep, record_csv=args.csv)
    return common.run_sweep(runs, args.runs, args.csv, FIELDS, args, engine=engine)


if __name__ == "__main__":
    raise SystemExit(main())
