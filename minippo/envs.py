"""Making Gymnasium environments, and refusing the ones minippo cannot handle with a clear message."""

from __future__ import annotations

import difflib
import json
import os

import gymnasium as gym
import numpy as np

from minippo.errors import MinippoError


def check_env_id(env_id: str) -> None:
    if env_id.startswith("MinAtar/"):  # registered on first use, since minatar is an optional dependency
        from minippo.minatar import register_games

        register_games()
    if env_id in gym.registry:
        return
    # near misses only (a typo, a case slip, another version): an id that resembles nothing gets no guess
    by_lower = {name.lower(): name for name in gym.registry}
    close = [by_lower[name] for name in difflib.get_close_matches(env_id.lower(), list(by_lower), n=3, cutoff=0.8)]
    hint = f"; did you mean {', '.join(close)}?" if close else "; see gymnasium.registry for the ids"
    raise MinippoError(f"unknown environment id '{env_id}'{hint}")


def spaces_of(env: gym.Env) -> tuple[int, str, int]:
    """Return (observation size, 'discrete' or 'continuous', number of actions or action size). An image's size is
    its number of entries, H·W·C: minippo carries images as flat rows (see ``FlatImages``)."""
    obs_space, action_space = env.observation_space, env.action_space
    if not (isinstance(obs_space, gym.spaces.Box) and len(obs_space.shape) in (1, 3)):
        raise MinippoError(
            f"unsupported observation space {type(obs_space).__name__}{getattr(obs_space, 'shape', '')}: minippo "
            "handles Box observations that are flat or images (H, W, C)"
        )
    obs_dim = int(np.prod(obs_space.shape))
    if isinstance(action_space, gym.spaces.Discrete):
        return obs_dim, "discrete", int(action_space.n)
    if isinstance(action_space, gym.spaces.Box) and len(action_space.shape) == 1:
        return obs_dim, "continuous", action_space.shape[0]
    raise MinippoError(
        f"unsupported action space {type(action_space).__name__}: minippo handles Discrete and flat Box actions"
    )


def image_shape_of(env: gym.Env) -> tuple[int, int, int] | None:
    """(H, W, C) of an environment whose observations are images, else None."""
    shape = getattr(env, "image_shape", env.observation_space.shape)
    return tuple(shape) if len(shape) == 3 else None


class FlatImages(gym.ObservationWrapper):
    """Image observations (H, W, C) as flat rows of H·W·C numbers in row-major order, so that the rollout, the
    normalisation and the batch treat them like any vector; the convolutional trunk reshapes them back."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.image_shape = tuple(env.observation_space.shape)
        space = env.observation_space
        self.observation_space = gym.spaces.Box(space.low.reshape(-1), space.high.reshape(-1), dtype=space.dtype)

    def observation(self, observation):
        return np.asarray(observation).reshape(-1)


def make_env(env_id: str, render_mode: str | None = None, size: int | None = None) -> gym.Env:
    """Make ``env_id`` (checking its spaces); ``size`` sets a MuJoCo task's rendered frame to size × size pixels."""
    check_env_id(env_id)
    if render_mode is not None:  # offscreen rendering (--gif) on machines without a display, unless the user chose
        os.environ.setdefault("MUJOCO_GL", "egl")  # MuJoCo's renderer
        os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # pygame's (CartPole and the other classic tasks)
    try:
        extra = {} if render_mode is None else {"render_mode": render_mode}
        if size is not None and "mujoco" in str(gym.spec(env_id).entry_point):
            # a camera that follows the robot's root body, so a walker stays in the picture
            camera = {
                "type": 2,
                "trackbodyid": 1,
                "distance": 3.5,
                "elevation": -15.0,
                "lookat": np.array([0.0, 0.0, 1.0]),
            }
            extra.update(width=size, height=size, default_camera_config=camera)
        env = gym.make(env_id, disable_env_checker=True, **extra)
    except Exception as error:  # a missing extra (e.g. mujoco) or a broken registration
        reason = str(error).splitlines()[0] if str(error) else type(error).__name__
        raise MinippoError(f"cannot make '{env_id}': {reason}")
    spaces_of(env)
    return FlatImages(env) if len(env.observation_space.shape) == 3 else env


# an environment in the middle of its episode, saved so that a resumed run steps on exactly as it would have

CLASSIC_STATE = ("state", "steps_beyond_terminated", "last_u")  # what the classic-control tasks carry between steps


def env_state(env: gym.Env) -> dict | None:
    """Everything the next steps of ``env`` depend on, as named arrays: the simulator (MuJoCo's integration state and
    the quantities it computed from it, which the tasks read before their next step), a classic-control task's own
    state, or what a game that saves itself returns (minippo's MinAtar games); the time limit's step count; the
    environment's random generator. None for an environment minippo does not know how to save (another family of
    tasks, or a wrapper it does not know)."""
    state = {}
    while isinstance(env, gym.Wrapper):
        if isinstance(env, gym.wrappers.TimeLimit):
            state["elapsed_steps"] = np.array(env._elapsed_steps)
        elif not isinstance(env, (gym.wrappers.OrderEnforcing, gym.wrappers.PassiveEnvChecker, FlatImages)):
            return None
        env = env.env
    state["np_random"] = np.array(json.dumps(env.np_random.bit_generator.state))
    if is_mujoco(env):
        import mujoco

        model, data = env.model, env.data
        physics = np.empty(mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_INTEGRATION))
        mujoco.mj_getState(model, data, physics, mujoco.mjtState.mjSTATE_INTEGRATION)
        state["physics"] = physics
        for name in mujoco_arrays(data):
            state[f"data.{name}"] = getattr(data, name).copy()
        return state
    if hasattr(env, "get_state") and hasattr(env, "set_state"):  # a game that saves itself (minippo's MinAtar)
        return state | {f"game.{key}": value for key, value in env.get_state().items()}
    if type(env).__module__.startswith("gymnasium.envs.classic_control"):
        scalars = {}
        for name in filter(lambda name: hasattr(env, name), CLASSIC_STATE):
            value = getattr(env, name)
            if isinstance(value, np.ndarray | np.generic):
                state[f"attr.{name}"] = np.array(value)
            else:
                scalars[name] = value
        state["scalars"] = np.array(json.dumps(scalars))
        return state
    return None


def load_env_state(env: gym.Env, state: dict) -> None:
    """Put ``env`` back where ``env_state`` saw it (``env`` made by ``make_env`` with the same id, and reset once)."""
    outer = env
    while isinstance(outer, gym.Wrapper):
        if isinstance(outer, gym.wrappers.TimeLimit):
            outer._elapsed_steps = int(state["elapsed_steps"])
        outer = outer.env
    env = env.unwrapped
    env.np_random.bit_generator.state = json.loads(str(state["np_random"]))
    if is_mujoco(env):
        import mujoco

        for name in mujoco_arrays(env.data):
            saved = state.get(f"data.{name}")  # those sized by the contacts of the moment are recomputed by a step
            if saved is not None and saved.shape == getattr(env.data, name).shape:
                getattr(env.data, name)[...] = saved
        mujoco.mj_setState(env.model, env.data, state["physics"], mujoco.mjtState.mjSTATE_INTEGRATION)
        return
    if hasattr(env, "set_state"):
        env.set_state({key[len("game.") :]: value for key, value in state.items() if key.startswith("game.")})
        return
    for name, value in json.loads(str(state["scalars"])).items():
        setattr(env, name, value)
    for name in CLASSIC_STATE:
        if f"attr.{name}" in state:
            value = np.array(state[f"attr.{name}"])
            setattr(env, name, value if value.ndim else value[()])


def is_mujoco(env) -> bool:
    return type(env).__module__.startswith("gymnasium.envs.mujoco") and hasattr(env, "data")


def mujoco_arrays(data) -> list[str]:
    """The arrays of an ``mjData``: its state and everything computed from it at the last step (positions of bodies
    and sites, contact forces, sensors), some of which a task reads before it steps again."""
    return [name for name in dir(data) if not name.startswith("_") and isinstance(getattr(data, name), np.ndarray)]
