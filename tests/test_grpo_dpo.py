"""GRPO and DPO in miniature: their hand-derived gradients against central finite differences in float64, the
group-relative advantages, the k3 estimator, the enumerable optimum π*, and short runs that learn."""

import numpy as np
import pytest
from conftest import assert_close, numerical_gradient

from minippo.distributions import Categorical
from minippo.lm import language as lm
from minippo.lm.dpo import DPOConfig, dpo_loss, dpo_loss_and_grad, response_tokens, sequence_log_probs, train_dpo
from minippo.lm.grpo import GRPOConfig, group_advantages, grpo_objective, k2, k3, train_grpo
from minippo.lm.reward_model import make_preferences
from minippo.lm.rlhf import (
    all_prompts,
    optimal_log_probs,
    pretrained_pieces,
    response_kl,
    response_log_probs,
    short_response_scores,
    short_responses,
)


def test_group_advantages_are_standardised_within_each_group_only():
    scores = np.array([[1.0, 2.0, 3.0, 6.0], [10.0, 10.0, 10.0, 10.0], [-5.0, 5.0, 0.0, 0.0]])
    advantages = group_advantages(scores)
    assert_close(advantages.mean(axis=1), np.zeros(3), atol=1e-12)
    assert_close(advantages[[0, 2]].std(axis=1), np.ones(2), rtol=1e-6)
    assert np.all(advantages[1] == 0.0)  # a group that all scored the same teaches nothing
    assert_close(advantages[0], (scores[0] - 3.0) / np.sqrt(3.5), rtol=1e-6)


def test_k3_is_an_unbiased_never_negative_estimate_of_the_kl(rng):
    logits, logits_ref = rng.normal(size=6), rng.normal(size=6)
    p, q = np.exp(logits - np.logaddexp.reduce(logits)), np.exp(logits_ref - np.logaddexp.reduce(logits_ref))
    estimates = k3(np.log(p), np.log(q))
    assert np.all(estimates >= 0.0)
    assert np.isclose(p @ estimates, p @ np.log(p / q))  # its expectation under π is KL[π ‖ π_ref], exactly


def test_group_advantages_without_the_std_division_are_centred_scores():
    scores = np.array([[1.0, 2.0, 3.0, 6.0], [0.0, 0.0, 4.0, 4.0]])
    assert_close(group_advantages(scores, normalize_std=False), scores - scores.mean(axis=1, keepdims=True))


def test_k3_in_the_loss_follows_the_forward_kl_and_k1_in_the_reward_the_reverse_kl(rng):
    """Exact expectations over a categorical π = softmax(z): the gradient of β k3 taken through log π with the sample
    held (what grpo_objective returns, per token) averages to ∇KL[π_ref ‖ π]; the log-ratio used as a reward, to
    ∇KL[π ‖ π_ref]. Both KLs' gradients are checked by central finite differences."""
    z, logits_ref = rng.normal(size=5), rng.normal(size=5)
    log_ref = logits_ref - np.logaddexp.reduce(logits_ref)

    def log_pi():
        return z - np.logaddexp.reduce(z)

    grad_log_pi = np.eye(5) - np.exp(log_pi())  # row a: ∇_z log π(a)
    forward = numerical_gradient(lambda: float(np.exp(log_ref) @ (log_ref - log_pi())), z)
    reverse = numerical_gradient(lambda: float(np.exp(log_pi()) @ (log_pi() - log_ref)), z)
    # grpo_objective's gradient with Â = 0, β = 1 and weight 1 is −∂k3/∂log π, token by token
    _, grad = grpo_objective(log_pi(), log_pi(), log_ref, np.zeros(5), np.ones(5), 0.2, 1.0)
    in_the_loss = np.exp(log_pi()) @ (-grad[:, None] * grad_log_pi)
    in_the_reward = np.exp(log_pi()) @ ((log_pi() - log_ref)[:, None] * grad_log_pi)
    assert_close(in_the_loss, forward)
    assert_close(in_the_reward, reverse)
    assert np.abs(in_the_loss - reverse).max() > 1e-2  # the two KLs' gradients differ here


def test_k2_in_the_loss_follows_the_reverse_kl(rng):
    """The per-token switch that keeps the KL in the loss but changes its estimator: grpo_objective's gradient with
    k2, Â = 0, β = 1 and weight 1, taken through log π with the sample held, averages exactly over π = softmax(z) to
    ∇KL[π ‖ π_ref] (by central finite differences), not to the forward KL's gradient that k3 gives."""
    z, logits_ref = rng.normal(size=5), rng.normal(size=5)
    log_ref = logits_ref - np.logaddexp.reduce(logits_ref)

    def log_pi():
        return z - np.logaddexp.reduce(z)

    grad_log_pi = np.eye(5) - np.exp(log_pi())
    forward = numerical_gradient(lambda: float(np.exp(log_ref) @ (log_ref - log_pi())), z)
    reverse = numerical_gradient(lambda: float(np.exp(log_pi()) @ (log_pi() - log_ref)), z)
    _, grad = grpo_objective(log_pi(), log_pi(), log_ref, np.zeros(5), np.ones(5), 0.2, 1.0, "k2")
    in_the_loss = np.exp(log_pi()) @ (-grad[:, None] * grad_log_pi)
    assert_close(in_the_loss, reverse)
    assert np.abs(in_the_loss - forward).max() > 1e-2
    assert np.all(k2(log_pi(), log_ref) >= 0.0)


def test_grpo_objective_with_k2_matches_finite_differences(rng):
    """The k2 objective's hand-derived gradient, w_t (surrogate − β log(π_θ/π_ref)), against central differences in
    float64, with log-ratios far enough from 0 that k3's derivative, a wrong sign or a missing ½ would all show."""
    n = 12
    logp_old = np.log(rng.uniform(0.05, 0.9, n))
    logp = logp_old + rng.normal(0, 0.3, n)
    logp_ref = logp + rng.normal(0, 1.0, n)
    advantages, weights = rng.normal(size=n), rng.uniform(0.01, 0.2, n)
    ratio = np.exp(logp - logp_old)
    assert np.all(np.abs(ratio - 0.8) > 1e-4) and np.all(np.abs(ratio - 1.2) > 1e-4)  # away from the kinks
    value, grad = grpo_objective(logp, logp_old, logp_ref, advantages, weights, 0.2, 0.7, "k2")
    numeric = numerical_gradient(
        lambda: grpo_objective(logp, logp_old, logp_ref, advantages, weights, 0.2, 0.7, "k2")[0], logp
    )
    assert_close(grad, numeric)
    surrogate, _ = grpo_objective(logp, logp_old, logp_ref, advantages, weights, 0.2, 0.0)
    assert np.isclose(value, surrogate - 0.7 * np.sum(weights * 0.5 * (logp - logp_ref) ** 2))
    _, grad_k3 = grpo_objective(logp, logp_old, logp_ref, advantages, weights, 0.2, 0.7)
    assert np.abs(grad - grad_k3).max() > 1e-3  # the two estimators' gradients differ on these tokens


@pytest.mark.parametrize(
    "fields",
    [dict(normalize_std=False), dict(kl_in="reward"), dict(average_over_tokens=False), dict(kl_estimator="k2")],
    ids=["normalize_std", "kl_in", "average_over_tokens", "kl_estimator"],
)
def test_each_grpo_switch_changes_the_update(small_pieces, fields):
    model, reward_model, _ = small_pieces
    config = dict(updates=2, prompts=2, group=4, beta=0.5)  # responses of different lengths
    published = train_grpo(model, reward_model, GRPOConfig(**config))[0]
    switched = train_grpo(model, reward_model, GRPOConfig(**config, **fields))[0]
    assert not np.allclose(published.params, switched.params)


def test_an_unknown_kl_place_or_estimator_is_an_error():
    with pytest.raises(ValueError, match="kl_in"):
        GRPOConfig(kl_in="advantage")
    with pytest.raises(ValueError, match="kl_estimator"):
        GRPOConfig(kl_estimator="k1")


def test_grpo_objective_gradient_matches_finite_differences(rng):
    n = 12
    logp_old = np.log(rng.uniform(0.05, 0.9, n))
    logp = logp_old + rng.normal(0, 0.3, n)
    logp_ref = np.log(rng.uniform(0.05, 0.9, n))
    advantages, weights = rng.normal(size=n), rng.uniform(0.01, 0.2, n)
    ratio = np.exp(logp - logp_old)
    assert np.all(np.abs(ratio - 0.8) > 1e-4) and np.all(np.abs(ratio - 1.2) > 1e-4)  # away from the kinks
    value, grad = grpo_objective(logp, logp_old, logp_ref, advantages, weights, 0.2, 0.3)
    numeric = numerical_gradient(
        lambda: grpo_objective(logp, logp_old, logp_ref, advantages, weights, 0.2, 0.3)[0], logp
    )
    assert_close(grad, numeric)
    clipped = ratio * advantages > np.clip(ratio, 0.8, 1.2) * advantages  # where the min takes the clipped term
    assert clipped.any() and not clipped.all()  # so both branches are checked


def test_dpo_loss_gradient_matches_finite_differences(rng):
    logp_w, logp_l = rng.normal(-6, 2, 9), rng.normal(-6, 2, 9)
    ref_w, ref_l = rng.normal(-6, 2, 9), rng.normal(-6, 2, 9)
    loss, grad_w, grad_l = dpo_loss(logp_w, logp_l, ref_w, ref_l, 0.7)
    margin = 0.7 * ((logp_w - ref_w) - (logp_l - ref_l))
    assert np.isclose(loss, np.mean(np.log1p(np.exp(-margin))))
    assert_close(grad_w, numerical_gradient(lambda: dpo_loss(logp_w, logp_l, ref_w, ref_l, 0.7)[0], logp_w))
    assert_close(grad_l, numerical_gradient(lambda: dpo_loss(logp_w, logp_l, ref_w, ref_l, 0.7)[0], logp_l))


def test_dpo_gradient_through_the_language_model_matches_finite_differences(rng):
    model = lm.new_language_model(rng, hidden=6)
    model.params[...] += 0.3 * rng.standard_normal(model.params.shape)
    policy = model.nets["policy"]
    preferred, rejected = make_preferences(3, rng)
    data_w, data_l = response_tokens(*preferred, lm.PROMPT_LEN), response_tokens(*rejected, lm.PROMPT_LEN)
    ref_w, ref_l = rng.normal(-8, 1, 3), rng.normal(-8, 1, 3)
    dpo_loss_and_grad(policy, data_w, data_l, ref_w, ref_l, 0.5)
    analytic = policy.grads.copy()
    numeric = numerical_gradient(lambda: dpo_loss_and_grad(policy, data_w, data_l, ref_w, ref_l, 0.5), policy.params)
    assert_close(analytic, numeric, rtol=1e-6, atol=1e-9)
    # and the sequence log-probability is the sum of the response's tokens, prompt excluded
    logp, _ = sequence_log_probs(policy, data_w, 3)
    tokens, lengths = preferred
    by_hand = sum(
        Categorical(policy(lm.prefix_features(tokens[:1], t))).log_prob(tokens[:1, t])[0]
        for t in range(lm.PROMPT_LEN, lengths[0])
    )
    assert np.isclose(logp[0], by_hand)


def test_the_enumerated_responses_are_a_distribution_and_pi_star_closes_the_gap():
    model, reward_model, _ = pretrained_pieces(seed=5, corpus_size=200, pairs=100, hidden=16, epochs=2)
    prompts = all_prompts(3)
    assert prompts.shape == (72, 3)
    tokens, lengths = short_responses()
    assert len(tokens) == 1 + (lm.V - 1) * lm.V and lengths[0] == 1
    logp_ref = response_log_probs(model, prompts)
    assert_close(np.exp(logp_ref).sum(axis=1), np.ones(72), atol=1e-12)
    scores = short_response_scores(reward_model, prompts)
    for i in (0, len(lm.VERBS)):  # "the cat is", "the dog is": the scores depend on the prompt's noun
        texts = np.concatenate([prompts[i : i + 1].repeat(len(tokens), axis=0), tokens], axis=1)
        # the response only: the verb is the prompt's, and counting it would shift every score by its weight
        assert_close(scores[i], reward_model.score(texts, 3 + lengths, 3))
        assert not np.allclose(scores[i], reward_model.score(texts, 3 + lengths))
    assert not np.allclose(scores[0], scores[len(lm.VERBS)])
    beta = 0.5
    logp_star, log_z = optimal_log_probs(logp_ref, scores, beta)

    def objective(logp):
        return float(np.mean(np.sum(np.exp(logp) * (scores - beta * (logp - logp_ref)), axis=1)))

    assert np.isclose(objective(logp_star), beta * log_z.mean())  # J(π*) = β Ê log Z
    assert np.isclose(objective(logp_star) - objective(logp_ref), beta * response_kl(logp_ref, logp_star))
    assert response_kl(logp_star, logp_star) == 0.0 and response_kl(logp_ref, logp_star) > 0.0


@pytest.fixture(scope="module")
def small_pieces():
    return pretrained_pieces(seed=0, corpus_size=1000, pairs=1000, hidden=32, epochs=6)


@pytest.mark.timeout(300)
def test_grpo_raises_the_score_and_dpo_fits_the_pairs(small_pieces):
    model, reward_model, _ = small_pieces
    before = model.params.copy()
    _, grpo = train_grpo(model, reward_model, GRPOConfig(updates=15, prompts=4, group=8))
    assert np.mean([s["score"] for s in grpo[-3:]]) > np.mean([s["score"] for s in grpo[:3]]) + 0.5
    preferred, rejected = make_preferences(400, np.random.default_rng(7))
    _, dpo = train_dpo(model, preferred, rejected, DPOConfig(epochs=3))
    assert dpo[-1]["loss"] < dpo[0]["loss"] and dpo[-1]["accuracy"] > 0.6
    assert np.array_equal(model.params, before), "the reference policy must stay frozen"


def test_grpo_and_dpo_are_the_same_for_the_same_seed(small_pieces):
    model, reward_model, _ = small_pieces
    config = GRPOConfig(updates=2, prompts=2, group=4)
    first, again = train_grpo(model, reward_model, config), train_grpo(model, reward_model, config)
    assert np.array_equal(first[0].params, again[0].params) and first[1] == again[1]
    preferred, rejected = make_preferences(50, np.random.default_rng(3))
    first, again = (train_dpo(model, preferred, rejected, DPOConfig(epochs=1)) for _ in range(2))
    assert np.array_equal(first[0].params, again[0].params) and first[1] == again[1]


@pytest.mark.parametrize(
    "argv, message",
    [
        (["dpo", "--restricted", "0"], "--restricted must be between 1"),
        (["grpo", "--iterations", "10"], "--iterations must be at least 30"),
        (["dpo", "--pairs", "0,10"], "pairs are whole numbers"),
        (["grpo", "--seeds", "3-1"], "seeds are N or N-M"),
    ],
)
def test_chapter_14s_benchmark_refuses_bad_arguments_in_one_line(argv, message, capsys):
    from benchmarks import grpo_dpo

    with pytest.raises(SystemExit) as stopped:
        grpo_dpo.main(argv)
    assert stopped.value.code == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert message in error[-1] and "Traceback" not in "".join(error)
