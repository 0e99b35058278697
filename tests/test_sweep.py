"""``minippo sweep`` on Ray: a grid on a local Ray instance matches ``minippo train`` bitwise; Ctrl-C keeps the
finished runs and the same command resumes; a failing run is recorded and the others finish; and a two-node cluster
started with ``ray start`` on this machine (loopback only) runs the sweep on both nodes."""

import csv
import os
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from minippo import sweep
from minippo.cli import main

ROOT = Path(__file__).resolve().parents[1]
TIMING = {"steps_per_s", "wall_s"}  # the clock columns, the only ones that differ between two identical runs


@pytest.fixture(autouse=True)
def _ray(ray_environment):
    """Every test here runs in the session's Ray environment (conftest.py)."""


def rows_of(path) -> list[dict]:
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def progress_without_clock(folder) -> list[dict]:
    return [{k: v for k, v in row.items() if k not in TIMING} for row in rows_of(Path(folder) / "progress.csv")]


def assert_same_as_train_alone(row: dict, scratch: Path) -> None:
    """Run the row's ``minippo train`` command alone into ``scratch`` and compare with the sweep's folder."""
    argv = shlex.split(row["command"])
    assert argv[:2] == ["minippo", "train"]
    swept = Path(argv[argv.index("--out") + 1])
    argv[argv.index("--out") + 1] = str(scratch)
    assert main(argv[1:] + ["--force"]) == 0
    assert progress_without_clock(swept) == progress_without_clock(scratch)
    assert (swept / "config.json").read_bytes() == (scratch / "config.json").read_bytes()
    with np.load(swept / "policy.npz") as a, np.load(scratch / "policy.npz") as b:
        assert sorted(a.files) == sorted(b.files)
        for key in a.files:
            assert a[key].tobytes() == b[key].tobytes(), key
    assert (swept / "curve.png").stat().st_size > 0 and (swept / "checkpoint.npz").exists()


# planning and bad input (no Ray)


def test_seeds_grid_and_plan():
    assert sweep.parse_seeds("1-3") == [1, 2, 3] and sweep.parse_seeds("1-2,7") == [1, 2, 7]
    grid = sweep.parse_grid(["clip_epsilon=0.1,0.3", "hidden_sizes=32x32,64", "anneal_lr=false,true"])
    assert grid == [("clip_epsilon", [0.1, 0.3]), ("hidden_sizes", [(32, 32), (64,)]), ("anneal_lr", [False, True])]
    runs = sweep.plan(["CartPole-v1", "Acrobot-v1"], [1, 2], 4096, grid[:2], {"objective": "klpen", "kl_target": 0.003})
    assert len(runs) == 2 * 2 * 2 * 2
    first = runs[0]
    assert first.name == "CartPole-v1-clip_epsilon=0.1-hidden_sizes=32x32-seed1"
    assert first.labels == {"env": "CartPole-v1", "seed": 1, "clip_epsilon": "0.1", "hidden_sizes": "32x32"}
    assert first.config.objective == "klpen" and first.config.kl_target == 0.003
    assert first.config.hidden_sizes == (32, 32) and first.config.total_steps == 4096
    assert first.command("out") == (  # cli.train_argv's words: the changed fields in Config's order
        "minippo train CartPole-v1 --steps 4096 --seed 1 --out out/CartPole-v1-clip_epsilon=0.1-hidden_sizes=32x32-"
        "seed1 --objective klpen --clip-epsilon 0.1 --kl-target 0.003 --hidden-sizes 32,32 --quiet"
    )
    assert [run.config.env_id for run in runs[-4:]] == ["Acrobot-v1"] * 4


def test_a_sweep_file_holds_the_arguments(tmp_path):
    from minippo.cli import build_parser

    (tmp_path / "eps.sweep").write_text(
        "# clipping on two tasks\nCartPole-v1 Acrobot-v1\n--seeds 1-3 --steps 4096  # short\n"
        "--grid clip_epsilon=0.1,0.2\n--out 'runs/eps sweep'\n"
    )
    args = build_parser().parse_args(["sweep", f"@{tmp_path / 'eps.sweep'}", "--workers", "2"])
    assert args.env_ids == ["CartPole-v1", "Acrobot-v1"] and args.seeds == "1-3" and args.steps == 4096
    assert args.grid == ["clip_epsilon=0.1,0.2"] and args.out == "runs/eps sweep" and args.workers == 2


@pytest.mark.parametrize(
    "words, message",
    [
        (["--seeds", "3-1"], "--seeds takes numbers and ranges"),
        (["--grid", "clip_epsilom=0.1,0.2"], "unknown config field 'clip_epsilom'; did you mean clip_epsilon?"),
        (["--grid", "clip_epsilon=0.1", "--config", "clip_epsilon=0.2"], "both swept (--grid) and fixed"),
        (["--grid", "lr=fast"], "cannot read 'fast' as float"),
        (["--grid", "seed=1,2"], "give the tasks, --seeds and --steps instead"),
        (["--workers", "0"], "--workers must be at least 1"),
        (["--address", "127.0.0.1:1"], "no Ray cluster answers at 127.0.0.1:1"),
        (["--address", "cluster"], "--address takes HOST:PORT, not 'cluster'"),
    ],
)
def test_bad_input_gets_one_line(words, message, capsys, tmp_path):
    code = main(["sweep", "CartPole-v1", "--steps", "4096", "--out", str(tmp_path / "s"), *words])
    error = capsys.readouterr().err
    assert code == 2 and message in error and error.count("\n") == 1
    assert not (tmp_path / "s").exists()


def test_unknown_task_is_refused_before_ray_starts(capsys, tmp_path, monkeypatch):
    monkeypatch.setattr(sweep, "start_ray", lambda *a: pytest.fail("Ray started"))
    assert main(["sweep", "CartPole-v9", "--steps", "4096", "--out", str(tmp_path)]) == 2
    assert "CartPole-v9" in capsys.readouterr().err


def test_missing_ray_is_one_line(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray now raises ImportError
    with pytest.raises(sweep.MinippoError, match=r'not installed: pip install "minippo\[sweep\]"'):
        sweep.start_ray(None, None)


def test_a_csv_of_another_sweep_is_refused(tmp_path, monkeypatch, capsys):
    """Resuming skips the runs with an ok row, but only when the row's command is this run's (Ray's tasks are
    replaced here by the same training in this process)."""

    def in_process(runs, on_result, *args, **kwargs):
        for run in runs:
            on_result(run, sweep.train_run(run.config.to_dict(), run.name), "", 1)

    monkeypatch.setattr(sweep, "execute", in_process)
    words = ["sweep", "CartPole-v1", "--steps", "2048", "--out", str(tmp_path / "s"), "--quiet"]
    assert main(words) == 0 and main(words) == 0  # the second time, nothing to do
    assert "all 1 runs are recorded" in capsys.readouterr().err
    assert len(rows_of(tmp_path / "s" / "sweep.csv")) == 1
    assert main([*words, "--config", "lr=0.001"]) == 2
    error = capsys.readouterr().err
    assert "holds CartPole-v1-seed1 made by 'minippo train CartPole-v1 --steps 2048" in error
    assert "give this sweep another --out or --csv" in error and error.count("\n") == 1


# on a local Ray instance


def test_local_sweep_matches_minippo_train_bitwise(tmp_path):
    out = tmp_path / "sweep"
    words = ["sweep", "CartPole-v1", "--seeds", "1-2", "--steps", "4096", "--grid", "clip_epsilon=0.1,0.3"]
    assert main([*words, "--out", str(out), "--workers", "2", "--quiet"]) == 0
    rows = rows_of(out / "sweep.csv")
    assert sorted((row["clip_epsilon"], row["seed"]) for row in rows) == [
        ("0.1", "1"),
        ("0.1", "2"),
        ("0.3", "1"),
        ("0.3", "2"),
    ]
    assert list(rows[0]) == ["env", "seed", "clip_epsilon", *sweep.RESULT_FIELDS]
    assert {row["status"] for row in rows} == {"ok"} and {row["steps"] for row in rows} == {"4096"}
    assert all(row["node"] and row["host"] == socket.gethostname() and row["commit"] for row in rows)
    returns = {float(row["return_mean"]) for row in rows}
    assert len(returns) == 4  # four different runs
    for row in rows:
        assert_same_as_train_alone(row, tmp_path / "alone")
        assert float(row["return_mean"]) == float(rows_of(Path(tmp_path / "alone") / "progress.csv")[-1]["return_mean"])


def test_a_failing_run_is_recorded_and_the_others_finish(tmp_path):
    out = tmp_path / "sweep"
    words = ["sweep", "CartPole-v1", "--steps", "4096", "--grid", "lr=1e30,0.0003", "--retries", "1", "--quiet"]
    assert main([*words, "--out", str(out), "--workers", "2"]) == 1  # one failed
    rows = {row["lr"]: row for row in rows_of(out / "sweep.csv")}
    assert rows["1e+30"]["status"] == "failed" and rows["1e+30"]["attempts"] == "2"
    assert rows["1e+30"]["error"].startswith("NonFiniteError: non-finite loss or gradient at update 1")
    assert "\n" not in rows["1e+30"]["error"] and rows["1e+30"]["return_mean"] == ""
    assert not (out / "CartPole-v1-lr=1e+30-seed1").exists()
    assert rows["0.0003"]["status"] == "ok" and rows["0.0003"]["attempts"] == "1"
    assert (out / "CartPole-v1-lr=0.0003-seed1" / "progress.csv").exists()


def session_processes(sid: int) -> list[int]:
    """The processes of session ``sid`` (a process started with start_new_session and everything it started)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[3]) == sid and fields[0] != "Z":
                found.append(int(entry.name))
    return found


def stop_session(process: subprocess.Popen, grace: float = 10.0) -> None:
    """Stop a process started in its own session, then anything of that session still alive."""
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            pass
    for pid in session_processes(process.pid):
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    if process.poll() is None:
        process.wait(timeout=10)


def as_a_terminal_job() -> None:
    """In the child before it starts: Ctrl-C as a shell leaves it for a job it starts, whatever the test process
    inherited or set (the default action, not blocked), so that the sweep's own handling is what is tested."""
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def ctrl_c_until_it_stops(process: subprocess.Popen, csv_path: Path, presses: int = 3) -> int:
    """Ctrl-C to the process's whole group, as a terminal sends it, then wait (up to a minute) for the process to end.
    A user who sees the sweep train on after a Ctrl-C presses it again; so does this, at most ``presses`` times. One
    more row may be written while the sweep stops (the run that finished with the Ctrl-C); two more mean the sweep
    went on training. Returns how many presses it took."""
    for press in range(1, presses + 1):
        rows = len(rows_of(csv_path))
        os.killpg(process.pid, signal.SIGINT)
        deadline = time.monotonic() + 60
        while process.poll() is None and len(rows_of(csv_path)) < rows + 2 and time.monotonic() < deadline:
            time.sleep(0.2)
        if process.poll() is not None or time.monotonic() >= deadline:
            return press
    return presses


def test_ctrl_c_keeps_finished_runs_and_the_same_command_resumes(tmp_path):
    out = tmp_path / "sweep"
    # eight runs of a few seconds each, one at a time: after the first finishes, the Ctrl-C lands well before the last
    argv = [sys.executable, "-m", "minippo", "sweep", "CartPole-v1", "--seeds", "1-8", "--steps", "49152"]
    argv += ["--out", str(out), "--workers", "1", "--quiet"]
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, [])
    inherited = f"SIGINT in the test process: {signal.getsignal(signal.SIGINT)}, blocked signals: {blocked}"
    first = subprocess.Popen(
        argv, cwd=tmp_path, start_new_session=True, stderr=subprocess.PIPE, text=True, preexec_fn=as_a_terminal_job
    )
    try:
        deadline = time.monotonic() + 90
        while not (out / "sweep.csv").exists() and time.monotonic() < deadline and first.poll() is None:
            time.sleep(0.2)
        assert (out / "sweep.csv").exists(), "no run finished"
        listening = listening_addresses(session_processes(first.pid))  # the local Ray: driver, raylet, workers
        presses = ctrl_c_until_it_stops(first, out / "sweep.csv")
        _, stderr = first.communicate(timeout=60)
        deadline = time.monotonic() + 20
        while session_processes(first.pid) and time.monotonic() < deadline:
            time.sleep(0.2)
        left = session_processes(first.pid)  # the workers, and the local Ray with them, have stopped
    finally:
        stop_session(first)
    assert first.returncode == 130, f"{stderr} ({presses} Ctrl-C presses; {inherited})"
    if presses > 1:  # seen on a loaded machine: the sweep went on training after a Ctrl-C, as if it was never sent
        warnings.warn(f"the sweep needed {presses} Ctrl-C presses to stop", stacklevel=1)
    assert not left, [Path(f"/proc/{pid}/cmdline").read_bytes()[:100] for pid in left]
    assert listening and listening <= LOOPBACK, listening
    assert "interrupted;" in stderr and "the same command continues" in stderr
    kept = rows_of(out / "sweep.csv")
    assert 1 <= len(kept) < 8 and {row["status"] for row in kept} == {"ok"}
    stamps = {row["seed"]: (out / f"CartPole-v1-seed{row['seed']}" / "progress.csv").stat().st_mtime_ns for row in kept}

    again = subprocess.Popen(argv, cwd=tmp_path, start_new_session=True, stderr=subprocess.PIPE, text=True)
    try:
        _, stderr = again.communicate(timeout=120)
    finally:
        stop_session(again)  # whatever happened, no Ray process of this test outlives it
    assert again.returncode == 0, stderr
    assert f"{len(kept)} already recorded" in stderr
    rows = rows_of(out / "sweep.csv")
    assert sorted(row["seed"] for row in rows) == [str(seed) for seed in range(1, 9)]  # each run once, none twice
    for seed, stamp in stamps.items():  # the runs recorded before the stop were not run again
        assert (out / f"CartPole-v1-seed{seed}" / "progress.csv").stat().st_mtime_ns == stamp


# a two-node cluster on this machine


LOOPBACK = {"127.0.0.1", "::1", "::ffff:127.0.0.1"}


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def listening_addresses(pids) -> set[str]:
    """The local addresses on which the processes ``pids`` accept TCP connections."""
    inodes = set()
    for pid in pids:
        try:
            for fd in Path(f"/proc/{pid}/fd").iterdir():
                target = os.readlink(fd)
                if target.startswith("socket:["):
                    inodes.add(target[8:-1])
        except OSError:
            continue
    found = set()
    for table, width in (("/proc/net/tcp", 8), ("/proc/net/tcp6", 32)):
        for line in Path(table).read_text().splitlines()[1:]:
            parts = line.split()
            if parts[3] == "0A" and parts[9] in inodes:  # LISTEN
                raw = parts[1].split(":")[0]
                if width == 8:
                    found.add(socket.inet_ntop(socket.AF_INET, bytes.fromhex(raw)[::-1]))
                else:
                    words = [bytes.fromhex(raw[i : i + 8])[::-1] for i in range(0, 32, 8)]
                    found.add(socket.inet_ntop(socket.AF_INET6, b"".join(words)))
    return found


# ``ray start`` for a second node refuses to run when Ray is told to stay on one machine, and otherwise replaces the
# address 127.0.0.1 by the machine's network address. This runs the same ``ray start`` but keeps 127.0.0.1.
SECOND_NODE = (
    "import sys; from ray._private import services; services.resolve_ip_for_localhost = lambda host: host; "
    "from ray.scripts.scripts import main; sys.argv[0] = 'ray'; sys.exit(main())"
)


@pytest.fixture
def two_nodes(tmp_path):
    """A Ray head and a second node on 127.0.0.1, one CPU each, each with its own temporary folder; stopped after."""
    port = free_port()
    short = Path(tempfile.mkdtemp(prefix="ray", dir="/tmp"))  # Ray's socket paths must fit in 107 bytes
    common = ["--block", "--node-ip-address=127.0.0.1", "--num-cpus=1", "--disable-usage-stats"]
    head = subprocess.Popen(
        ["ray", "start", "--head", f"--port={port}", "--include-dashboard=false", *common]
        + ["--temp-dir", str(short / "head")],
        start_new_session=True,
        stdout=open(tmp_path / "head.log", "w"),
        stderr=subprocess.STDOUT,
    )
    started = [head]
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=0.5).close()
                break
            except OSError:
                assert head.poll() is None, (tmp_path / "head.log").read_text()[-2000:]
                time.sleep(0.2)
        node = subprocess.Popen(
            [sys.executable, "-c", SECOND_NODE, "start", f"--address=127.0.0.1:{port}", *common]
            + ["--temp-dir", str(short / "node"), f"--dashboard-agent-listen-port={free_port()}"],
            start_new_session=True,
            stdout=open(tmp_path / "node.log", "w"),
            stderr=subprocess.STDOUT,
            env={**os.environ, "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "1"},
        )
        started.append(node)
        yield f"127.0.0.1:{port}", started
    finally:
        for process in reversed(started):  # the second node first, then the head
            stop_session(process)
        shutil.rmtree(short, ignore_errors=True)
        assert not any(session_processes(process.pid) for process in started)


def test_a_sweep_runs_on_both_nodes_of_a_two_node_cluster(two_nodes, tmp_path):
    import ray

    address, processes = two_nodes
    ray.init(address=address, log_to_driver=False)
    try:
        deadline = time.monotonic() + 90
        while len([n for n in ray.nodes() if n["Alive"]]) < 2 and time.monotonic() < deadline:
            time.sleep(0.5)
        nodes = {n["NodeID"][:12]: n for n in ray.nodes() if n["Alive"]}
    finally:
        ray.shutdown()
    assert len(nodes) == 2, (tmp_path / "node.log").read_text()[-2000:]
    assert {n["NodeManagerAddress"] for n in nodes.values()} == {"127.0.0.1"}

    out = tmp_path / "sweep"
    # runs long enough (a few seconds) that the second run starts while the first still holds its node's one CPU
    words = ["sweep", "CartPole-v1", "--seeds", "1-2", "--steps", "16384", "--grid", "clip_epsilon=0.1,0.3"]
    assert main([*words, "--out", str(out), "--address", address, "--quiet"]) == 0
    rows = rows_of(out / "sweep.csv")
    assert len(rows) == 4 and {row["status"] for row in rows} == {"ok"}, rows
    ran_on = [row["node"] for row in rows]
    assert set(ran_on) == set(nodes), (ran_on, list(nodes))  # runs on both nodes, and only there
    for row in rows:
        assert_same_as_train_alone(row, tmp_path / "alone")

    pids = [pid for process in processes for pid in session_processes(process.pid)]
    addresses = listening_addresses(pids)
    assert addresses and addresses <= LOOPBACK, addresses
