"""Runs for ``minippo doctor`` that no threshold was set on: healthy and broken PPO runs of three libraries, each
logged as its library logs it, split by the hashes of the runs' ids into a calibration part and a held-out part.

    python -m benchmarks.doctor_runs plan                  # results/doctor_manifest.csv, and the CPU time it costs
    python -m benchmarks.doctor_runs plan --measure        # first time a tiny run of each setting (doctor_speeds.csv)
    python -m benchmarks.doctor_runs run --part calibration --jobs 2
    python -m benchmarks.doctor_runs run --only sb3-zoo-Pendulum-v1-healthy-1x-seed1
    python -m benchmarks.doctor_runs run --part replication --jobs 2   # the held-out faults again, at a new seed

The manifest (``results/doctor_manifest.csv``: each run's id, part, library, settings, task, fault, the cause the
doctor should name, the setting changed, length, steps and seed) and with it the split are made from this file alone,
never from a run's results: thresholds are set on the calibration part and judged on the held-out part. Each run is
made in ``runs/doctor/<id>/``: minippo's run folder (config.json, progress.csv rounded to 6 digits), Stable-Baselines3's
logger output (its CSV and TensorBoard files, ``configure(folder, ["csv", "tensorboard"])``) with the hyperparameters
in a config.yml as rl-zoo saves them, or the TensorBoard events file of CleanRL's PPO (benchmarks/cleanrl_ppo.py). A
run is recorded in ``results/doctor_runs.json`` with its command, commit, library versions and date; a recorded run
is skipped, so the same command resumes.

The replication part (``results/doctor_manifest_replication.csv``, recorded in ``results/doctor_runs_replication.json``)
was planned after the held-out part had been evaluated: its 48 broken runs again, each at seed 2, which no broken run
had. Nothing is calibrated on it. It asks whether the held-out figures hold on runs nobody has seen, and it judges,
on those runs, the count proposed after the held-out evaluation: the doctor's recall over the runs the fault harmed
(doctor_confusion.harmed: below all four healthy seeds of its setting in the other two parts), beside the recall
over every broken run; both against the same aims (at least 90% flagged, and the right cause first on at least 80%),
with the thresholds and rules unchanged since the held-out evaluation.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import hashlib
import importlib
import inspect
import json
import math
import os
import shutil
import tempfile
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from functools import partial
from multiprocessing import get_context
from pathlib import Path

import gymnasium as gym

from benchmarks import cleanrl_ppo, common
from minippo.errors import MinippoError
from minippo.records import read_rows

MANIFEST_CSV = common.RESULTS / "doctor_manifest.csv"
RECORD_JSON = common.RESULTS / "doctor_runs.json"
SPEEDS_CSV = common.RESULTS / "doctor_speeds.csv"
RUN_ROOT = common.RUNS / "doctor"
PARTS = ("calibration", "held-out")
REPLICATION, REPLICATION_SEED = "replication", 2
REPLICATION_CSV = common.RESULTS / "doctor_manifest_replication.csv"
REPLICATION_JSON = common.RESULTS / "doctor_runs_replication.json"

# steps of a 1x run: the atlas's CartPole (150 updates of 512) and MinAtar (200 of 8 × 128); the others, which the
# atlas does not have, about rl-zoo's n_timesteps for Pendulum (1e5), and LunarLander twice that
TASKS = {"CartPole-v1": 76_800, "Acrobot-v1": 102_400, "Pendulum-v1": 102_400, "LunarLander-v3": 204_800,
         "MinAtar/Breakout-v1": 204_800}  # fmt: skip
LENGTHS = {"1x": 1, "4x": 4}
HEALTHY_SEEDS = {"1x": (1, 2, 3, 4), "4x": (5, 6)}  # other seeds at 4x: a constant step size would repeat a 1x run
FAULT_TASKS = ("CartPole-v1", "Acrobot-v1", "Pendulum-v1", "LunarLander-v3")  # LunarLander: pip install box2d
HEALTHY = {  # library: (settings, task) of its healthy runs; the first settings a task has are its defaults
    "minippo": [("defaults", task) for task in FAULT_TASKS] + [("cartpole_ppo", "CartPole-v1"),
                                                               ("atari", "MinAtar/Breakout-v1")],
    "sb3": [(settings, task) for settings in ("defaults", "zoo") for task in FAULT_TASKS],
    "cleanrl": [("ppo_continuous_action" if task == "Pendulum-v1" else "ppo", task) for task in FAULT_TASKS],
}  # fmt: skip
# Stable-Baselines3 is left out of MinAtar (rl-zoo has no entry for it, and SB3's CnnPolicy needs frames of 36 pixels
# or more), and so is CleanRL (its ppo.py is for vector observations); minippo's a2c preset is not PPO.

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


@dataclass(frozen=True)
class Entry:
    library: str
    settings: str
    task: str
    fault: str  # "healthy" or a key of FAULTS
    length: str  # a key of LENGTHS
    seed: int
    part: str = ""  # calibration or held-out, from ``split``
    tiny: int = 0  # the steps of a smoke run of the same settings (not in the id); 0: the manifest's length

    @property
    def id(self) -> str:
        task = self.task.replace("/", "-")
        return f"{self.library}-{self.settings}-{task}-{self.fault}-{self.length}-seed{self.seed}"

    @property
    def steps(self) -> int:
        return self.tiny or TASKS[self.task] * LENGTHS[self.length]

    @property
    def cause(self) -> str:
        return FAULTS[self.fault][2] if self.fault in FAULTS else ""

    @property
    def section(self) -> str:
        return FAULTS[self.fault][3] if self.fault in FAULTS else ""

    @property
    def stratum(self) -> tuple:
        """The runs split half and half: a healthy setting at one length (its seeds), or a fault of a library (its
        tasks)."""
        healthy = self.fault == "healthy"
        return (self.library, self.settings, self.task, self.length) if healthy else (self.library, self.fault)


def manifest() -> list[Entry]:
    entries = [Entry(library, settings, task, "healthy", length, seed)
               for library, pairs in HEALTHY.items() for settings, task in pairs
               for length, seeds in HEALTHY_SEEDS.items() for seed in seeds]  # fmt: skip
    for library, pairs in HEALTHY.items():
        defaults = {task: settings for settings, task in reversed(pairs)}  # a task's first settings
        entries += [Entry(library, defaults[task], task, fault, "1x", 1) for task in FAULT_TASKS for fault in FAULTS]
    parts = split(entries)
    return [dataclasses.replace(entry, part=parts[entry.id]) for entry in entries]


def split(entries) -> dict[str, str]:
    """{id: part}, fixed by the ids alone: in each stratum, the ids in the order of their SHA-256, the even ranks in
    calibration and the odd ranks held out (every stratum has an even number of runs)."""
    strata: dict[tuple, list[str]] = {}
    for entry in entries:
        strata.setdefault(entry.stratum, []).append(entry.id)
    ranked = (sorted(ids, key=lambda name: hashlib.sha256(name.encode()).hexdigest()) for ids in strata.values())
    return {name: PARTS[rank % 2] for ids in ranked for rank, name in enumerate(ids)}


def replication() -> list[Entry]:
    """The held-out part's broken runs, each again at REPLICATION_SEED."""
    return [dataclasses.replace(entry, seed=REPLICATION_SEED, part=REPLICATION) for entry in manifest()
            if entry.part == "held-out" and entry.fault != "healthy"]  # fmt: skip


def by_id(entry_id: str) -> Entry:
    named = {entry.id: entry for entry in manifest() + replication()}
    if entry_id not in named:
        raise common.BenchmarkError(f"no run '{entry_id}' in the manifest (python -m benchmarks.doctor_runs plan)")
    return named[entry_id]


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


# ---- plan: the manifest and the time it costs


def speed_key(entry: Entry) -> tuple:
    """What a run's speed depends on: its library, settings and task, and 50 epochs where the fault sets them."""
    return entry.library, entry.settings, entry.task, "epochs_50" if entry.fault == "epochs_50" else "healthy"


def measure_speeds() -> None:
    """A tiny run (one batch, at least 4,096 steps) of each speed_key, into results/doctor_speeds.csv; its speed is
    steps per second of the process's CPU time, which other work on the machine slows less than its clock."""
    rows, commit = [], code_commit()
    for key, entry in {speed_key(e): e for e in reversed(manifest())}.items():
        with tempfile.TemporaryDirectory() as scratch:
            result = make_run(dataclasses.replace(entry, tiny=max(batch_of(entry), 4096)), Path(scratch) / "run")
        rows.append(dict(zip(("library", "settings", "task", "fault"), key), steps=result["steps"],
                         wall_s=result["wall_s"], cpu_s=result["cpu_s"],
                         steps_per_cpu_s=round(result["steps"] / result["cpu_s"], 1),
                         load_1min=round(os.getloadavg()[0], 2), date=datetime.date.today().isoformat(),
                         commit=commit))  # fmt: skip
        print(*rows[-1].values(), flush=True)
    common.write_rows(SPEEDS_CSV, rows)


def change_of(entry: Entry) -> str:
    """The setting the fault changes, as its library names it, with its value in the run."""
    if entry.fault in ("healthy", "reward_zero"):
        return "" if entry.fault == "healthy" else "the environment pays 0"
    name = FIELDS[entry.library][FAULTS[entry.fault][0]]
    library = {"minippo": lambda e: minippo_config(e).to_dict(), "sb3": sb3_settings, "cleanrl": cleanrl_settings}
    return f"{name}={library[entry.library](entry)[name]:g}"


def manifest_rows(entries: list[Entry]) -> list[dict]:
    return [{"id": e.id, "part": e.part, "library": e.library, "settings": e.settings, "task": e.task,
             "fault": e.fault, "cause": e.cause, "section": e.section, "change": change_of(e), "length": e.length,
             "steps": e.steps, "updates": updates_of(e), "seed": e.seed} for e in entries]  # fmt: skip


def plan(measure: bool) -> int:
    entries = manifest()
    rows = manifest_rows(entries)
    common.write_rows(MANIFEST_CSV, rows)
    common.write_rows(REPLICATION_CSV, manifest_rows(replication()))
    count = Counter((e.library, e.task, e.part, e.fault == "healthy") for e in entries)
    print(f"{len(rows)} runs -> {common.relative(MANIFEST_CSV)}")
    print(f"{'':28} calibration: healthy broken   held-out: healthy broken")
    for library, task in dict.fromkeys((e.library, e.task) for e in entries):
        numbers = [count[library, task, part, healthy] for part in PARTS for healthy in (True, False)]
        print(f"{library:8}{task:20}{'':13}{numbers[0]:7}{numbers[1]:7}{'':11}{numbers[2]:7}{numbers[3]:7}")
    total = Counter((e.part, e.fault == "healthy") for e in entries)
    print(*(f"{part}: {total[part, True]} healthy, {total[part, False]} broken" for part in PARTS), sep="; ")
    if measure:
        measure_speeds()
    if not SPEEDS_CSV.exists():
        print("no measured speeds yet: python -m benchmarks.doctor_runs plan --measure")
        return 0
    speeds = {tuple(r[k] for k in ("library", "settings", "task", "fault")): float(r["steps_per_cpu_s"])
              for r in read_rows(SPEEDS_CSV)}  # fmt: skip
    cpu = Counter()
    for e in entries:
        cpu[e.part] += updates_of(e) * batch_of(e) / speeds[speed_key(e)]
    for part in PARTS:
        print(f"{part}: {cpu[part] / 3600:.1f} CPU hours at the speeds of {common.relative(SPEEDS_CSV)}, "
              f"{cpu[part] / 7200:.1f} h on two cores")  # fmt: skip
    return 0


# ---- run: the runs not yet recorded


def code_commit() -> str:
    return common.git_commit(("minippo", "benchmarks/doctor_runs.py", "benchmarks/cleanrl_ppo.py"))


def run(part: str | None, only: list[str], jobs: int, argv) -> int:
    chosen = [by_id(name) for name in only] if only else [e for e in manifest() if part in (None, e.part)]
    chosen = replication() if part == REPLICATION and not only else chosen
    if len({e.part == REPLICATION for e in chosen}) > 1:
        raise common.BenchmarkError("the replication's runs have a record of their own: name them apart")
    record_json = REPLICATION_JSON if chosen and chosen[0].part == REPLICATION else RECORD_JSON
    record = json.loads(record_json.read_text()) if record_json.exists() else {"commands": [], "runs": []}
    done = {row["id"] for row in record["runs"]}
    left = [e for e in chosen if e.id not in done]
    print(f"{len(left)} runs to make, {len(chosen) - len(left)} of those chosen already recorded", flush=True)
    command = common.invocation("doctor_runs", argv)
    record["commands"] += [command] if left and command not in record["commands"] else []
    commit = code_commit()
    os.environ.update(common.THREAD_ENV)  # the workers inherit one math thread each
    with ProcessPoolExecutor(max_workers=jobs, mp_context=get_context("spawn")) as pool:
        futures = {pool.submit(make_run, e, RUN_ROOT / e.id): e for e in left}
        for future in as_completed(futures):
            entry, result = futures[future], future.result()
            result |= {"part": entry.part, "commit": commit, "versions": versions(entry),
                       "date": datetime.date.today().isoformat(),
                       "command": f"python -m benchmarks.doctor_runs run --only {entry.id}"}  # fmt: skip
            record["runs"].append(result)
            record_json.write_text(json.dumps(record, indent=1, ensure_ascii=False) + "\n")
            print(f"{entry.id:55} {result['outcome'][:40]:40} {result['wall_s']:7.0f} s", flush=True)
    return 0


@common.one_line_errors
def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.doctor_runs", description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    planned = commands.add_parser("plan", help="write the manifest and estimate the campaign's CPU time")
    planned.add_argument("--measure", action="store_true", help="time a tiny run of each setting first")
    making = commands.add_parser("run", help="make the runs not yet recorded")
    making.add_argument("--part", choices=(*PARTS, REPLICATION))
    making.add_argument("--only", nargs="+", default=[], metavar="ID")
    making.add_argument("--jobs", type=int, default=1)
    args = parser.parse_args(argv)
    if args.command == "plan":
        return plan(args.measure)
    return run(args.part, args.only, max(1, args.jobs), argv)


if __name__ == "__main__":
    raise SystemExit(main())
