"""Returns and advantages over a batch of T steps that may hold several episodes (eqs. 10–12).

Gymnasium ends an episode in one of two ways, and they must be told apart:
- ``terminated``: the task reached a terminal state (Hopper fell). Nothing follows, so V(s_{t+1}) counts as 0.
- ``truncated``: a time limit stopped the episode. The state was not terminal, so we bootstrap from V of the
  final observation, which ``next_values[t]`` holds.
Either way the next step of the batch belongs to a new episode, so nothing flows back across the boundary.
The last step of the batch is cut by the horizon T: ``next_values[T−1]`` = V(s_T) bootstraps it (eq. 11's truncation).
"""

from __future__ import annotations

import numpy as np


def discounted_returns(rewards, next_values, terminated, truncated, gamma: float) -> np.ndarray:
    """G_t = r_t + γ G_{t+1} inside an episode; G_t = r_t + γ V(s_{t+1}) where it was truncated or the batch ends;
    G_t = r_t where it terminated. Arrays have shape (T,) or (T, N) for N parallel environments."""
    rewards = np.asarray(rewards, dtype=np.float64)
    terminated = np.asarray(terminated, dtype=bool)
    truncated = np.asarray(truncated, dtype=bool)
    returns = np.zeros_like(rewards)
    T = len(rewards)
    following = np.zeros_like(rewards[0])
    for t in range(T - 1, -1, -1):
        cut = truncated[t] | (t == T - 1)
        tail = np.where(cut, next_values[t], following)
        returns[t] = rewards[t] + gamma * np.where(terminated[t], 0.0, tail)
        following = returns[t]
    return returns


def td_residuals(rewards, values, next_values, terminated, gamma: float) -> np.ndarray:
    """δ_t = r_t + γ V(s_{t+1}) − V(s_t) (eq. 12), with V(s_{t+1}) = 0 after a termination."""
    rewards = np.asarray(rewards, dtype=np.float64)
    not_terminal = 1.0 - np.asarray(terminated, dtype=np.float64)
    return rewards + gamma * not_terminal * np.asarray(next_values) - np.asarray(values)


def gae(rewards, values, next_values, terminated, truncated, gamma: float, lam: float) -> np.ndarray:
    """Truncated generalized advantage estimation (eq. 11): Â_t = δ_t + (γλ) Â_{t+1}, restarted at episode ends.

    λ = 0 gives the one-step TD residual δ_t; λ = 1 gives the Monte Carlo return minus V(s_t).
    """
    deltas = td_residuals(rewards, values, next_values, terminated, gamma)
    episode_ends = np.asarray(terminated, dtype=bool) | np.asarray(truncated, dtype=bool)
    carry = 1.0 - episode_ends.astype(np.float64)
    decay = gamma * lam
    # The recurrence runs backwards over t on plain Python floats, one environment (column) at a time: on one
    # number per step, NumPy's per-call overhead would outweigh the arithmetic.
    T = len(deltas)
    advantages = np.empty((T, deltas.size // T))
    for i, (delta, keep) in enumerate(zip(deltas.reshape(T, -1).T.tolist(), carry.reshape(T, -1).T.tolist())):
        column, following = [0.0] * T, 0.0
        for t in range(T - 1, -1, -1):
            following = delta[t] + decay * keep[t] * following  # Â_t = δ_t + γλ Â_{t+1}
            column[t] = following
        advantages[:, i] = column
    return advantages.reshape(deltas.shape)
