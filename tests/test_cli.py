"""The command line as a user meets it: real subprocesses, exit codes, one-line errors, files on disk."""

import dataclasses
import subprocess
import sys
import typing

import gymnasium as gym
import numpy as np
import pytest

from minippo.cli import main, train_argv, train_config
from minippo.config import Config, field_types
from minippo.flags import option


def run(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "minippo", *args], capture_output=True, text=True, timeout=timeout)


def assert_one_line_error(result, *fragments):
    assert result.returncode != 0
    assert "Traceback" not in result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("minippo: error:"), result.stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]


@pytest.fixture(scope="module")
def trained_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "cartpole"
    result = run(
        "train",
        "CartPole-v1",
        "--steps",
        "1024",
        "--seed",
        "3",
        "--out",
        str(out),
        "--config",
        "horizon=512",
        "minibatch_size=128",
        "epochs=2",
    )
    assert result.returncode == 0, result.stderr
    return out, result


def test_train_writes_the_run_folder(trained_run):
    out, result = trained_run
    for name in ("config.json", "progress.csv", "policy.npz", "checkpoint.npz", "curve.png"):
        assert (out / name).stat().st_size > 0
    header = (out / "progress.csv").read_text().splitlines()[0].split(",")
    for column in (
        "step",
        "episodes",
        "return_mean",
        "approx_kl",
        "clip_fraction",
        "entropy",
        "value_loss",
        "explained_variance",
        "lr",
        "steps_per_s",
        "wall_s",
    ):
        assert column in header
    assert "CartPole-v1: 1024 steps" in result.stdout


def test_eval_prints_mean_and_std(trained_run):
    out, _ = trained_run
    result = run("eval", str(out), "--episodes", "3")
    assert result.returncode == 0, result.stderr
    assert "±" in result.stdout and "over 3 episodes" in result.stdout


def test_plot_overlays_runs(trained_run, tmp_path):
    out, _ = trained_run
    result = run("plot", str(out), str(out), "--out", str(tmp_path / "curves.png"))
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "curves.png").read_bytes()[:4] == b"\x89PNG"


def test_existing_out_is_refused_and_kept(trained_run):
    out, _ = trained_run
    before = (out / "progress.csv").read_bytes()
    result = run("train", "CartPole-v1", "--steps", "512", "--out", str(out))
    assert_one_line_error(result, "exists", "--force", "--resume")
    assert (out / "progress.csv").read_bytes() == before


@pytest.mark.parametrize(
    "args, fragments",
    [
        (["train", "Hoper-v5", "--steps", "100", "--out", "{tmp}/x"], ["unknown environment id", "Hopper-v5"]),
        (["train", "Blackjack-v1", "--steps", "100", "--out", "{tmp}/x"], ["unsupported observation space"]),
        (["train", "CartPole-v1", "--steps", "0", "--out", "{tmp}/x"], ["--steps"]),
        (["train", "CartPole-v1", "--steps", "-5", "--out", "{tmp}/x"], ["--steps"]),
        (["train", "CartPole-v1", "--steps", "99999999999999", "--out", "{tmp}/x"], ["--steps"]),
        (["train", "CartPole-v1", "--steps", "ten", "--out", "{tmp}/x"], ["invalid int value"]),
        (["train", "CartPole-v1", "--steps", "100", "--out", "{tmp}/x", "--config", "horizn=5"], ["horizon"]),
        (["train", "CartPole-v1", "--steps", "100", "--out", "{tmp}/x", "--config", "epochs=many"], ["epochs"]),
        (["train", "CartPole-v1", "--steps", "100", "--out", "{tmp}/x", "--resume"], ["no checkpoint"]),
        (["eval", "{tmp}/nothing-here"], ["no policy"]),
        (["eval", "{tmp}/corrupt", "--episodes", "2"], ["corrupted"]),
        (["eval", "{tmp}/garbage.npz"], ["corrupted", "not an .npz archive"]),
        (["train", "hopper-v5", "--steps", "100", "--out", "{tmp}/x"], ["did you mean Hopper-v5"]),
        (["plot", "{tmp}/nothing-here", "--out", "{tmp}/p.png"], ["no run folder"]),
        (["dance"], ["invalid choice"]),
    ],
)
def test_bad_input_gets_one_line_and_a_nonzero_exit(tmp_path, args, fragments):
    (tmp_path / "corrupt").mkdir()
    (tmp_path / "corrupt" / "policy.npz").write_bytes(b"PK\x03\x04 this is not a zip archive")
    (tmp_path / "garbage.npz").write_bytes(b"garbage")  # NumPy reads this as a pickle, and advises allow_pickle
    result = run(*[a.replace("{tmp}", str(tmp_path)) for a in args])
    assert_one_line_error(result, *fragments)
    assert "allow_pickle" not in result.stderr


def test_an_id_like_nothing_gets_no_guess(tmp_path):
    result = run("train", "ALE/Pong-v5", "--steps", "100", "--out", str(tmp_path / "x"))
    assert_one_line_error(result, "unknown environment id 'ALE/Pong-v5'")
    assert "did you mean" not in result.stderr


@pytest.mark.parametrize(
    "command, phrases",
    [
        ("train", ["env_id", "a Gymnasium id", "--steps", "environment steps to train", "--seed", "(default: 1)",
                   "--out", "the run folder", "(default: clip)"]),
        ("eval", ["a run folder", "episodes to run", "(default: 10)", "(default: 0)", "--gif"]),
        ("plot", ["run folders", "the PNG to write", "the figure's title"]),
    ],
)  # fmt: skip
def test_every_argument_is_explained_with_its_default(command, phrases):
    result = run(command, "--help")
    assert result.returncode == 0, result.stderr
    text = " ".join(result.stdout.split())  # argparse wraps lines
    for phrase in phrases:
        assert phrase in text, phrase
    assert "(default: None)" not in text


def test_steps_that_are_not_whole_batches_are_said(tmp_path):
    out = tmp_path / "cut"
    result = run("train", "CartPole-v1", "--steps", "1300", "--out", str(out), "--config", "horizon=512", "epochs=1")
    assert result.returncode == 0, result.stderr
    assert "--steps 1,300 is not a multiple of the batch (N·T = 512 steps); training 1,024 steps (2 updates)" in (
        result.stderr
    )
    assert (out / "progress.csv").read_text().splitlines()[-1].split(",")[1] == "1024"
    # the bar shows one rate, the trainer's steps/s, not tqdm's own count of steps a second beside it
    assert "steps/s" in result.stderr and "step/s" not in result.stderr.replace("steps/s", "")


def test_whole_batches_train_without_a_notice(trained_run):
    _, result = trained_run
    assert "not a multiple" not in result.stderr


def test_a_cartpole_run_films_a_gif(trained_run, tmp_path):
    out, _ = trained_run
    result = run("eval", str(out), "--episodes", "1", "--gif", str(tmp_path / "cartpole.gif"))
    assert result.returncode == 0, result.stderr
    assert result.stderr.strip() == ""
    from PIL import Image

    with Image.open(tmp_path / "cartpole.gif") as gif:
        assert gif.n_frames > 5


class NaNAfter(gym.Env):
    """CartPole-like spaces; the observation turns NaN after 1,300 steps in total."""

    observation_space = gym.spaces.Box(-1, 1, (3,))
    action_space = gym.spaces.Discrete(2)
    steps = 0

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(3, np.float32), {}

    def step(self, action):
        NaNAfter.steps += 1
        value = np.nan if NaNAfter.steps > 1300 else 0.1
        return np.full(3, value, np.float32), 1.0, NaNAfter.steps % 50 == 0, False, {}


def test_nan_stops_the_run_and_keeps_the_last_good_checkpoint(tmp_path, capsys):
    gym.register("NaNAfter-v0", entry_point=NaNAfter)
    out = tmp_path / "nan"
    code = main(
        [
            "train",
            "NaNAfter-v0",
            "--steps",
            "5120",
            "--out",
            str(out),
            "--quiet",
            "--config",
            "horizon=512",
            "minibatch_size=128",
            "epochs=1",
            "checkpoint_every=1",
        ]
    )
    err = capsys.readouterr().err.strip()
    assert code != 0 and "non-finite observation" in err and "checkpoint is kept" in err
    assert len(err.splitlines()) == 1
    with np.load(out / "checkpoint.npz") as data:
        assert int(data["update"]) == 2  # updates 1 and 2 finished before step 1301
    assert np.all(np.isfinite(np.load(out / "policy.npz")["params"]))


def test_resume_continues_the_run(tmp_path):
    out = tmp_path / "resumable"
    common = ["--out", str(out), "--quiet", "--config", "horizon=256", "minibatch_size=64", "epochs=1"]
    assert run("train", "CartPole-v1", "--steps", "512", *common).returncode == 0
    result = run("train", "CartPole-v1", "--steps", "1024", "--resume", "--out", str(out), "--quiet")
    assert result.returncode == 0, result.stderr
    steps = [line.split(",")[1] for line in (out / "progress.csv").read_text().splitlines()[1:]]
    assert steps == ["256", "512", "768", "1024"]


@pytest.mark.timeout(600)
def test_eval_renders_a_gif_offscreen(tmp_path):
    out = tmp_path / "pendulum"
    trained = run(
        "train",
        "InvertedPendulum-v5",
        "--steps",
        "256",
        "--out",
        str(out),
        "--quiet",
        "--config",
        "horizon=256",
        "epochs=1",
    )
    assert trained.returncode == 0, trained.stderr
    result = run("eval", str(out), "--episodes", "1", "--gif", str(tmp_path / "agent.gif"))
    assert result.returncode == 0, result.stderr
    from PIL import Image

    with Image.open(tmp_path / "agent.gif") as gif:
        assert gif.n_frames >= 1 and gif.size == (320, 320)


# train_argv, the parser's inverse


def away_from_default(field) -> object:
    """A value of the Config field other than its default, of the field's type (a float with a long repr)."""
    kind, default, words = field_types()[field.name], field.default, field.metadata["choices"]
    if words:
        return next(word for word in words if word != default)
    if kind is bool:
        return not default
    if kind is int:
        return default + 3
    if kind is float:
        return default + 0.1 if default else 0.1 + 0.2  # 0.30000000000000004: written as it reads back
    if kind == float | None:
        return 0.015
    if typing.get_origin(kind) is tuple:
        return (32, 16, 8)
    assert kind is str and field.name == "env_id", field.name
    return "Acrobot-v1"


FIELDS = [field.name for field in dataclasses.fields(Config)]


@pytest.mark.parametrize("name", FIELDS)
def test_train_argv_is_the_parser_s_inverse_for_every_field(name):
    field = next(field for field in dataclasses.fields(Config) if field.name == name)
    config = Config(**{name: away_from_default(field)})
    argv = train_argv(config, "runs/x")
    assert train_config(argv) == config, argv
    assert argv[argv.index("--out") + 1] == "runs/x"
    if name not in ("env_id", "total_steps", "seed"):  # written always, first: what names the run
        assert argv[7:] == option(name, getattr(config, name))  # and only the field that changed


def test_train_argv_of_a_config_that_changes_every_field_reads_back():
    changed = Config(**{field.name: away_from_default(field) for field in dataclasses.fields(Config)})
    argv = train_argv(changed, "out")
    assert train_config(argv) == changed
    assert train_config(train_argv(Config(), "out")) == Config()
    assert train_argv(Config(), "out") == ["Hopper-v5", "--steps", "1000000", "--seed", "1", "--out", "out"]


def test_an_error_names_the_option_and_the_field_however_it_was_set(tmp_path, capsys):
    base = ["train", "CartPole-v1", "--steps", "1024", "--out", str(tmp_path / "x"), "--quiet"]
    expected = "minippo: error: --minibatch-size (minibatch_size): 4096 exceeds the batch N·T = 1024\n"
    for words in (["--minibatch-size", "4096"], ["--config", "minibatch_size=4096"]):
        assert main([*base, "--horizon", "1024", *words]) == 2
        assert capsys.readouterr().err == expected
    assert main([*base, "--epochs", "many"]) == 2
    assert capsys.readouterr().err == "minippo: error: --epochs (epochs): cannot read 'many' as int\n"
    assert main([*base, "--config", "epochs"]) == 2
    assert capsys.readouterr().err == "minippo: error: --config: 'epochs' is not key=value\n"
