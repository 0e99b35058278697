"""A run survives anything: killed (SIGKILL) at random updates and resumed, stopped by Ctrl-C, or stopped by a full
disk, it carries on as the uninterrupted run, byte for byte in progress.csv (the clock columns aside) and policy.npz;
and a sweep whose worker is killed retries the run from its last checkpoint and records the same run."""

import csv
import errno
import importlib.util
import os
import random
import shlex
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from minippo.cli import main
from minippo.envs import env_state, load_env_state, make_env
from minippo.minatar import GAMES

pytestmark = pytest.mark.slow  # runs killed and resumed, in processes of their own

TIMING = {"steps_per_s", "wall_s"}  # the clock columns, the only ones that differ between two identical runs
RUNS = {  # small runs: 24 updates of one batch each, a checkpoint after every update
    "CartPole-v1": ["horizon=128", "minibatch_size=64", "epochs=2", "checkpoint_every=1"],
    "Hopper-v5": ["horizon=96", "minibatch_size=32", "epochs=2", "checkpoint_every=1"],
}
if importlib.util.find_spec("minatar") is not None:  # sticky actions and the game's own generator, saved mid-episode
    RUNS["MinAtar/Breakout-v1"] = ["horizon=64", "minibatch_size=32", "epochs=2", "checkpoint_every=1"]
    RUNS["MinAtar/Breakout-v1"] += ["network=minatar_cnn", "shared_network=true"]
UPDATES = 24
NEEDS_MINATAR = pytest.mark.skipif(importlib.util.find_spec("minatar") is None, reason="pip install '.[minatar]'")


def progress_without_clock(folder) -> list[dict]:
    with open(Path(folder) / "progress.csv", newline="") as handle:
        return [{k: v for k, v in row.items() if k not in TIMING} for row in csv.DictReader(handle)]


def assert_same_run(folder, reference) -> None:
    assert progress_without_clock(folder) == progress_without_clock(reference)
    with np.load(Path(folder) / "policy.npz") as a, np.load(Path(reference) / "policy.npz") as b:
        assert sorted(a.files) == sorted(b.files)
        for key in a.files:
            assert a[key].tobytes() == b[key].tobytes(), key


def train_argv(env_id: str, out, *extra) -> list[str]:
    steps = UPDATES * int(RUNS[env_id][0].split("=")[1])
    return ["train", env_id, "--steps", str(steps), "--seed", "7", "--out", str(out), "--quiet", "--config"] + [
        *RUNS[env_id],
        *extra,
    ]


def start(argv) -> subprocess.Popen:
    """``minippo`` in a child process that takes Ctrl-C as a terminal would give it (the default SIGINT action)."""

    def default_sigint():
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
        signal.signal(signal.SIGINT, signal.SIG_DFL)

    return subprocess.Popen(
        [sys.executable, "-m", "minippo", *argv], stderr=subprocess.PIPE, text=True, preexec_fn=default_sigint
    )


def wait_for_rows(process: subprocess.Popen, out: Path, rows: int, timeout: float = 120) -> None:
    """Wait until progress.csv holds ``rows`` updates (or the process ends)."""
    deadline = time.monotonic() + timeout
    while process.poll() is None and time.monotonic() < deadline:
        try:
            if (out / "progress.csv").read_text().count("\n") > rows:  # the header, then one line an update
                return
        except FileNotFoundError:
            pass
        time.sleep(0.005)


def checkpoint_update(out) -> int:
    with np.load(Path(out) / "checkpoint.npz") as data:
        return int(data["update"])


def leftovers(out) -> list[str]:
    return sorted(path.name for path in Path(out).iterdir() if ".tmp" in path.name)


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    """The two runs trained without a stop, by the command line in a process of their own."""
    folders = {}
    for env_id in RUNS:
        out = tmp_path_factory.mktemp("whole") / env_id
        result = subprocess.run([sys.executable, "-m", "minippo", *train_argv(env_id, out)], capture_output=True)
        assert result.returncode == 0, result.stderr
        folders[env_id] = out
    return folders


MINATAR = [pytest.param(f"MinAtar/{game}-v1", marks=NEEDS_MINATAR) for game in GAMES]


@pytest.mark.parametrize(
    "env_id",
    ["CartPole-v1", "Acrobot-v1", "Pendulum-v1", "MountainCar-v0", "Hopper-v5", "Ant-v5", "Humanoid-v5", *MINATAR],
)
def test_an_environment_saved_mid_episode_steps_on_as_the_original(env_id):
    """Saved at step 120 and put back into a fresh environment (reset with another seed), it returns the same
    observations, rewards and episode ends as the original, across resets (its random generator is saved too)."""
    original, copy = make_env(env_id), make_env(env_id)
    original.reset(seed=3)
    space = original.action_space
    actions = np.random.default_rng(0)

    def action():
        if hasattr(space, "n"):
            return int(actions.integers(space.n))
        return actions.uniform(space.low, space.high).astype(space.dtype)

    def step(env, a):
        obs, reward, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            obs = env.reset()[0]
        return np.asarray(obs).tobytes(), float(reward), terminated, truncated

    for _ in range(120):
        step(original, action())
    saved = env_state(original)
    assert saved is not None
    copy.reset(seed=99)
    load_env_state(copy, saved)
    ends = 0
    for t in range(400):
        a = action()
        expected, got = step(original, a), step(copy, a)
        assert got == expected, f"step {120 + t}"
        ends += expected[2] or expected[3]
    assert ends or env_id in ("Hopper-v5", "Ant-v5", "Humanoid-v5", "MountainCar-v0", "MinAtar/Freeway-v1")


@pytest.mark.timeout(300)
@pytest.mark.parametrize("env_id", list(RUNS))
def test_a_run_killed_at_random_updates_resumes_as_the_uninterrupted_run(env_id, uninterrupted, tmp_path):
    """SIGKILL at three random updates, each time resumed with --resume; the run ends as the uninterrupted one."""
    out = tmp_path / env_id
    points = sorted(random.Random(env_id).sample(range(2, UPDATES - 4), 3))
    argv = train_argv(env_id, out)
    killed_at = []
    for point in points:
        process = start(argv)
        wait_for_rows(process, out, point)
        process.send_signal(signal.SIGKILL)
        process.communicate(timeout=60)
        assert process.returncode == -signal.SIGKILL, f"the run ended before the kill at update {point}"
        killed_at.append(checkpoint_update(out))
        argv = ["train", env_id, "--out", str(out), "--resume", "--quiet"]
    finished = subprocess.run([sys.executable, "-m", "minippo", *argv], capture_output=True, text=True)
    assert finished.returncode == 0, finished.stderr
    assert 0 < killed_at[0] < UPDATES and killed_at[-1] < UPDATES, killed_at
    assert_same_run(out, uninterrupted[env_id])


def test_a_full_disk_stops_in_one_line_and_keeps_the_last_checkpoint(tmp_path, monkeypatch, capsys):
    """The fifth .npz write (the checkpoint of update 3) fills the disk halfway through: one line, the checkpoint of
    update 2 intact, no temporary file; once there is room again, --resume ends as the uninterrupted run."""
    savez, calls = np.savez, []

    def disk_fills(file, *args, **kwargs):
        calls.append(file)
        if len(calls) == 5:
            file.write(b"PK\x03\x04 half a zip")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        savez(file, *args, **kwargs)

    whole, out = tmp_path / "whole", tmp_path / "full"
    assert main(train_argv("CartPole-v1", whole, "epochs=1")) == 0
    capsys.readouterr()
    monkeypatch.setattr(np, "savez", disk_fills)
    assert main(train_argv("CartPole-v1", out, "epochs=1")) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and error.startswith("minippo: error: cannot write the run's files in")
    assert "No space left on device" in error and "the checkpoint of update 2 is kept" in error, error
    assert leftovers(out) == [] and checkpoint_update(out) == 2
    with np.load(out / "policy.npz") as policy:
        assert policy["params"].size > 0
    monkeypatch.setattr(np, "savez", savez)
    assert main(["train", "CartPole-v1", "--out", str(out), "--resume", "--quiet"]) == 0
    assert_same_run(out, whole)


def test_resume_of_a_finished_run_says_so_and_changes_nothing(uninterrupted, capsys):
    out = uninterrupted["CartPole-v1"]
    before = {path.name: path.read_bytes() for path in out.iterdir()}
    assert main(["train", "CartPole-v1", "--out", str(out), "--resume", "--quiet"]) == 0
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "has finished (3,072 steps, 24 updates)" in error
    assert "--resume --steps N, N > 3,072" in error
    assert {path.name: path.read_bytes() for path in out.iterdir()} == before
    assert main(["train", "CartPole-v1", "--out", str(out), "--resume", "--steps", "1024"]) == 2
    assert "has already trained 3,072 steps" in capsys.readouterr().err


def test_steps_extend_a_run_to_the_longer_run(tmp_path, capsys):
    """Without annealing, a run of 4 updates extended to 8 is the run of 8; with it (the default), the extension is
    not that run, and one line says so."""
    short, long = tmp_path / "short", tmp_path / "long"
    config = ["--config", "horizon=128", "epochs=1", "anneal_lr=false"]
    assert main(["train", "CartPole-v1", "--steps", "512", "--out", str(short), "--quiet", *config]) == 0
    assert main(["train", "CartPole-v1", "--steps", "1024", "--out", str(long), "--quiet", *config]) == 0
    capsys.readouterr()
    assert main(["train", "CartPole-v1", "--steps", "1024", "--out", str(short), "--resume", "--quiet"]) == 0
    assert capsys.readouterr().err == ""
    assert_same_run(short, long)
    assert (short / "config.json").read_bytes() == (long / "config.json").read_bytes()

    annealed = tmp_path / "annealed"
    assert main(["train", "CartPole-v1", "--steps", "512", "--out", str(annealed), "--quiet", *config[:3]]) == 0
    capsys.readouterr()
    assert main(["train", "CartPole-v1", "--steps", "1024", "--out", str(annealed), "--resume", "--quiet"]) == 0
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "the extended run differs from one trained to 1,024 steps" in error


@pytest.mark.timeout(300)
def test_ctrl_c_checkpoints_then_stops_and_the_run_resumes_as_the_uninterrupted_run(uninterrupted, tmp_path):
    out = tmp_path / "hopper"
    process = start(train_argv("Hopper-v5", out))
    wait_for_rows(process, out, 5)
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 130, stderr
    assert stderr.count("\n") == 1 and "minippo: interrupted; checkpoint written at update" in stderr, stderr
    stopped = checkpoint_update(out)
    assert f"update {stopped};" in stderr and len(progress_without_clock(out)) == stopped < UPDATES
    assert "continue with: minippo train Hopper-v5 --out" in stderr and leftovers(out) == []
    resumed = subprocess.run(
        [sys.executable, "-m", "minippo", "train", "Hopper-v5", "--out", str(out), "--resume", "--quiet"],
        capture_output=True,
    )
    assert resumed.returncode == 0, resumed.stderr
    assert_same_run(out, uninterrupted["Hopper-v5"])


@pytest.mark.timeout(300)
def test_a_second_ctrl_c_stops_at_once_and_keeps_the_last_checkpoint(tmp_path):
    """Updates of four times the paper's size (T = 8192: seconds each, even on a fast machine): the second Ctrl-C,
    while the first waits for the update to end, stops the run in the middle of it."""
    out = tmp_path / "hopper"
    argv = ["train", "Hopper-v5", "--steps", str(6 * 8192), "--horizon", "8192", "--out", str(out), "--quiet"]
    process = start([*argv, "--checkpoint-every", "1"])
    wait_for_rows(process, out, 1)
    process.send_signal(signal.SIGINT)
    time.sleep(0.1)  # the first is handled (it sets the stop), far inside an update of several seconds
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 130, stderr
    assert stderr.count("\n") == 1 and "minippo: interrupted at once; the checkpoint of update" in stderr, stderr
    kept = checkpoint_update(out)
    assert f"update {kept} is kept" in stderr and leftovers(out) == []
    assert len(progress_without_clock(out)) == kept < 6  # the update under way was not finished


GATE_UPDATE = 3  # the update after whose checkpoint the sweep's worker stops for the test to kill it


def train_until_killed(config_dict, name="", board=None, resume=None, gate=""):
    """The sweep's task for the killed-worker test: on its first attempt it trains as ``train_run`` does until the
    board has kept the checkpoint of update ``GATE_UPDATE``, then writes its pid to the file ``gate`` and waits to be
    killed; a retry (``resume`` given) trains as ``train_run`` does. So the kill lands at an update the test chose,
    however fast the machine."""
    import ray

    from minippo.sweep import train_run

    class Gate:  # the board, whose ``keep`` waits for the checkpoint to be kept and stops the run at the gate
        def __init__(self, board):
            self.board, self.report, self.keep = board, board.report, self

        def remote(self, run_name, update, files):
            ray.get(self.board.keep.remote(run_name, update, files))
            if update >= GATE_UPDATE:
                Path(gate).write_text(str(os.getpid()))
                time.sleep(600)

    return train_run(config_dict, name, board if resume is not None else Gate(board), resume)


def kill_at_the_gate(gate: Path, killed: list) -> None:
    """SIGKILL the process whose pid the gate file holds, once it is there."""
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and not gate.exists():
        time.sleep(0.05)
    if gate.exists():
        time.sleep(0.1)  # the pid is written whole (a few bytes)
        pid = int(gate.read_text())
        os.kill(pid, signal.SIGKILL)
        killed.append(pid)


@pytest.mark.timeout(300)
def test_a_sweep_retries_a_killed_worker_s_run_from_its_checkpoint(ray_environment, tmp_path):
    import ray.cloudpickle

    from minippo import sweep

    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])  # the workers cannot import this test module
    gate = tmp_path / "gate"

    def task(config_dict, name="", board=None, resume=None):
        return train_until_killed(config_dict, name, board, resume, str(gate))

    resumed_from = []

    class Noted(sweep.Sweep):
        def finish(self, run, result, error, attempts):
            resumed_from.append(None if result is None else result["resumed_from"])
            return super().finish(run, result, error, attempts)

    out = tmp_path / "sweep"
    killed: list = []
    killer = threading.Thread(target=kill_at_the_gate, args=(gate, killed), daemon=True)
    killer.start()
    runs = sweep.plan(["CartPole-v1"], [2], 4096, settings={"horizon": 256, "epochs": 4, "checkpoint_every": 1})
    assert Noted(runs, out, workers=1, retries=1, quiet=True, task=task).run() == 0
    killer.join(timeout=5)
    assert len(killed) == 1, "the worker did not reach the gate"
    with open(out / "sweep.csv", newline="") as handle:
        (row,) = list(csv.DictReader(handle))
    assert row["status"] == "ok" and row["attempts"] == "2", row
    assert resumed_from == [GATE_UPDATE], "the retry did not start from the checkpoint of the update it was killed at"
    alone = tmp_path / "alone"
    command = shlex.split(row["command"])
    command[command.index("--out") + 1] = str(alone)
    assert main(command[1:]) == 0
    assert_same_run(out / "CartPole-v1-seed2", alone)
    assert float(row["return_mean"]) == float(progress_without_clock(alone)[-1]["return_mean"])


class Drift(gym.Env):
    """A task minippo does not know how to save mid-episode (not one of Gymnasium's MuJoCo or classic-control ones)."""

    observation_space = gym.spaces.Box(-np.inf, np.inf, (2,), np.float64)
    action_space = gym.spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.position = self.np_random.normal(size=2)
        return self.position.copy(), {}

    def step(self, action):
        self.position += self.np_random.normal(size=2) * 0.1 + (action - 0.5)
        return self.position.copy(), -float(abs(self.position).sum()), bool(abs(self.position).max() > 3), False, {}


def test_an_environment_that_cannot_be_saved_is_said_in_one_line_and_restarts(tmp_path, capsys):
    gym.register("Drift-v0", entry_point=Drift, max_episode_steps=50)
    out = tmp_path / "drift"
    argv = ["train", "Drift-v0", "--steps", "256", "--out", str(out), "--quiet", "--config", "horizon=128", "epochs=1"]
    assert main(argv) == 0
    capsys.readouterr()
    assert main(["train", "Drift-v0", "--out", str(out), "--resume", "--steps", "512", "--quiet"]) == 0
    error = capsys.readouterr().err.splitlines()
    assert len(error) == 2 and "the learning rate of updates 1-2" in error[0]
    assert error[1] == (
        "minippo: the checkpoint holds no state of the Drift-v0 environments (minippo cannot save them, or an older "
        "minippo wrote it): they start fresh episodes, so the run goes on differently from one never interrupted"
    )
    assert [row["update"] for row in progress_without_clock(out)] == ["1", "2", "3", "4"]
