"""Running the snapshot policy π_θold for T steps in N environments: Algorithm 1's inner "for actor" loop."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from minippo.distributions import sample_categorical
from minippo.envs import env_state, load_env_state
from minippo.errors import NonFiniteError


@dataclass
class Batch:
    """T steps × N environments of experience. ``obs`` is normalised (what the policy saw); ``next_values[t]`` is
    V of the observation that followed step t (the final observation when the episode ended there)."""

    obs: np.ndarray  # (T, N, obs_dim)
    actions: np.ndarray  # (T, N, act_dim) unclipped, or (T, N) integers
    logp: np.ndarray  # (T, N) log π_θold(a_t|s_t)
    policy_out: np.ndarray  # (T, N, ·) logits or means of π_θold
    policy_log_std: np.ndarray  # (act_dim,) log σ of π_θold (continuous); (0,) for a categorical
    values: np.ndarray  # (T, N)
    next_values: np.ndarray  # (T, N)
    rewards: np.ndarray  # (T, N) scaled, as the learner sees them
    terminated: np.ndarray  # (T, N)
    truncated: np.ndarray  # (T, N)


class Rollout:
    def __init__(self, envs, agent, obs_normalizer, reward_scaler, horizon: int, rng, seed: int, clip_actions=True):
        self.envs, self.agent, self.horizon, self.rng = envs, agent, horizon, rng
        self.obs_normalizer, self.reward_scaler = obs_normalizer, reward_scaler
        space = envs[0].action_space
        self.low = getattr(space, "low", None)
        self.high = getattr(space, "high", None)
        self.clip_actions = clip_actions and agent.kind == "continuous"
        self.raw_obs = np.stack([env.reset(seed=seed + i)[0] for i, env in enumerate(envs)]).astype(np.float64)
        self.episode_return = [0.0] * len(envs)  # Python numbers: cheaper than NumPy scalars, one step at a time
        self.episode_length = [0] * len(envs)
        self.completed_returns: list[float] = []
        self.completed_lengths: list[int] = []
        self.steps = 0

    def collect(self) -> Batch:
        T, N, agent = self.horizon, len(self.envs), self.agent
        obs_dim = self.raw_obs.shape[1]
        raw_obs = np.empty((T + 1, N, obs_dim))  # s_0 … s_T: the environments write s_{t+1} into row t + 1
        raw_obs[0] = self.raw_obs
        obs = np.empty((T, N, obs_dim), dtype=agent.dtype)
        rewards = np.empty((T, N))
        terminated = np.zeros((T, N), dtype=bool)
        truncated = np.zeros((T, N), dtype=bool)
        final_obs = {}  # (t, i) -> normalised last observation of an episode cut by a time limit
        continuous = agent.kind == "continuous"
        if continuous:
            actions = np.empty((T, N, agent.act_dim), dtype=agent.dtype)
            policy_out = np.empty((T, N, agent.act_dim), dtype=agent.dtype)
            noise = self.rng.standard_normal((T, N, agent.act_dim))  # drawn at once: same numbers, fewer calls
            scaled_noise = (np.exp(agent.log_std) * noise).astype(agent.dtype)  # σ z_t, in the policy's dtype
            clipped = np.empty((N, agent.act_dim), dtype=agent.dtype)  # the actions the environments get
        else:
            actions = np.empty((T, N), dtype=np.int64)
            policy_out = np.empty((T, N, agent.act_dim), dtype=agent.dtype)
            uniforms = self.rng.random((T, N))

        for t in range(T):
            obs[t] = self.obs_normalizer(raw_obs[t])
            out = policy_out[t] = agent.policy_output(obs[t])
            if continuous:
                env_actions = np.add(out, scaled_noise[t], out=actions[t])  # a_t = μ(s_t) + σ z_t
                if self.clip_actions:  # np.clip, without its wrapper's overhead
                    env_actions = np.minimum(np.maximum(env_actions, self.low, out=clipped), self.high, out=clipped)
            else:
                env_actions = actions[t] = sample_categorical(out, uniforms[t])
            for i, env in enumerate(self.envs):
                next_obs, reward, term, trunc, _ = env.step(env_actions[i])
                rewards[t, i] = reward
                self.episode_return[i] += reward
                self.episode_length[i] += 1
                if term or trunc:
                    terminated[t, i], truncated[t, i] = term, trunc and not term
                    if truncated[t, i]:
                        final_obs[(t, i)] = self._check(np.asarray(next_obs, dtype=np.float64), t)
                    self.completed_returns.append(float(self.episode_return[i]))
                    self.completed_lengths.append(self.episode_length[i])
                    self.episode_return[i], self.episode_length[i] = 0.0, 0
                    next_obs, _ = env.reset()
                raw_obs[t + 1, i] = self._check(next_obs, t)
        self.raw_obs = raw_obs[T].copy()
        self.steps += T * N
        if not np.all(np.isfinite(rewards)):
            raise NonFiniteError(f"non-finite reward in the rollout ending at step {self.steps}")

        # V(s_t) for the batch and V(s_{t+1}) after it, with the statistics the policy acted on
        flat_obs = obs.reshape(T * N, obs_dim)
        values = agent.value(flat_obs).reshape(T, N)
        next_values = np.empty((T, N))
        next_values[:-1] = values[1:]
        next_values[-1] = agent.value(self.obs_normalizer(self.raw_obs))
        for (t, i), last in final_obs.items():
            next_values[t, i] = agent.value(self.obs_normalizer(last[None]))[0]
        dist = agent.distribution(policy_out.reshape(T * N, -1))
        logp = dist.log_prob(actions.reshape(T * N, -1) if continuous else actions.reshape(T * N)).reshape(T, N)

        # the statistics move only now, between batches (the stored obs keep the normalisation they were acted on)
        self.obs_normalizer.update(raw_obs[:T].reshape(T * N, obs_dim))
        scaled = self.reward_scaler.scale(rewards, terminated | truncated)
        old_log_std = agent.log_std.copy()  # with the means, all of π_θold: eq. 8's KL compares against both
        return Batch(obs, actions, logp, policy_out, old_log_std, values, next_values, scaled, terminated, truncated)

    # checkpoints: the episodes in progress, so that a resumed run steps on from exactly where it stopped

    def state_dict(self) -> dict:
        """The counts, the finished episodes, and each environment in the middle of its episode: the observation it
        last returned, the return and length so far, and its own state (``envs.env_state``), left out when one of
        the environments cannot be saved."""
        state = {
            "steps": np.array(self.steps),
            "returns": np.array(self.completed_returns, dtype=np.float64),
            "lengths": np.array(self.completed_lengths, dtype=np.int64),
            "raw_obs": self.raw_obs.copy(),
            "episode_return": np.array(self.episode_return, dtype=np.float64),
            "episode_length": np.array(self.episode_length, dtype=np.int64),
        }
        saved = [env_state(env) for env in self.envs]
        if all(env is not None for env in saved):
            for i, env in enumerate(saved):
                state.update({f"env{i}.{key}": value for key, value in env.items()})
        return state

    def load_state_dict(self, state: dict, seed: int) -> bool:
        """Carry on from ``state``. Returns False when it holds no environments (they cannot be saved, or an older
        minippo wrote it): they then start fresh episodes, reset with ``seed + i``."""
        self.steps = int(state["steps"])
        self.completed_returns = [float(x) for x in state["returns"]]
        self.completed_lengths = [int(x) for x in state["lengths"]]
        if not all(f"env{i}.np_random" in state for i in range(len(self.envs))) or "raw_obs" not in state:
            for i, env in enumerate(self.envs):
                self.raw_obs[i] = env.reset(seed=seed + i)[0]
            return False
        for i, env in enumerate(self.envs):
            prefix = f"env{i}."
            load_env_state(env, {key[len(prefix) :]: value for key, value in state.items() if key.startswith(prefix)})
        self.raw_obs = np.array(state["raw_obs"], dtype=np.float64)
        self.episode_return = [float(x) for x in state["episode_return"]]
        self.episode_length = [int(x) for x in state["episode_length"]]
        return True

    def _check(self, observation: np.ndarray, t: int) -> np.ndarray:
        if not np.isfinite(observation).all():
            raise NonFiniteError(f"non-finite observation from the environment at step {self.steps + t + 1}")
        return observation
