"""PPO from images: the conv actor-critic in the whole loss, MinAtar through Gymnasium, the Atari preset, A2C."""

import dataclasses
import importlib.util

import numpy as np
import pytest
from conftest import assert_close, numerical_gradient

from minippo import losses
from minippo.agent import ActorCritic, AgentSpec
from minippo.cli import main
from minippo.ppo import Config, Trainer, loss_and_grad, train
from minippo.presets import A2C, ATARI, CARTPOLE_PPO, PRESETS

needs_minatar = pytest.mark.skipif(
    importlib.util.find_spec("minatar") is None, reason="MinAtar is not installed (pip install 'minippo[minatar]')"
)
GAMES = ["Asterix", "Breakout", "Freeway", "Seaquest", "SpaceInvaders"]


@pytest.mark.parametrize("objective", ["clip", "pg"])
def test_cnn_whole_loss_gradient_matches_finite_differences(rng, objective):
    spec = AgentSpec(5 * 5 * 2, "discrete", 3, shared=True, network="minatar_cnn", image_shape=(5, 5, 2))
    agent = ActorCritic(spec, rng)
    assert agent.shared and agent.nets["trunk"].dense_shape == (3 * 3 * 16, 128)
    agent.params[...] += 0.1 * rng.standard_normal(agent.params.shape)  # biases and heads off their init
    n = 6
    obs = (rng.random((n, 50)) < 0.3).astype(np.float64)  # boolean images, as MinAtar gives them
    out, values, _ = agent.forward(obs)
    old = agent.distribution(out + 0.3 * rng.standard_normal(out.shape))
    actions = rng.integers(0, 3, n)
    mb = {
        "obs": obs,
        "actions": actions,
        "logp": old.log_prob(actions),
        "values": values + 0.05 * rng.standard_normal(n),
        "advantages": rng.standard_normal(n),
        "returns": values + rng.standard_normal(n),
    }
    config = Config(objective=objective, entropy_coef=0.01, value_coef=1.0, network="minatar_cnn", shared_network=True)
    loss_and_grad(agent, mb, config)
    # every kernel entry and bias, and a sample of the dense layer's and the heads' weights
    trunk = agent.nets["trunk"]
    picked = np.concatenate(
        [np.arange(trunk.K.size + 16), rng.choice(np.arange(trunk.K.size + 16, agent.params.size), 150, False)]
    )
    numeric = numerical_gradient(lambda: loss_and_grad(agent, mb, config)[0], agent.params, at=picked)
    assert_close(agent.grads[picked], numeric, rtol=1e-5, atol=1e-7)


def test_cnn_needs_images_and_a_shared_trunk():
    with pytest.raises(ValueError, match="needs images"):
        AgentSpec(4, "discrete", 2, shared=True, network="minatar_cnn")
    with pytest.raises(Exception, match="shared_network"):
        Config(network="minatar_cnn").validate()
    with pytest.raises(Exception, match="network must be one of"):
        Config(network="resnet").validate()


def test_presets_are_valid_configs():
    for preset in PRESETS.values():
        config = dataclasses.replace(Config(), **preset)
        assert all(getattr(config, key) == value for key, value in preset.items())
        config.validate()
    assert (ATARI["num_envs"] * ATARI["horizon"], ATARI["epochs"], ATARI["minibatch_size"]) == (1024, 3, 256)
    assert A2C["epochs"] == 1 and A2C["minibatch_size"] == A2C["num_envs"] * A2C["horizon"]  # one step a batch


@pytest.mark.parametrize("anneal_clip", [True, False])
def test_clip_annealing_follows_the_step_size(monkeypatch, anneal_clip):
    # the ε that each update's minibatches hand to L^CLIP: 0.2·α with α = 1 − (k − 1)/K at update k, or 0.2 throughout
    seen = []
    clip_objective = losses.clip_objective

    def recording(logp, logp_old, advantages, epsilon):
        seen.append(epsilon)
        return clip_objective(logp, logp_old, advantages, epsilon)

    monkeypatch.setattr(losses, "clip_objective", recording)
    config = Config(**CARTPOLE_PPO, total_steps=4 * 512, clip_epsilon=0.2, anneal_clip=anneal_clip, seed=2)
    trainer = Trainer(config)
    assert config.num_updates == 4
    for update in range(1, 5):
        seen.clear()
        alpha = 1 - (update - 1) / 4
        assert trainer.run_update()["lr"] == pytest.approx(2.5e-4 * alpha)
        assert len(seen) == config.epochs * (512 // config.minibatch_size)
        assert seen == pytest.approx([0.2 * alpha if anneal_clip else 0.2] * len(seen))


@pytest.mark.slow  # a learning run
def test_a2c_learns_cartpole():
    # the A2C preset's algorithm (one L^PG step a batch of 16 × 5) on CartPole's MLP: the return climbs well above a
    # random policy's (about 22)
    a2c = {key: value for key, value in A2C.items() if key not in ("network", "shared_network")}
    rows = train(Config(**a2c, env_id="CartPole-v1", total_steps=40_000, seed=1))
    assert rows[-1]["return_mean"] > 60, rows[-1]["return_mean"]


@needs_minatar
@pytest.mark.parametrize("game", GAMES)
def test_minatar_games_pass_gymnasiums_checker(game):
    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env

    from minippo.envs import image_shape_of, make_env, spaces_of

    make_env(f"MinAtar/{game}-v1").close()  # registers the games
    env = gym.make(f"MinAtar/{game}-v1")
    check_env(env.unwrapped, skip_render_check=True)
    obs, _ = env.reset(seed=3)
    assert obs.shape[:2] == (10, 10) and obs.dtype == bool
    flat = make_env(f"MinAtar/{game}-v1")
    obs_dim, kind, n_actions = spaces_of(flat)
    assert image_shape_of(flat) == obs.shape and obs_dim == obs.size and kind == "discrete"
    assert n_actions == len(env.unwrapped.game.minimal_action_set())
    assert np.array_equal(flat.reset(seed=3)[0], obs.reshape(-1))


@needs_minatar
def test_minippo_takes_the_ids_back_from_minatars_own_registration():
    # MinAtar 1.0.15 registers MinAtar/<Game>-v0 and -v1 itself, with its own class: under those ids minippo's runs
    # must still get minippo's class (seeded resets, a game state in checkpoints), and say that it took them back
    import warnings

    import gymnasium as gym
    from minatar.gym import register_envs

    from minippo.envs import env_state, make_env
    from minippo.minatar import GAMES, MinAtarEnv, register_games

    ids = [f"MinAtar/{name}-{version}" for name in GAMES for version in ("v0", "v1")]
    before = {env_id: gym.registry.get(env_id) for env_id in ids}
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # Gymnasium's own "Overriding environment" where minippo's ids were
            register_envs()
        assert gym.registry["MinAtar/Breakout-v1"].entry_point == "minatar.gym:BaseEnv"
        with pytest.warns(UserWarning, match="minippo registers its own MinAtarEnv") as caught:
            env = make_env("MinAtar/Breakout-v1")
        assert len(caught) == len(GAMES)  # one warning per game taken back
        assert isinstance(env.unwrapped, MinAtarEnv) and env_state(env) is not None
        assert all(gym.registry[f"MinAtar/{name}-v1"].entry_point is MinAtarEnv for name in GAMES)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            register_games()  # once they are minippo's again, registering is quiet
        env.close()
    finally:
        for env_id, spec in before.items():
            gym.registry.pop(env_id, None)
            if spec is not None:
                gym.registry[env_id] = spec


@needs_minatar
def test_minatar_episodes_repeat_with_their_seed():
    from minippo.envs import make_env

    def episode(seed):
        env = make_env("MinAtar/Breakout-v1")
        frames = [env.reset(seed=seed)[0]]
        for t in range(60):
            obs, _, terminated, truncated, _ = env.step(t % 3)
            frames.append(obs)
            if terminated or truncated:
                frames.append(env.reset()[0])
        return np.array(frames)

    assert np.array_equal(episode(5), episode(5))
    assert not np.array_equal(episode(5), episode(6))


@needs_minatar
def test_train_breakout_with_the_atari_preset(tmp_path, capsys):
    code = main(["train", "MinAtar/Breakout-v1", "--steps", "1024", "--preset", "atari", "--out", str(tmp_path / "run"),
                 "--quiet", "--config", "epochs=1"])  # fmt: skip
    assert code == 0
    assert "MinAtar/Breakout-v1: 1024 steps" in capsys.readouterr().out
    assert main(["eval", str(tmp_path / "run"), "--episodes", "2"]) == 0


def test_cnn_on_flat_observations_is_a_one_line_error(tmp_path, capsys):
    code = main(["train", "CartPole-v1", "--steps", "1024", "--preset", "atari", "--out", str(tmp_path), "--quiet"])
    assert code == 2
    err = capsys.readouterr().err.strip()
    # the field's option and the field, whichever of --preset, --config or the option set it
    expected = "minippo: error: --network (network): network=minatar_cnn needs image observations; CartPole-v1 has none"
    assert err == expected
    code = main(["train", "CartPole-v1", "--steps", "1024", "--preset", "atari", "--out", str(tmp_path), "--quiet",
                 "--config", "network=minatar_cnn"])  # fmt: skip
    assert code == 2
    assert capsys.readouterr().err.strip() == expected
