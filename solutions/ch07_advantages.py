"""Chapter 7: returns, TD residuals and generalized advantage estimation over a batch that holds several episodes.

A batch has T steps (shape (T,), or (T, N) for N environments side by side, time first). Step t has a reward r_t, the
value V(s_t) (``values``), the value of the observation that followed it (``next_values[t]``), and two flags:
- ``terminated[t]``: the episode reached a terminal state at step t; nothing follows, so V(s_{t+1}) counts as 0;
- ``truncated[t]``: a time limit cut the episode at step t; the state was not terminal, so bootstrap from
  next_values[t], which holds V of the episode's final observation.
Either way step t+1 starts a new episode, so nothing flows back across the boundary. A step with both flags set
counts as terminated: it is not bootstrapped. The last step of the batch is cut by the horizon: bootstrap it from
next_values[T−1] unless it terminated. With (T, N) arrays every column is its own environment with its own episode
ends, so work element by element (np.where, not a Python ``if`` on an array). Every result is a new float64 array,
whatever float type the inputs have.

Grade: ``minippo grade 7``
"""

from __future__ import annotations

import numpy as np

EXERCISES = ["discounted_returns", "td_residuals", "gae"]
TRANSFER = ["gae_with_step_discounts"]  # the chapter's idea applied to a case the book has not shown


def discounted_returns(rewards, next_values, terminated, truncated, gamma: float) -> np.ndarray:
    """G_t, the discounted return from step t to the end of its episode, bootstrapped from next_values where the episode
    was cut (a truncation, or the batch's last step) and not where it terminated.

    rewards, next_values: float arrays (T,) or (T, N); terminated, truncated: bool arrays of the same shape.
    Returns a new float64 array of the same shape.
    """
    rewards = np.asarray(rewards, dtype=np.float64)
    terminated, truncated = np.asarray(terminated, dtype=bool), np.asarray(truncated, dtype=bool)
    returns = np.zeros_like(rewards)
    T = len(rewards)
    for t in range(T - 1, -1, -1):
        if t == T - 1:
            following = next_values[t]
        else:
            following = np.where(truncated[t], next_values[t], returns[t + 1])
        returns[t] = rewards[t] + gamma * np.where(terminated[t], 0.0, following)
    return returns


def td_residuals(rewards, values, next_values, terminated, gamma: float) -> np.ndarray:
    """δ_t, the TD residual of the paper's eq. 12 (the book's (7.1)), with V(s_{t+1}) = next_values[t], and nothing to
    bootstrap from where the step terminated.

    Arrays of shape (T,) or (T, N). Returns a new float64 array of the same shape. A value function that is exact
    gives δ = 0.
    """
    rewards = np.asarray(rewards, dtype=np.float64)
    not_terminal = ~np.asarray(terminated, dtype=bool)
    return rewards + gamma * np.where(not_terminal, next_values, 0.0) - np.asarray(values, dtype=np.float64)


def gae(rewards, values, next_values, terminated, truncated, gamma: float, lam: float) -> np.ndarray:
    """Â_t, truncated GAE (the paper's eq. 11, the book's (7.2)): the (γλ)-discounted sum of TD residuals from step t to
    the end of t's episode (a termination, a truncation, or the batch's last step; the bootstrap at a cut is already
    inside that step's δ).

    Arrays of shape (T,) or (T, N). Returns a new float64 array of the same shape. λ = 0 gives δ_t; λ = 1 gives the
    discounted return minus V(s_t).
    """
    deltas = td_residuals(rewards, values, next_values, terminated, gamma)
    ends = np.asarray(terminated, dtype=bool) | np.asarray(truncated, dtype=bool)
    advantages = np.zeros_like(deltas)
    T = len(deltas)
    for t in range(T - 1, -1, -1):
        if t == T - 1:
            advantages[t] = deltas[t]
        else:
            advantages[t] = deltas[t] + gamma * lam * np.where(ends[t], 0.0, advantages[t + 1])
    return advantages


def gae_with_step_discounts(rewards, values, next_values, terminated, truncated, gammas, lam: float) -> np.ndarray:
    """Transfer task: GAE when every step has its own discount, as when steps last different times (γ_t = γ^{Δt_t}).

    gammas[t] discounts what follows step t: its bootstrap V(s_{t+1}) and everything after it. With every
    gammas[t] = γ this is chapter 7's gae. The flags, the bootstrap at a truncation or at the batch's last step and
    the episode ends are gae's.
    rewards, values, next_values, gammas: (T,) floats.  terminated, truncated: (T,) bools.  lam: λ.
    Returns Â, a new (T,) float64 array.
    """
    rewards, values = np.asarray(rewards, dtype=np.float64), np.asarray(values, dtype=np.float64)
    terminated, truncated = np.asarray(terminated, dtype=bool), np.asarray(truncated, dtype=bool)
    gammas = np.asarray(gammas, dtype=np.float64)
    deltas = rewards + gammas * np.where(terminated, 0.0, next_values) - values
    advantages = np.zeros_like(deltas)
    carry = 0.0
    for t in range(len(deltas) - 1, -1, -1):
        ends = terminated[t] or truncated[t] or t == len(deltas) - 1
        carry = deltas[t] + (0.0 if ends else gammas[t] * lam * carry)
        advantages[t] = carry
    return advantages
