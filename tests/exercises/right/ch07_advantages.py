"""Other correct ways to write chapter 7."""

import numpy as np


def td_residuals_one_minus_done(rewards, values, next_values, terminated, gamma):
    """(1 − done) · V(s_{t+1}) in place of np.where (the 1e6 after a termination is multiplied by 0)."""
    done = np.asarray(terminated, dtype=np.float64)
    return np.asarray(rewards, dtype=np.float64) + gamma * (1.0 - done) * next_values - values


def discounted_returns_column_by_column(rewards, next_values, terminated, truncated, gamma):
    """Plain Python branches, one environment (column) at a time."""
    rewards = np.asarray(rewards, dtype=np.float64)
    columns = rewards.reshape(len(rewards), -1)
    nexts = np.asarray(next_values, dtype=np.float64).reshape(columns.shape)
    ends = np.asarray(terminated).reshape(columns.shape), np.asarray(truncated).reshape(columns.shape)
    returns = np.zeros(columns.shape)
    for i in range(columns.shape[1]):
        following = 0.0
        for t in range(len(columns) - 1, -1, -1):
            if ends[0][t, i]:
                following = 0.0
            elif ends[1][t, i] or t == len(columns) - 1:
                following = nexts[t, i]
            returns[t, i] = columns[t, i] + gamma * following
            following = returns[t, i]
    return returns.reshape(rewards.shape)


def gae_with_masks(rewards, values, next_values, terminated, truncated, gamma, lam):
    """The recursion with a 0/1 mask that is 0 at an episode end and at the batch's last step."""
    done = np.asarray(terminated, dtype=np.float64)
    deltas = np.asarray(rewards, dtype=np.float64) + gamma * (1.0 - done) * next_values - values
    keep = 1.0 - np.maximum(done, np.asarray(truncated, dtype=np.float64))
    advantages = np.zeros(deltas.shape)
    following = np.zeros(deltas.shape[1:])
    for t in range(len(deltas) - 1, -1, -1):
        following = deltas[t] + gamma * lam * keep[t] * following
        advantages[t] = following
    return advantages


VARIANTS = {
    "td_residuals_one_minus_done": {"td_residuals": td_residuals_one_minus_done},
    "discounted_returns_column_by_column": {"discounted_returns": discounted_returns_column_by_column},
    "gae_with_masks": {"gae": gae_with_masks},
}


def step_gae_vectorised_flags(rewards, values, next_values, terminated, truncated, gammas, lam):
    """(1 − done) masks and a discount array for the carry, built before the loop."""
    deltas = rewards + gammas * (1.0 - terminated) * next_values - values
    keep = 1.0 - (terminated | truncated)
    keep[-1] = 0.0
    factors = gammas * lam * keep
    result = np.zeros(len(deltas))
    carry = 0.0
    for t in reversed(range(len(deltas))):
        carry = deltas[t] + factors[t] * carry
        result[t] = carry
    return result


VARIANTS["step_gae_vectorised_flags"] = {"gae_with_step_discounts": step_gae_vectorised_flags}
