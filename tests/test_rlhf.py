"""The language model in miniature: its grammar, the gradients of its pretraining and of the Bradley–Terry reward
model (central differences in float64), the KL-shaped rewards, and PPO on tokens learning with a bounded KL."""

import dataclasses
import typing

import numpy as np
import pytest
from conftest import assert_close, numerical_gradient

from minippo.config import Config
from minippo.distributions import Categorical
from minippo.lm import language as lm
from minippo.lm.reward_model import TASTES, RewardModel, bradley_terry_loss, make_preferences, rater_score
from minippo.lm.rlhf import (
    RLHFConfig,
    collect,
    kl_shaped_rewards,
    pretrained_pieces,
    proportional_beta,
    token_advantages,
    train_rlhf,
)
from minippo.minibatches import epochs_of
from minippo.optimizer import Adam
from minippo.ppo import UpdateSettings, update_minibatch


def test_the_grammar_writes_well_formed_sentences_and_the_checker_rejects_others(rng):
    for _ in range(200):
        assert lm.is_well_formed(lm.sample_sentence(rng))
    for bad in (
        "the cat is good good .",
        "the cat is good",
        "cat the is good .",
        "the cat is good and .",
        "the cat is very .",
        "the cat is good bad .",
        "the cat is good . .",
    ):
        assert not lm.is_well_formed(bad.split()), bad
    assert lm.is_well_formed("my day was very good and bad but very new and old .".split())


def test_the_rater_counts_words_and_ranks_ill_formed_sentences_last():
    assert rater_score("the cat is good and great but sad .".split()) == 1.0
    assert rater_score("the cat is bad and sad but poor and dull and awful .".split()) == -5.0
    worst = "the cat is bad and sad but poor and dull and awful and big ."
    assert rater_score(worst.split()) == -6.0 > rater_score("the cat is good good good .".split())


def test_the_raters_taste_depends_on_the_subject():
    assert rater_score("the cat is small .".split()) == 1.0 and rater_score("the dog is small .".split()) == -1.0
    assert rater_score("a day was long and good .".split()) == 0.0 and rater_score("a meal was long .".split()) == 1.0
    assert rater_score("my song is old .".split()) == 1.0 and rater_score("my film is old .".split()) == -1.0


def test_prefix_features_describe_the_prefix():
    tokens = lm.encode("the cat is good .".split())[None, :]
    obs = lm.prefix_features(tokens, 3)  # predicting "good" after "the cat is"
    V, W = lm.V, lm.WINDOW
    window = obs[0, : W * V].reshape(W, V)
    assert [lm.VOCAB[i] for i in window.argmax(axis=1)] == ["is", "cat", "the"]
    counts = obs[0, W * V : W * V + V]
    assert counts.sum() == 3 and counts[lm.TOKEN["cat"]] == 1
    assert obs[0, W * V + V + 3] == 1 and obs[0, W * V + V :].sum() == 1
    first = lm.prefix_features(tokens, 0)[0, : W * V].reshape(W, V)
    assert np.all(first.argmax(axis=1) == lm.TOKEN[lm.BOS])


def test_pretraining_gradient_matches_finite_differences(rng):
    model = lm.new_language_model(rng, hidden=8)
    model.params[...] += 0.3 * rng.standard_normal(model.params.shape)  # move the output layer off its 0.01 scale
    tokens, lengths = lm.make_corpus(4, rng)
    obs = lm.sequence_features(tokens)[:, :5].reshape(-1, lm.OBS_DIM)
    targets = tokens[:, :5].reshape(-1)
    lm.nll_and_grad(model, obs, targets)
    analytic = model.nets["policy"].grads.copy()
    policy = model.nets["policy"]
    grads_scratch = model.grads.copy()
    numeric = numerical_gradient(lambda: lm.nll_and_grad(model, obs, targets), policy.params)
    model.grads[...] = grads_scratch
    assert_close(analytic, numeric, rtol=1e-6, atol=1e-8)


def test_bradley_terry_gradient_matches_finite_differences(rng):
    preferred, rejected = rng.normal(0, 2, 7), rng.normal(0, 2, 7)
    loss, grad_w, grad_l = bradley_terry_loss(preferred, rejected)
    assert_close(grad_w, numerical_gradient(lambda: bradley_terry_loss(preferred, rejected)[0], preferred))
    assert_close(grad_l, numerical_gradient(lambda: bradley_terry_loss(preferred, rejected)[0], rejected))
    assert np.isclose(loss, np.mean(np.log1p(np.exp(-(preferred - rejected)))))


def test_bradley_terry_loss_is_finite_for_huge_margins():
    loss, grad_w, grad_l = bradley_terry_loss(np.array([1000.0, -1000.0]), np.array([0.0, 0.0]))
    assert np.isclose(loss, 500.0) and np.allclose(grad_w, [0.0, -0.5]) and np.allclose(grad_l, [0.0, 0.5])


def reference_scores(model: RewardModel, tokens: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """r(x, y) = Σ_t (θ_{y_t} + Θ_{n(x), y_t}) over the response's tokens, word by word, without model.features."""
    theta, by_noun = model.weights[: lm.V], np.zeros((len(lm.NOUNS), lm.V))
    if model.by_subject:
        by_noun = model.weights[lm.V :].reshape(len(lm.NOUNS), lm.V)
    scores = []
    for row, n in zip(tokens, lengths):
        noun = lm.NOUNS.index(lm.VOCAB[row[1]])  # a corpus text is DET NOUN ...
        scores.append(sum(theta[t] + by_noun[noun, t] for t in row[model.prompt_len : n]))
    return np.array(scores)


@pytest.mark.parametrize("by_subject", [True, False])
def test_reward_model_gradient_matches_finite_differences(rng, by_subject):
    """The analytic gradient (through model.features) against central differences of the loss computed from
    reference_scores, so that a (noun, word) block put in the wrong place (the noun ignored, or another's) shows."""
    model = RewardModel(l2=0.1, by_subject=by_subject)
    model.weights[...] = rng.standard_normal(model.weights.shape)
    preferred, rejected = lm.make_corpus(24, rng), lm.make_corpus(24, rng)
    _, analytic = model.loss_and_grad(model.features(*preferred), model.features(*rejected))

    def loss():
        bt, _, _ = bradley_terry_loss(reference_scores(model, *preferred), reference_scores(model, *rejected))
        return bt + 0.5 * model.l2 * float(model.weights @ model.weights)

    numeric = numerical_gradient(loss, model.weights)
    assert_close(analytic, numeric)
    if by_subject:  # the data reach several subjects' blocks, so a block in the wrong place cannot pass
        data_part = (numeric - model.l2 * model.weights)[lm.V :].reshape(len(lm.NOUNS), lm.V)
        assert np.count_nonzero(np.abs(data_part).max(axis=1) > 1e-6) >= 4
    else:
        assert analytic.shape == (lm.V,)


def test_the_reward_model_weighs_a_word_by_the_prompts_subject():
    model = RewardModel()
    small = lm.TOKEN["small"]
    model.weights[small] = 0.5  # θ_small, for every subject
    model.weights[lm.V + lm.NOUNS.index("cat") * lm.V + small] = 2.0  # Θ_{cat, small}
    texts = np.stack([lm.encode(f"the {noun} is small .".split()) for noun in ("cat", "dog")])
    assert_close(model.score(texts, np.array([5, 5])), [2.5, 0.5])
    assert model.word_weights("cat")[small] == 2.5 and model.word_weights("dog")[small] == 0.5


def test_kl_shaped_rewards_by_hand():
    logp = np.log(np.array([[0.5, 0.5, 0.5], [0.2, 0.2, 0.2]]))
    logp_ref = np.log(np.array([[0.25, 0.5, 0.9], [0.4, 0.4, 0.4]]))
    rewards = kl_shaped_rewards(logp, logp_ref, np.array([3.0, -1.0]), np.array([2, 3]), beta=0.5)
    expected = np.array([[-0.5 * np.log(2), 3.0, 0.0], [0.5 * np.log(2), 0.5 * np.log(2), 0.5 * np.log(2) - 1.0]])
    assert_close(rewards, expected)


def test_token_advantages_restart_at_each_sequence_end():
    batch = {
        "rewards": np.array([[0.0, 2.0, 5.0], [0.0, 0.0, 1.0]]),
        "values": np.zeros((2, 3)),
        "lengths": np.array([2, 3]),
    }
    advantages, returns = token_advantages(batch, gamma=1.0, lam=1.0)
    assert_close(advantages, [[2.0, 2.0, 5.0], [1.0, 1.0, 1.0]])  # the 5 after the first sequence's end stays out
    assert_close(returns, advantages)


@pytest.fixture(scope="module")
def pieces():
    return pretrained_pieces(seed=0, corpus_size=1500, pairs=1500, hidden=64, epochs=8)


def test_pretraining_learns_the_grammar_and_the_reward_model_the_rule(pieces):
    model, reward_model, record = pieces
    assert record["pretrain_losses"][-1] < record["pretrain_losses"][0] - 0.2
    tokens, lengths = lm.generate(model, 300, np.random.default_rng(1))
    well_formed = np.mean([lm.is_well_formed([lm.VOCAB[t] for t in row[:n]]) for row, n in zip(tokens, lengths)])
    assert well_formed > 0.85, well_formed
    weights = {noun: dict(zip(lm.VOCAB, reward_model.word_weights(noun))) for noun in lm.NOUNS}
    assert np.mean([weights[noun][w] for noun in lm.NOUNS for w in lm.POSITIVE]) > 0.5
    assert np.mean([weights[noun][w] for noun in lm.NOUNS for w in lm.NEGATIVE]) < -0.5
    for noun in lm.NOUNS:
        for word, taste in TASTES[noun].items():
            assert weights[noun][word] * taste > 0.1, (noun, word)  # it learned the subject's taste
    assert record["held_out_accuracy"] > 0.65
    assert record["held_out_accuracy"] > record["blind_held_out_accuracy"]  # reading the subject helps


@pytest.mark.slow  # a learning run
@pytest.mark.timeout(300)
def test_ppo_on_tokens_raises_the_reward_with_a_bounded_kl_and_hacks_it_without_the_penalty(pieces):
    model, reward_model, _ = pieces
    before = model.params.copy()
    _, penalised = train_rlhf(model, reward_model, RLHFConfig(seed=0, beta=0.5, updates=40))
    _, free = train_rlhf(model, reward_model, RLHFConfig(seed=0, beta=0.0, updates=40))
    assert np.array_equal(model.params, before), "the reference policy must stay frozen"
    start = np.mean([s["score"] for s in penalised[:3]])
    end = {
        name: {k: np.mean([s[k] for s in run[-5:]]) for k in run[0]}
        for name, run in (("penalised", penalised), ("free", free))
    }
    assert end["penalised"]["score"] > start + 1.0
    assert end["penalised"]["kl_to_reference"] < 4.0
    assert end["penalised"]["well_formed"] > 0.7
    assert end["free"]["score"] > end["penalised"]["score"] + 5.0  # the reward model's score runs away ...
    assert end["free"]["well_formed"] < 0.2  # ... on text the rater calls broken
    assert end["free"]["kl_to_reference"] > 5 * end["penalised"]["kl_to_reference"]


def test_the_pretrained_pieces_are_the_same_for_the_same_seed():
    first = pretrained_pieces(seed=5, corpus_size=200, pairs=100, hidden=16, epochs=2)
    second = pretrained_pieces(seed=5, corpus_size=200, pairs=100, hidden=16, epochs=2)
    assert np.array_equal(first[0].params, second[0].params) and np.array_equal(first[1].weights, second[1].weights)
    pairs = first[2].pop("preferences"), second[2].pop("preferences")
    assert all(np.array_equal(a, b) for side, again in zip(*pairs) for a, b in zip(side, again))
    assert first[2] == second[2]


def test_the_same_seed_gives_the_same_run_bitwise(pieces):
    model, reward_model, _ = pieces
    config = RLHFConfig(seed=3, beta=0.2, updates=2, sequences=16)
    first, runs = train_rlhf(model, reward_model, config)
    second, again = train_rlhf(model, reward_model, config)
    assert np.array_equal(first.params, second.params) and runs == again
    assert not np.array_equal(
        first.params, train_rlhf(model, reward_model, RLHFConfig(seed=4, beta=0.2, updates=2, sequences=16))[0].params
    )


def test_preference_pairs_share_their_prompt_and_the_reward_model_reads_the_response(rng):
    preferred, rejected = make_preferences(50, rng)
    assert np.array_equal(preferred[0][:, : lm.PROMPT_LEN], rejected[0][:, : lm.PROMPT_LEN])
    assert not np.array_equal(preferred[0], rejected[0])
    model = RewardModel()
    model.weights[lm.TOKEN["the"]], model.weights[lm.TOKEN["good"]] = 5.0, 1.0
    tokens = lm.encode("the film was good .".split())[None, :]
    assert model.score(tokens, np.array([5]))[0] == 1.0  # "the" is in the prompt, so it is not counted


def test_collect_answers_the_prompts_and_charges_the_kl_on_the_response_only(pieces):
    model, reward_model, _ = pieces
    prompts = lm.make_prompts(6, np.random.default_rng(0))
    batch = collect(model, model, reward_model, prompts, 0.3, np.random.default_rng(1), response_len=4)
    assert np.array_equal(batch["tokens"][:, : lm.PROMPT_LEN], prompts)
    assert batch["logp"].shape == (6, 4) and np.all((1 <= batch["lengths"]) & (batch["lengths"] <= 4))
    assert np.allclose(batch["logp"], batch["logp_ref"])  # the policy is its own reference here: no penalty
    assert np.allclose(batch["rewards"].sum(axis=1), batch["scores"])


def test_collect_scores_the_response_only_when_the_prompt_is_longer_than_the_reward_models(pieces):
    model, reward_model, _ = pieces
    assert reward_model.prompt_len == 2
    prompts = lm.make_prompts(40, np.random.default_rng(0), 3)  # DET NOUN VERB: the verb is in the prompt
    batch = collect(model, model, reward_model, prompts, 0.0, np.random.default_rng(1), response_len=2)
    by_hand = [
        reward_model.word_weights(lm.VOCAB[row[1]])[row[3:n]].sum()
        for row, n in zip(batch["tokens"], batch["text_lengths"])
    ]
    assert_close(batch["scores"], by_hand)
    assert np.abs(reward_model.weights[prompts[:, 2]]).max() > 1e-3  # the verbs' weights would have moved the scores


def test_an_unknown_kl_rule_is_an_error():
    with pytest.raises(ValueError, match="kl_rule"):
        RLHFConfig(kl_target=2.0, kl_rule="eq 8")


def test_proportional_beta_moves_by_at_most_the_clipped_error():
    assert proportional_beta(1.0, 2.0, 2.0) == 1.0
    assert np.isclose(proportional_beta(1.0, 100.0, 2.0), 1.02) and np.isclose(proportional_beta(1.0, 0.0, 2.0), 0.98)
    assert np.isclose(proportional_beta(0.5, 2.2, 2.0), 0.5 * (1 + 0.1 * 0.1))


def test_the_minibatch_update_reads_an_rlhf_config_as_it_reads_the_ppo_config_of_the_same_settings(rng):
    """RLHFConfig has every field the update reads (ppo.UpdateSettings), so no PPO Config is made for tokens; and the
    update it drives is the one a Config of the same settings drives, step for step."""
    settings = typing.get_type_hints(UpdateSettings)
    assert settings and set(settings) <= {f.name for f in dataclasses.fields(RLHFConfig)}
    assert set(settings) <= {f.name for f in dataclasses.fields(Config)}
    config = RLHFConfig(objective="clip", clip_epsilon=0.1, value_coef=0.7, max_grad_norm=0.3)
    same = Config(**{name: getattr(config, name) for name in settings})
    model = lm.new_language_model(rng, hidden=8)
    obs = rng.random((40, lm.OBS_DIM))
    out, values, _ = model.forward(obs)
    actions = rng.integers(0, lm.V, 40)
    data = {"obs": obs, "actions": actions, "logp": Categorical(out).log_prob(actions) - 0.3 * rng.random(40)}
    data |= {"values": values, "advantages": rng.normal(size=40), "returns": values + rng.normal(size=40)}
    twins = [model.copy(), model.copy()]
    for agent, settings_used in zip(twins, (config, same)):
        optimizer = Adam(agent.params, lr=1e-2)
        for epoch in epochs_of(data, 2, 16, np.random.default_rng(7)):
            for minibatch in epoch:
                update_minibatch(agent, optimizer, minibatch, settings_used)
    assert not np.array_equal(twins[0].params, model.params)
    assert np.array_equal(twins[0].params, twins[1].params)
