"""MinAtar (Young & Tian 2019) through Gymnasium: five Atari games on a 10 × 10 grid, as ``MinAtar/<Game>-v1``.

The observation is the game's state as MinAtar keeps it, a (10, 10, C) boolean image with one channel per kind of
object (C = 4 for Breakout, up to 10 for Seaquest); the actions are each game's minimal set (3 for Breakout, up to 6).
Sticky actions (the last action repeats with probability 0.1) and the difficulty ramp stay on, MinAtar's defaults.

``minatar`` is an optional dependency (``pip install 'minippo[minatar]'``); the games are registered the first time
minippo is asked for a ``MinAtar/`` id.

MinAtar 1.0.15 registers Gymnasium ids of its own (``minatar.gym.register_envs``, also named as a Gymnasium plugin):
``MinAtar/<Game>-v0`` with all six actions and ``MinAtar/<Game>-v1`` with the minimal set, the same ids as minippo's.
minippo keeps its own class under the ``-v1`` ids, and takes them back if MinAtar's registration ran first, for what
MinAtar's class does not do: ``reset(seed=...)`` seeds Gymnasium's generator as well as the game's, and starts the
episode with no action left to repeat; ``get_state``/``set_state`` put the game in a checkpoint, so that a resumed
run is the run it would have been; and the action set and the episode's time limit are written here rather than
chosen by whichever registration ran last. Playing the minimal action set is minippo's choice (MinAtar's ``-v1``
makes the same one, its ``-v0`` keeps all six actions).
"""

from __future__ import annotations

import importlib.util
import json
import warnings

import gymnasium as gym
import numpy as np

from minippo.errors import MinippoError

GAMES = {  # Gymnasium name: MinAtar's module name
    "Asterix": "asterix",
    "Breakout": "breakout",
    "Freeway": "freeway",
    "Seaquest": "seaquest",
    "SpaceInvaders": "space_invaders",
}
# Gymnasium's Atari games end an episode at 108,000 frames, 27,000 agent steps; MinAtar has no limit of its own, and an
# agent that never loses would otherwise never finish an evaluation episode.
MAX_EPISODE_STEPS = 27_000
CELL_PIXELS = 16  # each grid cell drawn as a 16 × 16 square by render()


FIXED_ATTRIBUTES = ("random", "channels", "action_map", "ramping")  # a game's attributes that play does not change


class MinAtarEnv(gym.Env):
    metadata = {"render_modes": ["rgb_array"], "render_fps": 15}

    def __init__(self, game: str, sticky_action_prob: float = 0.1, difficulty_ramping: bool = True, render_mode=None):
        from minatar import Environment

        self.game = Environment(game, sticky_action_prob=sticky_action_prob, difficulty_ramping=difficulty_ramping)
        self.actions = list(self.game.minimal_action_set())  # our action i is MinAtar's action actions[i]
        self.action_space = gym.spaces.Discrete(len(self.actions))
        self.observation_space = gym.spaces.Box(0, 1, shape=tuple(self.game.state_shape()), dtype=bool)
        self.render_mode = render_mode
        self.game.seed(int(np.random.SeedSequence().generate_state(1)[0]))  # unseeded: fresh entropy, like Gymnasium

    def reset(self, *, seed: int | None = None, options=None):
        super().reset(seed=seed)
        if seed is not None:  # one generator drives the game and its sticky actions: seeding it fixes the episode
            self.game.seed(seed)
        self.game.last_action = 0  # an episode starts with no action to repeat, whatever the last one did
        self.game.reset()
        return self.game.state(), {}

    def step(self, action):
        reward, terminal = self.game.act(self.actions[int(action)])
        return self.game.state(), float(reward), bool(terminal), False, {}

    def get_state(self) -> dict[str, np.ndarray]:
        """The game where it is, as named arrays for a checkpoint: MinAtar's generator (it draws the game's chance
        events and the sticky actions), the last action (the one a sticky step repeats) and every attribute of the
        game that changes in play. ``set_state`` puts a game made with the same id back there."""
        game = self.game
        name, keys, position, has_gauss, cached_gauss = game.random.get_state()
        scalars, arrays = {}, {"random_keys": keys}
        for attribute, value in vars(game.env).items():
            if attribute in FIXED_ATTRIBUTES:
                continue
            if isinstance(value, np.ndarray):
                arrays[attribute] = value.copy()
            else:
                scalars[attribute] = value
        header = {"random": [name, position, has_gauss, cached_gauss], "last_action": game.last_action, "game": scalars}
        as_json = json.dumps(header, default=lambda value: value.item())  # NumPy scalars in the game's lists
        return {"scalars": np.array(as_json), **{f"array.{key}": value for key, value in arrays.items()}}

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        header = json.loads(str(state["scalars"]))
        name, position, has_gauss, cached_gauss = header["random"]
        keys = np.asarray(state["array.random_keys"], dtype=np.uint32)
        self.game.random.set_state((name, keys, position, has_gauss, cached_gauss))
        self.game.env.random = self.game.random  # one generator for both, as MinAtar's seed() leaves them
        self.game.last_action = header["last_action"]
        for attribute, value in header["game"].items():
            setattr(self.game.env, attribute, value)
        for key, value in state.items():
            if key.startswith("array.") and key != "array.random_keys":
                setattr(self.game.env, key[len("array.") :], np.array(value))

    def render(self):
        """The grid as an RGB image, one colour per channel (a later channel paints over an earlier one)."""
        if self.render_mode != "rgb_array":
            return None
        import matplotlib

        state = self.game.state()
        colours = np.asarray(matplotlib.colormaps["tab10"].colors)[: state.shape[-1]]
        image = np.zeros((*state.shape[:2], 3), dtype=np.uint8)
        for channel, colour in enumerate(colours):
            image[state[:, :, channel]] = np.round(255 * colour)
        return image.repeat(CELL_PIXELS, axis=0).repeat(CELL_PIXELS, axis=1)


def is_ours(spec) -> bool:
    entry = spec.entry_point
    return entry is MinAtarEnv or entry == f"{__name__}:MinAtarEnv"


def register_games() -> None:
    """Register ``MinAtar/<Game>-v1`` for the five games as ``MinAtarEnv``, or say how to install MinAtar. An id that
    another class holds (MinAtar's own registration, see the module's docstring) is taken back, with a warning."""
    if importlib.util.find_spec("minatar") is None:
        raise MinippoError("the MinAtar games need the minatar package: pip install 'minippo[minatar]'")
    for name, game in GAMES.items():
        env_id = f"MinAtar/{name}-v1"
        spec = gym.registry.get(env_id)
        if spec is not None and is_ours(spec):
            continue
        if spec is not None:
            warnings.warn(
                f"{env_id} was registered with {spec.entry_point}; minippo registers its own MinAtarEnv under it "
                "(seeded resets, a game state saved in checkpoints)",
                stacklevel=2,
            )
            del gym.registry[env_id]
        gym.register(env_id, entry_point=MinAtarEnv, kwargs={"game": game}, max_episode_steps=MAX_EPISODE_STEPS)
