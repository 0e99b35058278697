"""The speed race in one process: raw environment stepping, minippo and Stable-Baselines3 PPO; or, with --sweep,
a small grid trained one run after the other, then on minippo sweep's engine.

    python -m benchmarks.speed                            # Hopper-v5, 5 interleaved rounds -> results/speed.csv
    python -m benchmarks.speed --env MinAtar/Breakout-v1  # the paper's Atari settings -> results/speed_minatar.csv
    python -m benchmarks.speed --sweep --steps 204800     # 4 Hopper runs, alone and on 2 workers -> sweep_speed.csv

The race interleaves its rounds (20,000 random steps, ``--updates`` updates of minippo's ``Trainer`` and of SB3 PPO
with the peers' settings) so that a change in the machine's load hits all three, and reports the medians. --sweep
checks that every progress.csv is the same on both sides but for the clock. The load average goes in the CSV.
"""

from __future__ import annotations

import os

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"  # before NumPy (and torch) start their thread pools

import argparse  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

from benchmarks import common  # noqa: E402

FIELDS = "env contender steps_per_s rounds steps_per_round vs_raw vs_sb3 version load_before load_after machine date"
FIELDS = [*FIELDS.split(), "commit", "command"]
SWEEP_FIELDS = "env grid runs steps workers cpus sequential_s sweep_s speedup sequential_train_s sweep_train_s"
SWEEP_FIELDS = [*SWEEP_FIELDS.split(), "same_progress", "load_before", "load_after", "commit", "command"]
RAW_STEPS = 20_000  # random steps a round


def raw_stepping(env_id: str, steps: int, seed: int) -> float:
    """Steps per second of random actions in the bare environment."""
    import gymnasium as gym

    with gym.make(env_id) as env:
        env.action_space.seed(seed)
        env.reset(seed=seed)
        actions = [env.action_space.sample() for _ in range(steps)]  # sampled before the clock starts
        started = time.perf_counter()
        for action in actions:
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
        return steps / (time.perf_counter() - started)


def sb3_minatar_model(config):
    """SB3 PPO with minippo's ATARI preset translated, on minippo's MinAtar network written in torch."""
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

    def annealed(initial):
        return lambda progress_remaining: initial * progress_remaining  # α falls linearly from 1 to 0

    settings = dict(n_steps=config.horizon, batch_size=config.minibatch_size, n_epochs=config.epochs)
    settings |= dict(gamma=config.gamma, gae_lambda=config.gae_lambda, ent_coef=config.entropy_coef)
    settings |= dict(vf_coef=config.value_coef, max_grad_norm=config.max_grad_norm, learning_rate=annealed(config.lr))
    settings |= dict(clip_range=annealed(config.clip_epsilon), clip_range_vf=annealed(config.clip_epsilon))
    trunk = dict(features_extractor_class=MinAtarTrunk, net_arch=[], share_features_extractor=True)
    env = make_vec_env(config.env_id, config.num_envs, config.seed)
    return PPO("MlpPolicy", env, policy_kwargs=trunk, device="cpu", seed=config.seed, verbose=0, **settings)


def summarize(env_id: str, rounds: dict[str, list[float]], steps: dict[str, int], versions: dict[str, str]) -> list:
    """One row per contender: the median over rounds, and the ratios of the medians."""
    medians = {name: statistics.median(values) for name, values in rounds.items() if values}
    rows = []
    for name in ("raw", "minippo", "sb3"):
        median = medians.get(name)
        row = {"env": env_id, "contender": name, "steps_per_s": "" if median is None else round(median, 1)}
        row |= {"rounds": ";".join(f"{v:.1f}" for v in rounds.get(name, [])), "steps_per_round": steps.get(name, "")}
        for other in ("raw", "sb3"):
            row[f"vs_{other}"] = round(median / medians[other], 3) if median is not None and other in medians else ""
        rows.append({**row, "version": versions.get(name, "")})
    return rows


def sweep_race(args, argv) -> int:
    """Each run's ``minippo train`` in this process, one after the other, then ``minippo sweep`` of the same runs
    (timed from Ray's start to its stop); one row appended to the record."""
    import shlex
    import tempfile
    from pathlib import Path

    from minippo import sweep
    from minippo.cli import main as minippo
    from minippo.records import append_row, read_rows

    runs = sweep.plan([args.env], sweep.parse_seeds(args.seeds), args.steps, sweep.parse_grid([args.grid]))
    if args.workers < 1 or args.steps < 2048:
        common.fail("--workers must be at least 1 and --steps at least one horizon (2048)")

    load_before, commit, seconds = os.getloadavg()[0], common.git_commit(), {}  # the code as it starts
    with tempfile.TemporaryDirectory(prefix="sweep-speed-") as scratch:
        alone, swept = Path(scratch) / "alone", Path(scratch) / "swept"
        started = time.perf_counter()
        for run in runs:
            if minippo(shlex.split(run.command(alone))[1:]) != 0:
                common.fail(f"'{run.command(alone)}' failed")
        seconds["sequential"], started = time.perf_counter() - started, time.perf_counter()
        failed = sweep.Sweep(runs, swept, workers=args.workers, quiet=True).run()
        seconds["sweep"] = time.perf_counter() - started
        if failed:
            common.fail(f"{failed} runs of the sweep failed; see {swept / 'sweep.csv'}")
        sides = {"sequential": alone, "sweep": swept}
        progress = {side: [read_rows(f / run.name / "progress.csv") for run in runs] for side, f in sides.items()}
    train = {side: sum(float(rows[-1]["wall_s"]) for rows in runs_rows) for side, runs_rows in progress.items()}

    def unclocked(rows):
        return [{k: v for k, v in row.items() if k not in ("steps_per_s", "wall_s")} for row in rows]

    steps = runs[0].config.num_updates * runs[0].config.batch_size
    row = {"env": args.env, "grid": args.grid, "runs": len(runs), "steps": steps, "workers": args.workers}
    row |= {"cpus": os.cpu_count(), **{f"{side}_s": round(value, 1) for side, value in seconds.items()}}
    row |= {"speedup": round(seconds["sequential"] / seconds["sweep"], 2)}
    row |= {"sequential_train_s": round(train["sequential"], 1), "sweep_train_s": round(train["sweep"], 1)}
    same = all(unclocked(a) == unclocked(b) for a, b in zip(progress["sequential"], progress["sweep"]))
    row |= {"same_progress": "yes" if same else "no", "load_before": round(load_before, 2)}
    row |= {"load_after": round(os.getloadavg()[0], 2), "commit": commit, "command": common.invocation("speed", argv)}
    append_row(args.csv, SWEEP_FIELDS, row)
    print(
        f"{len(runs)} runs of {args.env}: one after the other {row['sequential_s']} s, on the sweep engine with "
        f"{args.workers} workers {row['sweep_s']} s ({row['speedup']}x); the same progress: {row['same_progress']}"
    )
    return 0 if same else 1


@common.one_line_errors
def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default="Hopper-v5", help="a MuJoCo task, or a MinAtar game (MinAtar/<Game>-v1)")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--updates", type=int, help="timed updates per round for each trainer (3; 5 on MinAtar)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--no-sb3", action="store_true", help="leave Stable-Baselines3 out even if installed")
    parser.add_argument("--csv", help="the record (speed.csv, speed_minatar.csv on MinAtar, sweep_speed.csv --sweep)")
    parser.add_argument("--sweep", action="store_true", help="time a grid alone and on the sweep engine instead")
    parser.add_argument("--grid", default="clip_epsilon=0.1,0.2", help="--sweep: KEY=V1,V2 as minippo sweep takes it")
    parser.add_argument("--seeds", default="1-2", help="--sweep: the seeds")
    parser.add_argument("--steps", type=int, default=102400, help="--sweep: steps per run")
    parser.add_argument("--workers", type=int, default=2, help="--sweep: the engine's workers")
    args = parser.parse_args(argv)
    atari = args.env.startswith("MinAtar/")  # the paper's Atari settings, else its MuJoCo ones (Config's defaults)
    record = "sweep_speed" if args.sweep else "speed_minatar" if atari else "speed"
    args.csv = args.csv or str(common.RESULTS / f"{record}.csv")
    if args.sweep:
        return sweep_race(args, argv)
    args.updates = (5 if atari else 3) if args.updates is None else args.updates
    if args.rounds < 1 or args.updates < 1:
        common.fail("--rounds and --updates must be positive")
    import importlib.util

    import gymnasium as gym

    from benchmarks.peers import sb3_model, version
    from minippo.envs import check_env_id
    from minippo.ppo import Config, Trainer
    from minippo.presets import ATARI

    check_env_id(args.env)  # registers the MinAtar games when asked for one
    load_before = os.getloadavg()[0]
    preset = dict(ATARI, total_steps=10_000_000) if atari else dict(total_steps=1_000_000)
    config = Config(env_id=args.env, seed=args.seed, **preset).validate()
    versions = {"raw": f"gymnasium {gym.__version__}", "minippo": version("minippo")}
    trainer = Trainer(config)  # each trainer after a warm-up update: first touches of memory, caches, lazy imports
    trainer.run_update()
    # {name: (steps done so far, run N updates)}
    contenders = {"minippo": (lambda: trainer.rollout.steps, lambda n: [trainer.run_update() for _ in range(n)])}
    if args.no_sb3 or importlib.util.find_spec("stable_baselines3") is None:
        versions["sb3"] = "skipped: " + ("--no-sb3" if args.no_sb3 else "stable-baselines3 is not installed")
    else:
        versions["sb3"] = version("sb3")
        model = sb3_minatar_model(config) if atari else sb3_model(config)[0]  # the peers' settings
        batch = model.n_steps * model.n_envs
        model.learn(total_timesteps=batch)
        more = lambda n: model.learn(total_timesteps=n * batch, reset_num_timesteps=False)  # noqa: E731
        contenders["sb3"] = (lambda: model.num_timesteps, more)
    rounds: dict[str, list[float]] = {name: [] for name in ("raw", "minippo", "sb3")}
    steps: dict[str, int] = {"raw": RAW_STEPS}
    for number in range(1, args.rounds + 1):
        rounds["raw"].append(raw_stepping(args.env, RAW_STEPS, args.seed + number))
        for name, (done, advance) in contenders.items():
            before, started = done(), time.perf_counter()
            advance(args.updates)
            seconds, steps[name] = time.perf_counter() - started, done() - before
            rounds[name].append(steps[name] / seconds)
        shown = ", ".join(f"{name} {values[-1]:.0f}" for name, values in rounds.items() if values)
        print(f"round {number}: {shown} steps/s", flush=True)
    rows = summarize(args.env, rounds, steps, versions)
    extra = {"load_before": round(load_before, 2), "load_after": round(os.getloadavg()[0], 2)}
    extra["machine"] = f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    extra |= {"date": time.strftime("%Y-%m-%d %H:%M"), "commit": common.git_commit()}
    extra["command"] = common.invocation("speed", argv)
    common.write_rows(args.csv, [{**row, **extra} for row in rows], FIELDS)  # one race per file
    for row in rows:
        print(f"{row['contender']:<8} {row['steps_per_s']!s:>9} steps/s   vs raw {row['vs_raw']!s:>6}   "
              f"vs sb3 {row['vs_sb3']!s:>6}   {row['version']}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
