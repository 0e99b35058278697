"""Running observation normalisation and reward scaling (two of the "37 details" for continuous control).

Neither has trainable parameters, so neither has a gradient: they change what the networks see, not how they learn.
Their statistics are saved with the policy, so evaluation sees observations exactly as training did.
"""

from __future__ import annotations

import numpy as np


class RunningMeanStd:
    """Mean and variance of everything seen so far, merged batch by batch (Chan et al.'s parallel formula)."""

    def __init__(self, shape=(), epsilon: float = 1e-4):
        self.mean = np.zeros(shape)
        self.var = np.ones(shape)
        self.count = epsilon

    def update(self, batch: np.ndarray) -> None:
        batch = np.asarray(batch, dtype=np.float64).reshape((-1,) + self.mean.shape)
        if len(batch) == 0:
            return
        batch_mean, batch_var, batch_count = batch.mean(axis=0), batch.var(axis=0), len(batch)
        delta = batch_mean - self.mean
        total = self.count + batch_count
        self.mean = self.mean + delta * batch_count / total
        m2 = self.var * self.count + batch_var * batch_count + delta**2 * self.count * batch_count / total
        self.var = m2 / total
        self.count = total

    def state_dict(self) -> dict:
        return {"mean": self.mean.copy(), "var": self.var.copy(), "count": np.array(self.count)}

    def load_state_dict(self, state: dict) -> None:
        self.mean = np.array(state["mean"], dtype=np.float64)
        self.var = np.array(state["var"], dtype=np.float64)
        self.count = float(state["count"])


class ObservationNormalizer:
    """o ↦ clip((o − μ) / √(σ² + 1e-8), −c, c), with μ, σ² running over all observations seen (c = 10)."""

    def __init__(self, shape, clip: float = 10.0, enabled: bool = True):
        self.stats = RunningMeanStd(shape)
        self.clip = clip
        self.enabled = enabled
        self.refresh()

    def refresh(self) -> None:
        self._shift = self.stats.mean.copy()
        self._scale = 1.0 / np.sqrt(self.stats.var + 1e-8)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        if not self.enabled:
            return np.asarray(obs, dtype=np.float64)
        z = (obs - self._shift) * self._scale
        np.maximum(z, -self.clip, out=z)  # np.minimum(np.maximum(·)) is np.clip without its wrapper's overhead,
        return np.minimum(z, self.clip, out=z)  # which counts on the rollout's one-row calls

    def update(self, raw_obs: np.ndarray) -> None:
        """Fold a batch of raw observations into the statistics. The rollout calls this once per batch, so every
        observation of one batch is normalised with the same statistics."""
        if self.enabled:
            self.stats.update(raw_obs)
            self.refresh()

    def state_dict(self) -> dict:
        """The running statistics: {"mean", "var", "count"}."""
        return self.stats.state_dict()

    def load_state_dict(self, state: dict) -> None:
        self.stats.load_state_dict(state)
        self.refresh()


class RewardScaler:
    """r ↦ clip(r / √(Var[G] + 1e-8), −c, c), G the running discounted return G ← γ G + r (reset at episode ends).

    The rewards are divided, never shifted: shifting would change which behaviour is optimal.
    """

    def __init__(self, gamma: float, clip: float = 10.0, enabled: bool = True, num_envs: int = 1):
        self.stats = RunningMeanStd(())
        self.gamma = gamma
        self.clip = clip
        self.enabled = enabled
        self.discounted = np.zeros(num_envs)

    def scale(self, rewards: np.ndarray, episode_ends: np.ndarray) -> np.ndarray:
        """Scale a (T, N) batch of rewards, after folding its discounted returns into the statistics."""
        rewards = np.asarray(rewards, dtype=np.float64)
        if not self.enabled:
            return rewards
        # G_t of every step, on plain Python floats one environment at a time (see advantages.gae)
        T = len(rewards)
        returns = np.empty((T, len(self.discounted)))
        ends = np.asarray(episode_ends, dtype=bool).reshape(T, -1).T.tolist()
        for i, (column, ended) in enumerate(zip(rewards.reshape(T, -1).T.tolist(), ends)):
            discounted = float(self.discounted[i])
            for t in range(T):
                discounted = self.gamma * discounted + column[t]  # G ← γ G + r
                returns[t, i] = discounted
                if ended[t]:
                    discounted = 0.0
            self.discounted[i] = discounted
        self.stats.update(returns)
        return np.clip(rewards / np.sqrt(self.stats.var + 1e-8), -self.clip, self.clip)

    def state_dict(self) -> dict:
        """The running statistics of G, and each environment's G so far: {"mean", "var", "count", "discounted"}."""
        return {**self.stats.state_dict(), "discounted": self.discounted.copy()}

    def load_state_dict(self, state: dict) -> None:
        self.stats.load_state_dict(state)
        self.discounted = np.array(state["discounted"], dtype=np.float64)
