"""GAE and returns: brute-force sums, boundaries inside a batch, termination vs truncation."""

import numpy as np

from minippo.advantages import discounted_returns, gae, td_residuals


def brute_force_gae(rewards, values, next_values, terminated, truncated, gamma, lam):
    """Â_t = Σ_l (γλ)^l δ_{t+l}, summed until the episode (or the batch) ends."""
    deltas = td_residuals(rewards, values, next_values, terminated, gamma)
    T, out = len(rewards), np.zeros(len(rewards))
    for t in range(T):
        for l in range(T - t):
            out[t] += (gamma * lam) ** l * deltas[t + l]
            if terminated[t + l] or truncated[t + l]:
                break
    return out


def random_batch(rng, T=40):
    rewards, values = rng.normal(size=T), rng.normal(size=T)
    next_values = np.append(values[1:], rng.normal())
    terminated = np.zeros(T, bool)
    truncated = np.zeros(T, bool)
    terminated[[7, 23]] = True
    truncated[15] = True
    next_values[15] = rng.normal()  # V of the final observation of the truncated episode
    return rewards, values, next_values, terminated, truncated


def test_gae_matches_the_brute_force_sum(rng):
    batch = random_batch(rng)
    for lam in [0.0, 0.5, 0.95, 1.0]:
        assert np.allclose(gae(*batch, 0.99, lam), brute_force_gae(*batch, 0.99, lam))


def test_lambda_zero_is_td_and_lambda_one_is_monte_carlo(rng):
    rewards, values, next_values, terminated, truncated = random_batch(rng)
    assert np.allclose(
        gae(rewards, values, next_values, terminated, truncated, 0.9, 0.0),
        td_residuals(rewards, values, next_values, terminated, 0.9),
    )
    returns = discounted_returns(rewards, next_values, terminated, truncated, 0.9)
    assert np.allclose(gae(rewards, values, next_values, terminated, truncated, 0.9, 1.0), returns - values)


def test_a_perfect_value_function_gives_zero_residuals():
    gamma, rewards = 0.9, np.array([1.0, 2.0, 0.5, 3.0])
    terminated = np.array([False, False, False, True])
    values = discounted_returns(rewards, np.zeros(4), terminated, np.zeros(4, bool), gamma)
    next_values = np.append(values[1:], 123.0)  # ignored after termination
    assert np.allclose(td_residuals(rewards, values, next_values, terminated, gamma), 0)
    assert np.allclose(gae(rewards, values, next_values, terminated, np.zeros(4, bool), gamma, 0.95), 0)


def test_termination_and_truncation_differ_only_in_the_bootstrap():
    rewards, values = np.array([1.0, 1.0]), np.array([0.0, 0.0])
    next_values = np.array([5.0, 7.0])
    ended = np.array([True, False])
    term = gae(rewards, values, next_values, ended, np.zeros(2, bool), 0.5, 1.0)
    trunc = gae(rewards, values, next_values, np.zeros(2, bool), ended, 0.5, 1.0)
    assert term[0] == 1.0  # nothing follows a terminal state
    assert trunc[0] == 1.0 + 0.5 * 5.0  # bootstrap from V(final observation)
    assert term[1] == trunc[1] == 1.0 + 0.5 * 7.0  # the batch's last step bootstraps from V(s_T)


def test_parallel_environments_are_independent(rng):
    a, b = random_batch(rng), random_batch(rng)
    stacked = [np.stack([x, y], axis=1) for x, y in zip(a, b)]
    both = gae(*stacked, 0.99, 0.95)
    assert np.allclose(both[:, 0], gae(*a, 0.99, 0.95)) and np.allclose(both[:, 1], gae(*b, 0.99, 0.95))


def test_inputs_are_not_mutated(rng):
    batch = random_batch(rng)
    copies = [x.copy() for x in batch]
    gae(*batch, 0.99, 0.95)
    discounted_returns(batch[0], batch[2], batch[3], batch[4], 0.99)
    assert all(np.array_equal(x, y) for x, y in zip(batch, copies))
