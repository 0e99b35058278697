"""The corridor toy: exact values against independent computations, gradients against finite differences (float64),
and the explorer's claims (the clip holds the trust region, L^CPI breaks out of it)."""

import math

import numpy as np
import pytest
from conftest import assert_close, numerical_gradient

from minippo.errors import MinippoError
from minippo.toys import corridor as cd

GAMMA = cd.GAMMA


def random_logits(rng, scale=1.5):
    return rng.normal(0.0, scale, (cd.N_STATES, cd.N_ACTIONS))


def as_lists(array):
    return [list(map(float, row)) for row in array]


def transition_matrix(probs):
    """P^π among the five states, and the expected one-step reward R^π (the trap and the goal are absorbing)."""
    P = np.zeros((cd.N_STATES, cd.N_STATES))
    R = np.zeros(cd.N_STATES)
    for s in range(cd.N_STATES):
        if s > 0:
            P[s, s - 1] = probs[s][cd.LEFT]
        else:
            R[s] += probs[s][cd.LEFT] * cd.TRAP_REWARD
        if s < cd.N_STATES - 1:
            P[s, s + 1] = probs[s][cd.RIGHT]
        else:
            R[s] += probs[s][cd.RIGHT] * cd.GOAL_REWARD
    return P, R


def test_tridiagonal_solver_matches_numpy(rng):
    n = 7
    lower, upper = rng.normal(size=n), rng.normal(size=n)
    diag = np.abs(lower) + np.abs(upper) + 1.0 + rng.random(n)
    lower[0] = upper[-1] = 0.0
    rhs = rng.normal(size=n)
    A = np.diag(diag) + np.diag(lower[1:], -1) + np.diag(upper[:-1], 1)
    x = cd.solve_tridiagonal(list(lower), list(diag), list(upper), list(rhs))
    assert np.allclose(x, np.linalg.solve(A, rhs), rtol=1e-12, atol=1e-12)


def test_values_solve_the_bellman_equation(rng):
    for _ in range(5):
        probs = cd.softmax_policy(as_lists(random_logits(rng)))
        V = np.array(cd.state_values(probs))
        P, R = transition_matrix(probs)
        assert np.allclose(V, R + GAMMA * P @ V, atol=1e-13)
        # and against plain value iteration, which converges at rate γ
        iterate = np.zeros(cd.N_STATES)
        for _ in range(2000):
            iterate = R + GAMMA * P @ iterate
        assert np.allclose(V, iterate, atol=1e-12)


def test_action_values_and_advantages(rng):
    probs = cd.softmax_policy(as_lists(random_logits(rng)))
    V = cd.state_values(probs)
    Q = cd.action_values(V)
    A = cd.advantages_of(probs, Q, V)
    for s in range(cd.N_STATES):
        # V(s) = Σ_a π(a|s) Q(s,a), so the advantages average to zero under π
        assert math.isclose(sum(probs[s][a] * Q[s][a] for a in range(2)), V[s], abs_tol=1e-13)
        assert abs(sum(probs[s][a] * A[s][a] for a in range(2))) < 1e-13
    assert Q[0][cd.LEFT] == cd.TRAP_REWARD and Q[4][cd.RIGHT] == cd.GOAL_REWARD
    assert math.isclose(Q[2][cd.RIGHT], GAMMA * V[3])


def test_visitation_is_the_discounted_occupancy(rng):
    probs = cd.softmax_policy(as_lists(random_logits(rng)))
    d = np.array(cd.visitation(probs))
    P, _ = transition_matrix(probs)
    occupancy = np.zeros(cd.N_STATES)
    where = np.eye(cd.N_STATES)[0]  # P(s_t = s), starting at start
    for t in range(3000):
        occupancy += GAMMA**t * where
        where = where @ P
    assert np.allclose(d, occupancy, atol=1e-12)


def test_returns_of_known_policies():
    always_right = [[-40.0, 40.0]] * cd.N_STATES
    always_left = [[40.0, -40.0]] * cd.N_STATES
    assert math.isclose(cd.expected_return(always_right), GAMMA**4, rel_tol=1e-12)
    assert math.isclose(cd.optimal_return(), GAMMA**4)
    assert math.isclose(cd.expected_return(always_left), cd.TRAP_REWARD, rel_tol=1e-12)
    uniform = [[0.0, 0.0]] * cd.N_STATES
    assert cd.TRAP_REWARD < cd.expected_return(uniform) < cd.optimal_return()


def snapshot_and_logits(rng, noise_scale=0.3):
    """A random snapshot (with noisy advantages) and a θ whose ratios spread inside and outside the band."""
    old = as_lists(random_logits(rng))
    noise = list(rng.normal(size=cd.N_STATES * cd.N_ACTIONS))
    snapshot = cd.Snapshot(old, GAMMA, noise, noise_scale)
    logits = np.array(old) + rng.normal(0.0, 0.4, (cd.N_STATES, cd.N_ACTIONS))
    return snapshot, logits


def near_band_edge(logits, snapshot, epsilon, margin=1e-3):
    r = np.array(cd.ratios(cd.softmax_policy(as_lists(logits)), snapshot))
    return bool(np.any(np.abs(np.abs(r - 1.0) - epsilon) < margin))


@pytest.mark.parametrize("name", ["cpi", "clip", "klpen"])
def test_surrogate_gradients_match_finite_differences(rng, name):
    epsilon, beta = 0.2, 0.7
    checked = 0
    clipped_seen = False
    while checked < 6:
        snapshot, logits = snapshot_and_logits(rng)
        if name == "clip" and near_band_edge(logits, snapshot, epsilon):
            continue  # the clipped surrogate has a kink at the band's edges

        def objective(theta=logits, snapshot=snapshot):
            if name == "cpi":
                return cd.cpi_objective(as_lists(theta), snapshot)
            if name == "clip":
                return cd.clip_objective(as_lists(theta), snapshot, epsilon)
            return cd.kl_penalty_objective(as_lists(theta), snapshot, beta)

        _, grad = objective()
        assert_close(np.array(grad), numerical_gradient(lambda f=objective: f()[0], logits), rtol=1e-7)
        if name == "clip":
            clipped_seen |= any(any(row) for row in cd.clipped_mask(cd.softmax_policy(as_lists(logits)), snapshot, 0.2))
        checked += 1
    if name == "clip":
        assert clipped_seen, "no test point had a clipped (s, a): the zero-gradient branch went untested"


def test_surrogate_values_against_direct_sums(rng):
    snapshot, logits = snapshot_and_logits(rng)
    probs = np.array(cd.softmax_policy(as_lists(logits)))
    old = np.array(snapshot.probs)
    adv = np.array(snapshot.advantages)
    d = np.array(snapshot.visitation)[:, None]
    r = probs / old
    assert math.isclose(cd.cpi_objective(as_lists(logits), snapshot)[0], float((d * old * r * adv).sum()))
    clipped = np.minimum(r * adv, np.clip(r, 0.8, 1.2) * adv)
    assert math.isclose(cd.clip_objective(as_lists(logits), snapshot, 0.2)[0], float((d * old * clipped).sum()))
    kl = (old * np.log(old / probs)).sum(axis=1)
    assert np.allclose(cd.kl_per_state(snapshot, probs.tolist()), kl)
    expected = float((d * old * r * adv).sum() - 0.5 * (d[:, 0] * kl).sum())
    assert math.isclose(cd.kl_penalty_objective(as_lists(logits), snapshot, 0.5)[0], expected)
    assert math.isclose(cd.mean_kl(snapshot, probs.tolist()), float((d[:, 0] * kl).sum() / d.sum()))


def test_clipped_surrogate_is_a_lower_bound_on_cpi(rng):
    for _ in range(20):
        snapshot, logits = snapshot_and_logits(rng)
        for epsilon in (0.05, 0.2, 0.5):
            clip_value = cd.clip_objective(as_lists(logits), snapshot, epsilon)[0]
            assert clip_value <= cd.cpi_objective(as_lists(logits), snapshot)[0] + 1e-15


def test_cpi_gradient_at_the_snapshot_is_the_policy_gradient(rng):
    """∇_θ L^CPI at θ = θ_old equals ∇_θ V^π(start) (exact advantages, unnormalised visitation)."""
    for _ in range(3):
        logits = random_logits(rng)
        snapshot = cd.Snapshot(as_lists(logits))
        _, grad_cpi = cd.cpi_objective(as_lists(logits), snapshot)
        grad_v = numerical_gradient(lambda theta=logits: cd.expected_return(as_lists(theta)), logits)
        assert_close(np.array(grad_cpi), grad_v, rtol=1e-7)
        # at the snapshot nothing is clipped and the KL term has zero gradient: all three agree
        assert np.allclose(cd.clip_objective(as_lists(logits), snapshot, 0.2)[1], grad_cpi, atol=1e-15)
        assert np.allclose(cd.kl_penalty_objective(as_lists(logits), snapshot, 3.0)[1], grad_cpi, atol=1e-15)


def test_kl_and_clip_fraction(rng):
    snapshot, logits = snapshot_and_logits(rng)
    assert cd.mean_kl(snapshot, snapshot.probs) == 0.0
    assert cd.clip_fraction(snapshot.probs, snapshot, 0.2) == 0.0
    probs = cd.softmax_policy(as_lists(logits))
    assert cd.mean_kl(snapshot, probs) > 0.0
    r = np.array(cd.ratios(probs, snapshot))
    outside = np.abs(r - 1.0) > 0.2
    weights = np.array(snapshot.visitation)[:, None] * np.array(snapshot.probs)
    assert math.isclose(cd.clip_fraction(probs, snapshot, 0.2), float((weights * outside).sum() / weights.sum()))
    assert cd.kl_limit(0.2) == pytest.approx(0.04)


def test_noise_is_seeded_and_standard_normal():
    first = cd.Noise(7)
    again = cd.Noise(7)
    draws = [first.normal() for _ in range(20000)]
    assert draws[:50] == [again.normal() for _ in range(50)]
    assert [cd.Noise(8).normal() for _ in range(5)] != draws[:5]
    assert abs(np.mean(draws)) < 0.03 and abs(np.std(draws) - 1.0) < 0.03
    assert cd.Noise(3).uniform() == cd.Noise(3).uniform()
    generator = cd.Noise(123)
    sample = [generator.uniform() for _ in range(10000)]
    assert min(sample) >= 0.0 and max(sample) < 1.0 and abs(np.mean(sample) - 0.5) < 0.01
    # 32-bit words: every uniform is a multiple of 2⁻³²
    assert all((u * 4294967296.0).is_integer() for u in sample[:100])


def rounds_of(trace):
    grouped = {}
    for record in trace:
        grouped.setdefault(record["round"], []).append(record)
    return grouped


def test_explorer_plays_rounds_of_k_epochs():
    trace = cd.run({"epochs": 4}, ticks=10)
    assert [(r["round"], r["epoch"]) for r in trace] == [
        (1, 1), (1, 2), (1, 3), (1, 4), (2, 1), (2, 2), (2, 3), (2, 4), (3, 1), (3, 2)
    ]  # fmt: skip
    # a round's snapshot is the policy the previous round ended with: KL restarts near zero
    assert trace[4]["kl"] < trace[3]["kl"]
    changed = cd.run({"epochs": 4}, ticks=6, changes={3: {"epochs": 2}})
    assert [(r["round"], r["epoch"]) for r in changed] == [(1, 1), (1, 2), (2, 1), (2, 2), (3, 1), (3, 2)]


def test_same_settings_same_trace():
    assert cd.run({"preset": "noclip"}, ticks=90) == cd.run({"preset": "noclip"}, ticks=90)
    assert cd.run({"preset": "clip", "seed": 2}, ticks=30) != cd.run({"preset": "clip", "seed": 3}, ticks=30)


def test_clip_preset_holds_the_trust_region_and_learns():
    trace = cd.run({"preset": "clip"}, ticks=600)
    assert all(r["held"] for r in trace), max(r["kl"] for r in trace)
    assert any(r["clip_fraction"] > 0 for r in trace)  # the clip did act
    by_round = rounds_of(trace)
    ends = [by_round[k][-1]["return"] for k in sorted(by_round)]
    assert ends[0] < 0.0 < ends[5] < ends[20] < ends[-1]
    assert ends[-1] > 0.95 * cd.optimal_return()


def test_no_clip_preset_breaks_out_and_switching_to_clip_brings_it_back():
    trace = cd.run({"preset": "noclip"}, ticks=40 * 12)
    limit = cd.kl_limit(0.2)
    assert not all(r["held"] for r in trace)
    assert max(r["kl"] for r in trace) > 10 * limit
    broken_rounds = {r["round"] for r in trace if not r["held"]}
    assert len(broken_rounds) >= 2

    # switch to clip in the middle of round 2 (40 epochs a round): from round 3 on the light stays held
    switched = cd.run({"preset": "noclip"}, ticks=40 * 12, changes={60: {"objective": "clip"}})
    assert switched[58]["objective"] == "cpi" and switched[59]["objective"] == "clip"
    assert all(r["held"] for r in switched if r["round"] >= 3)
    assert switched[-1]["return"] > 0.9 * cd.optimal_return()


def test_huge_step_with_clip_stays_bounded_below_no_clip():
    huge = cd.run({"preset": "hugestep"}, ticks=40 * 20)
    noclip = cd.run({"preset": "noclip", "step_size": 3.0}, ticks=40 * 20)
    assert max(r["kl"] for r in huge) < 0.5 * max(r["kl"] for r in noclip)


def test_kl_penalty_adapts_beta():
    trace = cd.run({"preset": "clip", "objective": "klpen"}, ticks=200)
    betas = {r["beta"] for r in trace}
    assert len(betas) > 2 and all(b > 0 for b in betas)
    assert trace[-1]["return"] > trace[0]["return"]


def test_epsilon_moves_the_band_and_the_limit():
    wide = cd.run({"preset": "clip", "epsilon": 0.5}, ticks=10)[-1]
    narrow = cd.run({"preset": "clip", "epsilon": 0.05}, ticks=10)[-1]
    assert narrow["kl_limit"] < wide["kl_limit"]
    assert narrow["kl"] < wide["kl"]  # a narrower band lets the policy move less in a round
    assert narrow["clip_fraction"] > wide["clip_fraction"]


@pytest.mark.parametrize(
    "settings, message",
    [
        ({"objective": "ppo"}, "objective must be one of"),
        ({"epsilon": 0.9}, "epsilon must be a number in"),
        ({"epochs": 2.5}, "epochs must be a whole number"),
        ({"noise": "lots"}, "noise must be a number"),
        ({"clip": 0.2}, "unknown corridor setting"),
        ({"preset": "fast"}, "preset must be one of"),
        ({"gamma": 1.0}, "gamma must be in"),
        ({"seed": "one"}, "seed must be a whole number"),
        ({"kl_beta": None}, "kl_beta must be a number"),
    ],
)
def test_bad_settings_get_a_clear_error(settings, message):
    with pytest.raises(MinippoError, match=message):
        cd.run(settings, ticks=1)


def test_portable_exp_log_cos_match_the_math_module(rng):
    for x in rng.uniform(-60.0, 60.0, 5000):
        assert math.isclose(cd.exp(x), math.exp(x), rel_tol=4e-16)
    for x in np.exp(rng.uniform(-60.0, 60.0, 5000)):
        assert math.isclose(cd.log(x), math.log(x), rel_tol=4e-16, abs_tol=1e-16)
    for u in rng.random(5000):
        assert math.isclose(cd.cos_turns(u), math.cos(2.0 * math.pi * u), abs_tol=1e-15)
    assert cd.exp(0.0) == 1.0 and cd.log(1.0) == 0.0 and cd.cos_turns(0.0) == 1.0
    assert cd.exp(-800.0) == 0.0


def test_extreme_settings_stay_finite():
    for objective in cd.OBJECTIVES:
        trace = cd.run({"objective": objective, "step_size": 100.0, "noise": 1.0, "epochs": 100, "seed": 5}, 400)
        for record in trace:
            assert all(abs(z) <= cd.LOGIT_BOUND for row in record["logits"] for z in row)
            assert all(math.isfinite(record[key]) for key in ("kl", "return", "surrogate"))
