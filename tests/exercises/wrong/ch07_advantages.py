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


def returns_python_if(rewards, next_values, terminated, truncated, gamma):
    """Right for one environment, but branches with a Python `if` on terminated[t], an array for (T, N) batches."""
    returns = np.zeros(np.shape(rewards))
    for t in range(len(rewards) - 1, -1, -1):
        if terminated[t]:
            returns[t] = rewards[t]
        elif truncated[t] or t == len(rewards) - 1:
            returns[t] = rewards[t] + gamma * next_values[t]
        else:
            returns[t] = rewards[t] + gamma * returns[t + 1]
    return returns


def returns_zeros_like(rewards, next_values, terminated, truncated, gamma):
    """Right numbers in an array made by np.zeros_like(rewards): float32 rewards give float32 returns."""
    returns = np.zeros_like(rewards)
    for t in range(len(rewards) - 1, -1, -1):
        following = next_values[t] if t == len(rewards) - 1 else np.where(truncated[t], next_values[t], returns[t + 1])
        returns[t] = rewards[t] + gamma * np.where(terminated[t], 0.0, following)
    return returns


def returns_bootstrap_last_step_always(rewards, next_values, terminated, truncated, gamma):
    """The batch's last step is always bootstrapped, even when it terminated."""
    returns = np.zeros(np.shape(rewards))
    for t in range(len(rewards) - 1, -1, -1):
        if t == len(rewards) - 1:
            returns[t] = rewards[t] + gamma * next_values[t]
        else:
            following = np.where(truncated[t], next_values[t], returns[t + 1])
            returns[t] = rewards[t] + gamma * np.where(terminated[t], 0.0, following)
    return returns


def returns_truncation_wins(rewards, next_values, terminated, truncated, gamma):
    """Looks at truncated before terminated: a step with both flags bootstraps from a state that was terminal."""
    returns = np.zeros(np.shape(rewards))
    for t in range(len(rewards) - 1, -1, -1):
        tail = returns[t + 1] if t < len(rewards) - 1 else next_values[t]
        tail = np.where(terminated[t], 0.0, tail)
        returns[t] = rewards[t] + gamma * np.where(truncated[t], next_values[t], tail)
    return returns


def td_python_if(rewards, values, next_values, terminated, gamma):
    """A loop with a Python `if terminated[t]`: an error for (T, N) batches."""
    deltas = np.zeros(np.shape(rewards))
    for t in range(len(rewards)):
        following = 0.0 if terminated[t] else next_values[t]
        deltas[t] = rewards[t] + gamma * following - values[t]
    return deltas


def td_float32(rewards, values, next_values, terminated, gamma):
    """Right numbers, but the inputs' float32 is kept."""
    return rewards + gamma * np.where(terminated, 0, next_values) - values


def gae_any_environment_ends(rewards, values, next_values, terminated, truncated, gamma, lam):
    """Cuts every environment's sum when any one of them ends an episode (np.any over the row)."""
    deltas = correct_td_residuals(rewards, values, next_values, terminated, gamma)
    ended = np.asarray(terminated) | np.asarray(truncated)
    advantages, following = np.zeros_like(deltas), np.zeros_like(deltas[0])
    for t in range(len(deltas) - 1, -1, -1):
        following = deltas[t] + gamma * lam * (0.0 if np.any(ended[t]) else following)
        advantages[t] = following
    return advantages


def gae_decays_by_lambda_only(rewards, values, next_values, terminated, truncated, gamma, lam):
    """Decays by λ instead of γλ."""
    deltas = correct_td_residuals(rewards, values, next_values, terminated, gamma)
    ended = np.asarray(terminated) | np.asarray(truncated)
    advantages, following = np.zeros_like(deltas), np.zeros_like(deltas[0])
    for t in range(len(deltas) - 1, -1, -1):
        following = deltas[t] + lam * np.where(ended[t], 0.0, following)
        advantages[t] = following
    return advantages


def gae_python_if(rewards, values, next_values, terminated, truncated, gamma, lam):
    """A Python `if terminated[t] or truncated[t]`: right for one environment, an error for (T, N)."""
    deltas = correct_td_residuals(rewards, values, next_values, terminated, gamma)
    advantages = np.zeros(np.shape(deltas))
    for t in range(len(deltas) - 1, -1, -1):
        if t == len(deltas) - 1 or terminated[t] or truncated[t]:
            advantages[t] = deltas[t]
        else:
            advantages[t] = deltas[t] + gamma * lam * advantages[t + 1]
    return advantages


def gae_resets_a_step_early(rewards, values, next_values, terminated, truncated, gamma, lam):
    """Checks the episode end of the step after: the last step of an episode is cut from the one before it, and the
    episode's end still takes the next episode's advantages."""
    deltas = correct_td_residuals(rewards, values, next_values, terminated, gamma)
    ended = np.asarray(terminated) | np.asarray(truncated)
    advantages = deltas.copy()
    for t in range(len(deltas) - 2, -1, -1):
        advantages[t] = deltas[t] + gamma * lam * np.where(ended[t + 1], 0.0, advantages[t + 1])
    return advantages


VARIANTS.update(
    {
        "gae_resets_a_step_early": {"gae": gae_resets_a_step_early},
        "returns_python_if": {"discounted_returns": returns_python_if},
        "returns_zeros_like": {"discounted_returns": returns_zeros_like},
        "returns_bootstrap_last_step_always": {"discounted_returns": returns_bootstrap_last_step_always},
        "returns_truncation_wins": {"discounted_returns": returns_truncation_wins},
        "td_python_if": {"td_residuals": td_python_if},
        "td_float32": {"td_residuals": td_float32},
        "gae_any_environment_ends": {"gae": gae_any_environment_ends},
        "gae_decays_by_lambda_only": {"gae": gae_decays_by_lambda_only},
        "gae_python_if": {"gae": gae_python_if},
    }
)

FIRST_FAILURE = {
    "returns_ignore_episode_ends": r"G for one step that terminated",
    "returns_truncation_as_termination": r"truncat",
    "returns_no_bootstrap_at_batch_end": r"one step cut by the horizon",
    "td_ignores_termination": r"td_residuals: .*termination",
    "td_sign_flipped": r"td_residuals",
    "returns_python_if": r"discounted_returns\(rewards=array \(24, 3\).*truth value.*np\.where",
    "returns_zeros_like": r"float64.*not float32",
    "returns_bootstrap_last_step_always": r"G for one step that terminated .*no bootstrap",
    "returns_truncation_wins": r"both terminated and truncated",
    "td_python_if": r"td_residuals\(rewards=array \(24, 3\).*truth value",
    "td_float32": r"td_residuals.*float64.*not float32",
    "gae_any_environment_ends": r"environment",
    "gae_decays_by_lambda_only": r"gae",
    "gae_python_if": r"gae\(rewards=array \(24, 3\).*truth value",
    "gae_loop_never_ends": r"took longer than",
    "td_next_value_from_the_next_row": r"td_residuals: .*next_values\[t\], not values\[t \+ 1\].*step 1",
    "gae_ignores_episode_ends": r"ends at step 1 by termination.*step 1: terminated = True",
    "gae_stops_only_at_termination": r"ends at step 1 by truncation.*step 1: terminated = False, truncated = True",
    "gae_resets_after_the_end": r"ends at step 1 by termination",
    "gae_resets_a_step_early": r"ends at step 1 by termination.*step 1: terminated = True",
    "gae_truncation_as_termination": r"ends at step 1 by truncation",
}


# the transfer task


def _step_deltas(rewards, values, next_values, terminated, gammas):
    return rewards + gammas * np.where(terminated, 0.0, next_values) - values


def step_gae_next_discount(rewards, values, next_values, terminated, truncated, gammas, lam):
    """The carry discounted by γ_{t+1}, the next step's own discount."""
    deltas = _step_deltas(rewards, values, next_values, terminated, gammas)
    result, carry = np.zeros(len(deltas)), 0.0
    for t in range(len(deltas) - 1, -1, -1):
        ends = terminated[t] or truncated[t] or t == len(deltas) - 1
        carry = deltas[t] + (0.0 if ends else gammas[t + 1] * lam * carry)
        result[t] = carry
    return result


def step_gae_mean_discount(rewards, values, next_values, terminated, truncated, gammas, lam):
    """One γ for the whole batch, the mean of the gammas."""
    gamma = float(np.mean(gammas))
    deltas = rewards + gamma * np.where(terminated, 0.0, next_values) - values
    result, carry = np.zeros(len(deltas)), 0.0
    for t in range(len(deltas) - 1, -1, -1):
        ends = terminated[t] or truncated[t] or t == len(deltas) - 1
        carry = deltas[t] + (0.0 if ends else gamma * lam * carry)
        result[t] = carry
    return result


def step_gae_across_episodes(rewards, values, next_values, terminated, truncated, gammas, lam):
    """The carry never reset at an episode's end."""
    deltas = _step_deltas(rewards, values, next_values, terminated, gammas)
    result, carry = np.zeros(len(deltas)), 0.0
    for t in range(len(deltas) - 1, -1, -1):
        carry = deltas[t] + (0.0 if t == len(deltas) - 1 else gammas[t] * lam * carry)
        result[t] = carry
    return result


def step_gae_discount_only_in_the_carry(rewards, values, next_values, terminated, truncated, gammas, lam):
    """The per-step γ in the carry, but δ_t bootstrapped with γ = 1."""
    deltas = rewards + np.where(terminated, 0.0, next_values) - values
    result, carry = np.zeros(len(deltas)), 0.0
    for t in range(len(deltas) - 1, -1, -1):
        ends = terminated[t] or truncated[t] or t == len(deltas) - 1
        carry = deltas[t] + (0.0 if ends else gammas[t] * lam * carry)
        result[t] = carry
    return result


VARIANTS.update(
    {
        "step_gae_next_discount": {"gae_with_step_discounts": step_gae_next_discount},
        "step_gae_mean_discount": {"gae_with_step_discounts": step_gae_mean_discount},
        "step_gae_across_episodes": {"gae_with_step_discounts": step_gae_across_episodes},
        "step_gae_discount_only_in_the_carry": {"gae_with_step_discounts": step_gae_discount_only_in_the_carry},
    }
)
FIRST_FAILURE.update(
    {
        "step_gae_next_discount": r"carry discounted by γ_\{t\+1\}",
        "step_gae_mean_discount": r"one γ for the whole batch",
        "step_gae_across_episodes": r"carry not stopped at an episode's end",
        "step_gae_discount_only_in_the_carry": r"bootstrapped without its γ_t",
    }
)
