"""Grading chapter 7: returns, TD residuals and GAE against brute-force sums over episodes, with episode ends inside
the batch, terminated versus truncated steps, a truncated or terminated final step, a step with both flags, several
environments side by side (T, N), float32 inputs and one-step batches.

Tests run from the most specific (one step, a short hand-worked batch) to the most general, so the first failure
names the mistake; a wrong entry is shown with its step, its flags and where its episode ends."""

import _harness
import numpy as np
import pytest
from _harness import call_checking_inputs, check_array, check_close, expect_number

student = _harness.student  # the fixture: the implementation under test (see _harness.py)
pytest_generate_tests = _harness.pytest_generate_tests  # one run per wrong variant under MINIPPO_IMPL=wrong
rng = _harness.rng  # a seeded NumPy Generator

pytestmark = pytest.mark.timeout(10)
GAMMA = 0.9


def random_batch(rng, T=24, truncate_last=False, terminate_last=False):
    """One environment, T steps: episodes end by termination at steps 5 and 17 and by truncation at step 11."""
    rewards, values = rng.normal(size=T), rng.normal(size=T)
    next_values = np.append(values[1:], rng.normal())
    terminated, truncated = np.zeros(T, bool), np.zeros(T, bool)
    terminated[[5, 17]] = True
    truncated[11] = True
    next_values[11] = rng.normal()  # V of the truncated episode's final observation, not of the next episode's start
    next_values[[5, 17]] = 1e6  # after a termination there is no next state: this number must not be used
    if truncate_last:
        truncated[-1] = True
    if terminate_last:
        terminated[-1] = True
        next_values[-1] = 1e6
    return rewards, values, next_values, terminated, truncated


def episode_end(t, terminated, truncated):
    """The last step of t's episode inside the batch."""
    while t < len(terminated) - 1 and not (terminated[t] or truncated[t]):
        t += 1
    return t


def describe_step(terminated, truncated):
    """For check_close's ``where``: the failing step, its flags, and where its episode ends."""

    def describe(index):
        t, column = int(index[0]), tuple(int(i) for i in index[1:])
        term, trunc = terminated[(slice(None), *column)], truncated[(slice(None), *column)]
        end = episode_end(t, term, trunc)
        how = (
            "by termination"
            if term[end]
            else "by truncation"
            if trunc[end]
            else "at the batch's end (cut by the horizon)"
        )
        role = f"this step ends its episode {how}" if end == t else f"its episode ends {how} at step {end}"
        env = f" of environment {column[0]}" if column else ""
        return f"step {t}{env}: terminated = {bool(term[t])}, truncated = {bool(trunc[t])}; {role}"

    return describe


def brute_force_returns(rewards, next_values, terminated, truncated, gamma):
    returns = np.zeros(len(rewards))
    for t in range(len(rewards)):
        end = episode_end(t, terminated, truncated)
        returns[t] = sum(gamma ** (k - t) * rewards[k] for k in range(t, end + 1))
        if not terminated[end]:  # cut by a time limit or by the end of the batch: bootstrap
            returns[t] += gamma ** (end - t + 1) * next_values[end]
    return returns


def brute_force_deltas(rewards, values, next_values, terminated, gamma):
    return np.array(
        [r + (0.0 if d else gamma * nv) - v for r, v, nv, d in zip(rewards, values, next_values, terminated)]
    )


def brute_force_gae(rewards, values, next_values, terminated, truncated, gamma, lam):
    deltas = brute_force_deltas(rewards, values, next_values, terminated, gamma)
    advantages = np.zeros(len(rewards))
    for t in range(len(rewards)):
        end = episode_end(t, terminated, truncated)
        advantages[t] = sum((gamma * lam) ** (k - t) * deltas[k] for k in range(t, end + 1))
    return advantages


# one step, and short batches worked by hand


def test_returns_of_a_one_step_batch(student):
    no = np.zeros(1, bool)
    returns = student.discounted_returns(np.array([2.0]), np.array([10.0]), no, no, GAMMA)
    check_array(returns, "discounted_returns", (1,), "G for a batch of one step")
    expect_number(returns, 2.0 + GAMMA * 10.0, "discounted_returns", "G for one step cut by the horizon", "r + γ V")
    ended = student.discounted_returns(np.array([2.0]), np.array([10.0]), np.ones(1, bool), no, GAMMA)
    expect_number(ended, 2.0, "discounted_returns", "G for one step that terminated", "just r, no bootstrap")


def test_returns_when_the_last_step_terminated(student):
    terminated = np.array([False, False, True])
    returns = student.discounted_returns(np.ones(3), np.array([0.0, 0.0, 1e6]), terminated, np.zeros(3, bool), 0.5)
    check_array(returns, "discounted_returns", (3,), "G for a batch whose last step terminated")
    check_close(
        returns,
        [1.75, 1.5, 1.0],
        "discounted_returns",
        "G for a batch whose last step terminated (no bootstrap there, even at the batch's end)",
        where=describe_step(terminated, np.zeros(3, bool)),
    )


def test_td_residuals_of_a_short_batch(student):
    terminated = np.array([False, True, False, False])
    deltas = student.td_residuals(
        np.array([1.0, 2.0, 3.0, 4.0]), np.array([0.5, 1.0, 1.5, 2.0]), np.array([1.0, 1e6, 2.0, 3.0]), terminated, 0.5
    )
    check_array(deltas, "td_residuals", (4,), "δ for a batch of four steps")
    check_close(
        deltas,
        [1.0, 1.0, 2.5, 3.5],
        "td_residuals",
        "δ_t = r_t + γ V(s_{t+1}) − V(s_t) for four steps, γ = 0.5 (V(s_{t+1}) = 0 after the termination at step 1)",
        where=describe_step(terminated, np.zeros(4, bool)),
    )


def test_td_residuals_take_the_next_value_from_next_values(student):
    # step 1 was truncated: next_values[1] = 4 is V of its episode's final observation, while values[2] = 1.5 is V of
    # the next episode's first state; δ_1 = 1 + 0.5·4 − 1 = 2
    deltas = student.td_residuals(
        np.ones(3), np.array([0.5, 1.0, 1.5]), np.array([1.0, 4.0, 2.0]), np.zeros(3, bool), 0.5
    )
    check_array(deltas, "td_residuals", (3,), "δ for a batch of three steps")
    check_close(
        deltas,
        [1.0, 2.0, 0.5],
        "td_residuals",
        "δ_t = r_t + γ next_values[t] − V(s_t), γ = 0.5, where step 1 was cut by a time limit (next_values[1] = 4 is V "
        "of that episode's final observation; values[2] = 1.5 belongs to the next episode, so V(s_{t+1}) is "
        "next_values[t], not values[t + 1])",
        where=lambda i: f"step {i[0]}: next_values[{i[0]}] = {[1.0, 4.0, 2.0][i[0]]:g}",
    )


def test_a_step_both_terminated_and_truncated_counts_as_terminated(student):
    terminated, truncated = np.array([False, True, False]), np.array([False, True, False])
    rewards, next_values = np.ones(3), np.array([0.0, 1e6, 4.0])
    returns = student.discounted_returns(rewards, next_values, terminated, truncated, 0.5)
    check_close(
        returns,
        [1.5, 1.0, 3.0],
        "discounted_returns",
        "G when step 1 is both terminated and truncated (terminated wins: no bootstrap)",
        where=describe_step(terminated, truncated),
    )


def test_gae_of_a_one_step_batch(student):
    no = np.zeros(1, bool)
    advantages = student.gae(np.array([1.0]), np.array([0.5]), np.array([2.0]), no, no, GAMMA, 0.95)
    check_array(advantages, "gae", (1,), "Â for a batch of one step")
    expect_number(advantages, 1.0 + GAMMA * 2.0 - 0.5, "gae", "Â for a batch of one step", "it is δ_0 = r + γ V′ − V")


def test_gae_of_one_short_episode(student):
    # no episode end inside: Â_2 = δ_2, Â_1 = δ_1 + γλ Â_2, Â_0 = δ_0 + γλ Â_1, with γλ = 0.45
    no = np.zeros(3, bool)
    rewards, values, next_values = np.array([1.0, 0.0, 2.0]), np.array([0.5, 1.0, 0.0]), np.array([1.0, 0.0, 2.0])
    deltas = rewards + 0.9 * next_values - values  # 1.4, −1, 3.8
    expected = [deltas[0] + 0.45 * (deltas[1] + 0.45 * deltas[2]), deltas[1] + 0.45 * deltas[2], deltas[2]]
    advantages = student.gae(rewards, values, next_values, no, no, 0.9, 0.5)
    check_array(advantages, "gae", (3,), "Â for one episode of three steps")
    check_close(
        advantages,
        expected,
        "gae",
        "Â for one episode of three steps, γ = 0.9, λ = 0.5 (Â_t = δ_t + γλ Â_{t+1}, so the decay is γλ = 0.45)",
        where=describe_step(no, no),
    )


@pytest.mark.parametrize("how", ["terminated", "truncated"])
def test_gae_stops_at_an_episode_end(student, how):
    # step 1 ends its episode; δ = (1, 1, 2) after a termination (its next value 1e6 unused), (1, 3, 2) after a
    # truncation (bootstrapped from V = 4 of the final observation); with γλ = 0.5, Â_1 = δ_1 and Â_0 = δ_0 + 0.5 Â_1
    flags = np.array([False, True, False])
    terminated, truncated = (flags, np.zeros(3, bool)) if how == "terminated" else (np.zeros(3, bool), flags)
    next_values = np.array([0.0, 1e6 if how == "terminated" else 4.0, 2.0])
    advantages = student.gae(np.ones(3), np.zeros(3), next_values, terminated, truncated, 0.5, 1.0)
    check_array(advantages, "gae", (3,), f"Â for three steps, step 1 {how}")
    check_close(
        advantages,
        [1.5, 1.0, 2.0] if how == "terminated" else [2.5, 3.0, 2.0],
        "gae",
        f"Â for three steps whose episode ends at step 1 by {how[:-2]}ion, γ = 0.5, λ = 1 (Â_1 = δ_1: nothing flows "
        "back from step 2, which starts a new episode; Â_0 = δ_0 + γλ Â_1)",
        where=describe_step(terminated, truncated),
    )


def test_gae_stops_at_a_step_both_terminated_and_truncated(student):
    terminated, truncated = np.array([False, True, False]), np.array([False, True, False])
    advantages = student.gae(np.ones(3), np.zeros(3), np.array([0.0, 1e6, 4.0]), terminated, truncated, 0.5, 1.0)
    check_close(
        advantages,
        [1.5, 1.0, 3.0],
        "gae",
        "Â when step 1 is both terminated and truncated (terminated wins: δ has no bootstrap)",
        where=describe_step(terminated, truncated),
    )


def test_gae_bootstraps_a_truncated_final_step(student):
    no = np.zeros(3, bool)
    truncated = np.array([False, False, True])
    advantages = student.gae(np.ones(3), np.zeros(3), np.array([0.0, 0.0, 5.0]), no, truncated, 0.5, 1.0)
    check_close(
        advantages,
        [1.75 + 0.625, 1.5 + 1.25, 1.0 + 2.5],
        "gae",
        "Â for a batch whose last step was truncated (bootstrap from V of the final observation)",
        where=describe_step(no, truncated),
    )


# discounted returns


@pytest.mark.parametrize("last", ["horizon-cut", "truncated", "terminated"])
def test_returns_match_the_sum_over_each_episode(student, rng, last):
    batch = random_batch(rng, truncate_last=last == "truncated", terminate_last=last == "terminated")
    rewards, _, next_values, terminated, truncated = batch
    returns = call_checking_inputs(
        student.discounted_returns, "discounted_returns", rewards, next_values, terminated, truncated, GAMMA
    )
    check_array(returns, "discounted_returns", (24,))
    expected = brute_force_returns(rewards, next_values, terminated, truncated, GAMMA)
    check_close(
        returns,
        expected,
        "discounted_returns",
        "G_t (summed to the end of each episode, bootstrapped where "
        "it was truncated or the batch ends, not after a termination)",
        where=describe_step(terminated, truncated),
    )


def test_td_residuals_match_the_definition(student, rng):
    rewards, values, next_values, terminated, _ = random_batch(rng)
    deltas = call_checking_inputs(student.td_residuals, "td_residuals", rewards, values, next_values, terminated, GAMMA)
    check_array(deltas, "td_residuals", (24,))
    expected = brute_force_deltas(rewards, values, next_values, terminated, GAMMA)
    check_close(
        deltas,
        expected,
        "td_residuals",
        "δ_t = r_t + γ V(s_{t+1}) − V(s_t), with V(s_{t+1}) = 0 after a termination",
        where=describe_step(terminated, np.zeros_like(terminated)),
    )


def test_a_perfect_value_function_has_zero_td_residuals(student, rng):
    rewards, _, next_values, terminated, truncated = random_batch(rng)
    # V(s_t) equal to the (bootstrapped) return: then r_t + γ V(s_{t+1}) = V(s_t) at every step
    values = brute_force_returns(rewards, next_values, terminated, truncated, GAMMA)
    next_values = next_values.copy()
    inside = ~(terminated | truncated)
    inside[-1] = False
    next_values[:-1][inside[:-1]] = values[1:][inside[:-1]]
    deltas = student.td_residuals(rewards, values, next_values, terminated, GAMMA)
    check_close(
        deltas, np.zeros(24), "td_residuals", "δ for an exact value function (it should be 0 everywhere)", atol=1e-9
    )


# GAE


@pytest.mark.parametrize("lam", [0.0, 0.5, 0.95, 1.0])
def test_gae_matches_the_sum_over_each_episode(student, rng, lam):
    batch = random_batch(rng)
    advantages = call_checking_inputs(student.gae, "gae", *batch, GAMMA, lam)
    check_array(advantages, "gae", (24,))
    expected = brute_force_gae(*batch, GAMMA, lam)
    check_close(
        advantages,
        expected,
        "gae",
        f"Â_t for λ = {lam} (Σ (γλ)^l δ_(t+l), stopping at the end of t's episode)",
        where=describe_step(batch[3], batch[4]),
    )


def test_gae_with_lambda_one_is_return_minus_value(student, rng):
    rewards, values, next_values, terminated, truncated = random_batch(rng, truncate_last=True)
    advantages = student.gae(rewards, values, next_values, terminated, truncated, GAMMA, 1.0)
    expected = brute_force_returns(rewards, next_values, terminated, truncated, GAMMA) - values
    check_close(advantages, expected, "gae", "Â for λ = 1 (it should be the discounted return minus V(s_t))")


def test_gae_does_not_flow_across_episode_ends(student, rng):
    rewards, values, next_values, terminated, truncated = random_batch(rng)
    before = student.gae(rewards, values, next_values, terminated, truncated, GAMMA, 0.95)
    changed = rewards.copy()
    changed[12:] += 100.0  # only the episodes after the truncation at step 11
    after = student.gae(changed, values, next_values, terminated, truncated, GAMMA, 0.95)
    check_close(
        after[:12],
        before[:12],
        "gae",
        "Â before an episode end, after rewards of the next episode changed "
        "(nothing may flow back across a termination or a truncation)",
    )


def stacked_batch(rng):
    """Three environments side by side, shape (T, N) = (24, 3), whose episodes end at different steps."""
    columns = [[np.roll(x, 4 * i) for x in random_batch(rng)] for i in range(3)]
    stacked = [np.stack([c[i] for c in columns], axis=1) for i in range(5)]
    stacked[3][2, 1] = True  # a termination in one environment only
    stacked[2][2, 1] = 1e6
    return stacked


def test_returns_for_several_environments(student, rng):
    rewards, values, next_values, terminated, truncated = stacked_batch(rng)
    returns = call_checking_inputs(
        student.discounted_returns, "discounted_returns", rewards, next_values, terminated, truncated, GAMMA
    )
    check_array(returns, "discounted_returns", (24, 3), "G for a batch of shape (T, N) = (24, 3)")
    for i in range(3):
        expected = brute_force_returns(rewards[:, i], next_values[:, i], terminated[:, i], truncated[:, i], GAMMA)
        check_close(
            returns[:, i],
            expected,
            "discounted_returns",
            f"G of environment {i} in a (T, N) batch (each column has its own episode ends)",
            where=describe_step(terminated[:, i], truncated[:, i]),
        )


def test_td_residuals_for_several_environments(student, rng):
    rewards, values, next_values, terminated, _ = stacked_batch(rng)
    deltas = call_checking_inputs(student.td_residuals, "td_residuals", rewards, values, next_values, terminated, GAMMA)
    check_array(deltas, "td_residuals", (24, 3), "δ for a batch of shape (T, N) = (24, 3)")
    expected = np.stack(
        [brute_force_deltas(rewards[:, i], values[:, i], next_values[:, i], terminated[:, i], GAMMA) for i in range(3)],
        axis=1,
    )
    check_close(
        deltas,
        expected,
        "td_residuals",
        "δ in a (T, N) batch",
        where=describe_step(terminated, np.zeros_like(terminated)),
    )


@pytest.mark.parametrize("function", ["discounted_returns", "td_residuals", "gae"])
def test_float32_inputs_give_float64_results(student, rng, function):
    """The rollout may store float32; the contract returns float64 whatever the inputs' float type."""
    rewards, values, next_values, terminated, truncated = (
        x.astype(np.float32) if x.dtype.kind == "f" else x for x in random_batch(rng)
    )
    next_values[[5, 17]] = 0.0
    if function == "discounted_returns":
        result = student.discounted_returns(rewards, next_values, terminated, truncated, GAMMA)
    elif function == "td_residuals":
        result = student.td_residuals(rewards, values, next_values, terminated, GAMMA)
    else:
        result = student.gae(rewards, values, next_values, terminated, truncated, GAMMA, 0.95)
    check_array(result, function, (24,), "the result for float32 inputs (it should still be float64)")


def test_gae_for_several_environments(student, rng):
    columns = [[np.roll(x, 4 * i) for x in random_batch(rng)] for i in range(3)]  # episode ends at other steps
    stacked = [np.stack([c[i] for c in columns], axis=1) for i in range(5)]
    stacked[3][2, 1] = True  # a termination in one environment only
    stacked[2][2, 1] = 1e6
    advantages = call_checking_inputs(student.gae, "gae", *stacked, GAMMA, 0.95)
    check_array(advantages, "gae", (24, 3), "Â for a batch of shape (T, N) = (24, 3)")
    for i in range(3):
        expected = brute_force_gae(*(x[:, i] for x in stacked), GAMMA, 0.95)
        check_close(
            advantages[:, i],
            expected,
            "gae",
            f"Â of environment {i} in a (T, N) batch",
            where=describe_step(stacked[3][:, i], stacked[4][:, i]),
        )


# the transfer task: GAE with a discount per step


def gae_step_discounts_by_definition(rewards, values, next_values, terminated, truncated, gammas, lam):
    """Â_t as the sum it stands for: Σ_l (∏ of the factors γ_j λ between t and t + l) δ_{t+l}, to the episode's end."""
    T = len(rewards)
    deltas = rewards + gammas * np.where(terminated, 0.0, next_values) - values
    result = np.zeros(T)
    for t in range(T):
        weight, s = 1.0, t
        while True:
            result[t] += weight * deltas[s]
            if terminated[s] or truncated[s] or s == T - 1:
                break
            weight *= gammas[s] * lam
            s += 1
    return result


@pytest.fixture
def step_discount_case(rng):
    T = 12
    terminated, truncated = np.zeros(T, bool), np.zeros(T, bool)
    terminated[4], truncated[8] = True, True
    return (rng.standard_normal(T), rng.standard_normal(T), rng.standard_normal(T), terminated, truncated,
            rng.uniform(0.5, 0.99, T))  # fmt: skip


def test_gae_with_step_discounts_of_two_steps(student):
    # Â_0 = δ_0 + γ_0 λ δ_1: the factor between steps 0 and 1 is γ_0, the discount of what follows step 0
    rewards, values, next_values = np.array([1.0, 0.0]), np.array([0.0, 0.0]), np.array([0.0, 1.0])
    flags = np.zeros(2, bool)
    gammas = np.array([0.5, 0.9])
    result = _harness.call_checking_inputs(
        student.gae_with_step_discounts, "gae_with_step_discounts", rewards, values, next_values, flags, flags.copy(),
        gammas, 1.0,
    )  # fmt: skip
    result = check_array(result, "gae_with_step_discounts", (2,), "Â")
    # δ_0 = 1, δ_1 = 0.9; Â_1 = 0.9, Â_0 = 1 + 0.5 · 0.9
    expected = [1.45, 0.9]
    if np.allclose(result, [1.81, 0.9]):
        raise AssertionError(
            "gae_with_step_discounts: for two steps with r = (1, 0), V = 0, next_values = (0, 1), γ = (0.5, 0.9), "
            "λ = 1, Â_0 should be 1.45 = δ_0 + γ_0 λ Â_1, not 1.81: the carry discounted by γ_{t+1}, the next step's "
            "own discount, where γ_t discounts what follows step t?"
        )
    mistakes = {
        "one γ for the whole batch (the mean of the gammas), where each step has its own": [1.49, 0.7],
        "δ_t bootstrapped without its γ_t: γ_t discounts V(s_{t+1}) in δ_t too": [1.5, 1.0],
    }
    for words, wrong in mistakes.items():
        if np.allclose(result, wrong):
            raise AssertionError(
                f"gae_with_step_discounts: for two steps with r = (1, 0), V = 0, next_values = (0, 1), γ = (0.5, 0.9), "
                f"λ = 1, Â should be {expected}, not {result.tolist()}: {words}?"
            )
    check_close(result, expected, "gae_with_step_discounts", "Â for r = (1, 0), next_values = (0, 1), γ = (0.5, 0.9)")


def test_gae_with_equal_step_discounts_is_gae(student, step_discount_case):
    rewards, values, next_values, terminated, truncated, _ = step_discount_case
    result = student.gae_with_step_discounts(rewards, values, next_values, terminated, truncated, np.full(12, 0.9), 0.8)
    from minippo.advantages import gae

    expected = gae(rewards, values, next_values, terminated, truncated, 0.9, 0.8)
    deltas = rewards + 0.9 * np.where(terminated, 0.0, next_values) - values
    across = np.zeros(12)
    for t in range(11, -1, -1):
        across[t] = deltas[t] + (0.9 * 0.8 * across[t + 1] if t < 11 else 0.0)
    if np.allclose(result, across):
        raise AssertionError(
            "gae_with_step_discounts: with every γ_t = 0.9, Â differs from chapter 7's gae before the episode ends at "
            "steps 4 (terminated) and 8 (truncated): the carry not stopped at an episode's end?"
        )
    check_close(
        check_array(result, "gae_with_step_discounts", (12,), "Â"),
        expected,
        "gae_with_step_discounts",
        "Â with every γ_t = 0.9 (chapter 7's gae)",
        where={"terminated": terminated, "truncated": truncated},
    )


def test_gae_with_step_discounts_matches_the_sum(student, step_discount_case):
    rewards, values, next_values, terminated, truncated, gammas = step_discount_case
    result = student.gae_with_step_discounts(rewards, values, next_values, terminated, truncated, gammas, 0.8)
    expected = gae_step_discounts_by_definition(rewards, values, next_values, terminated, truncated, gammas, 0.8)
    check_close(
        check_array(result, "gae_with_step_discounts", (12,), "Â"), expected, "gae_with_step_discounts",
        "Â against the sum of discounted TD residuals, with a different γ_t at every step",
        where={"γ_t": gammas, "terminated": terminated, "truncated": truncated},
    )  # fmt: skip
