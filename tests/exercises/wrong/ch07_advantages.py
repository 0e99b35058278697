"""Plausible mistakes in chapter 7: returns, TD residuals and GAE at episode boundaries."""

import numpy as np

from solutions.ch07_advantages import td_residuals as correct_td_residuals


def returns_ignore_episode_ends(rewards, next_values, terminated, truncated, gamma):
    """G_t = r_t + γ G_{t+1} straight through every episode end, bootstrapped only at the end of the batch."""
    returns = np.zeros(np.shape(rewards))
    following = np.asarray(next_values[-1], dtype=np.float64)
    for t in range(len(rewards) - 1, -1, -1):
        following = rewards[t] + gamma * following
        returns[t] = following
    return returns


def returns_truncation_as_termination(rewards, next_values, terminated, truncated, gamma):
    """Stops at a truncation as if it were terminal: no bootstrap from the final observation."""
    returns = np.zeros(np.shape(rewards))
    ended = np.asarray(terminated) | np.asarray(truncated)
    for t in range(len(rewards) - 1, -1, -1):
        tail = next_values[t] if t == len(rewards) - 1 else returns[t + 1]
        returns[t] = rewards[t] + gamma * np.where(ended[t], 0.0, tail)
    return returns


def returns_no_bootstrap_at_batch_end(rewards, next_values, terminated, truncated, gamma):
    """Treats the horizon cut as terminal: G_{T−1} = r_{T−1}."""
    returns = np.zeros(np.shape(rewards))
    for t in range(len(rewards) - 1, -1, -1):
        tail = 0.0 if t == len(rewards) - 1 else np.where(truncated[t], next_values[t], returns[t + 1])
        returns[t] = rewards[t] + gamma * np.where(terminated[t], 0.0, tail)
    return returns


def td_ignores_termination(rewards, values, next_values, terminated, gamma):
    """Bootstraps after a termination too."""
    return rewards + gamma * np.asarray(next_values) - values


def td_sign_flipped(rewards, values, next_values, terminated, gamma):
    """V(s_t) − r_t − γ V(s_{t+1})."""
    return -correct_td_residuals(rewards, values, next_values, terminated, gamma)


def td_next_value_from_the_next_row(rewards, values, next_values, terminated, gamma):
    """V(s_{t+1}) taken as values[t+1], which after a truncation is the next episode's first state."""
    following = np.append(np.asarray(values)[1:], np.asarray(next_values)[-1:], axis=0)
    return rewards + gamma * np.where(terminated, 0.0, following) - values


def gae_ignores_episode_ends(rewards, values, next_values, terminated, truncated, gamma, lam):
    """Â_t = δ_t + γλ Â_{t+1} through every episode end."""
    deltas = correct_td_residuals(rewards, values, next_values, terminated, gamma)
    advantages, following = np.zeros_like(deltas), np.zeros_like(deltas[0])
    for t in range(len(deltas) - 1, -1, -1):
        following = deltas[t] + gamma * lam * following
        advantages[t] = following
    return advantages


def gae_truncation_as_termination(rewards, values, next_values, terminated, truncated, gamma, lam):
    """Stops at a truncation, but also drops its bootstrap (δ uses V = 0 after a truncation)."""
    ended = np.asarray(terminated) | np.asarray(truncated)
    deltas = correct_td_residuals(rewards, values, next_values, ended, gamma)
    advantages, following = np.zeros_like(deltas), np.zeros_like(deltas[0])
    for t in range(len(deltas) - 1, -1, -1):
        following = deltas[t] + gamma * lam * np.where(ended[t], 0.0, following)
        advantages[t] = following
    return advantages


def gae_stops_only_at_termination(rewards, values, next_values, terminated, truncated, gamma, lam):
    """Flows back across a truncation into the previous episode."""
    deltas = correct_td_residuals(rewards, values, next_values, terminated, gamma)
    advantages, following = np.zeros_like(deltas), np.zeros_like(deltas[0])
    for t in range(len(deltas) - 1, -1, -1):
        following = deltas[t] + gamma * lam * np.where(terminated[t], 0.0, following)
        advantages[t] = following
    return advantages


def gae_decays_by_gamma_only(rewards, values, next_values, terminated, truncated, gamma, lam):
    """Decays by γ instead of γλ."""
    deltas = correct_td_residuals(rewards, values, next_values, terminated, gamma)
    ended = np.asarray(terminated) | np.asarray(truncated)
    advantages, following = np.zeros_like(deltas), np.zeros_like(deltas[0])
    for t in range(len(deltas) - 1, -1, -1):
        following = deltas[t] + gamma * np.where(ended[t], 0.0, following)
        advantages[t] = following
    return advantages


def gae_resets_after_the_end(rewards, values, next_values, terminated, truncated, gamma, lam):
    """Checks the episode end one step late: the first step of the next episode is cut off instead."""
    deltas = correct_td_residuals(rewards, values, next_values, terminated, gamma)
    ended = np.asarray(terminated) | np.asarray(truncated)
    advantages, following = np.zeros_like(deltas), np.zeros_like(deltas[0])
    for t in range(len(deltas) - 1, -1, -1):
        cut = ended[t - 1] if t > 0 else False
        following = deltas[t] + gamma * lam * np.where(cut, 0.0, following)
        advantages[t] = following
    return advantages


def gae_loop_never_ends(rewards, values, next_values, terminated, truncated, gamma, lam):
    """A while loop whose counter is never decremented: it runs until the time limit stops it."""
    deltas = correct_td_residuals(rewards, values, next_values, terminated, gamma)
    advantages, t = np.zeros_like(deltas), len(deltas) - 1
    while t >= 0:
        advantages[t] = deltas[t]
    return advantages


VARIANTS = {
    "returns_ignore_episode_ends": {"discounted_returns": returns_ignore_episode_ends},
    "returns_truncation_as_termination": {"discounted_returns": returns_truncation_as_termination},
    "returns_no_bootstrap_at_batch_end": {"discounted_returns": returns_no_bootstrap_at_batch_end},
    "td_ignores_termination": {"td_residuals": td_ignores_termination},
    "td_sign_flipped": {"td_residuals": td_sign_flipped},
    "td_next_value_from_the_next_row": {"td_residuals": td_next_value_from_the_next_row},
    "gae_ignores_episode_ends": {"gae": gae_ignores_episode_ends},
    "gae_truncation_as_termination": {"gae": gae_truncation_as_termination},
    "gae_stops_only_at_termination": {"gae": gae_stops_only_at_termination},
    "gae_decays_by_gamma_only": {"gae": gae_decays_by_gamma_only},
    "gae_resets_after_the_end": {"gae": gae_resets_after_the_end},
    "gae_loop_never_ends": {"gae": gae_loop_never_ends},
}
