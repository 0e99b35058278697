"""The preferences, and a reward model learned from them with the Bradley–Terry loss.

The rater here is a rule a reader can check: it scores a sentence by its positive words minus its negative words,
plus its taste for the subject (TASTES: a small cat and a big dog are good, a small dog and a big cat are not), and it
puts any sentence that is not well formed (off the grammar, or repeating an adjective) below every one that is. A pair
is two responses to the same prompt (two sentences of the corpus that start with the same subject), and the rater
prefers one with the Bradley–Terry probability P(a ≻ b) = σ(score(a) − score(b)), so its labels are noisy like a
person's.

The reward model scores a response y to a prompt x, linearly in the counts of the response's tokens, with one weight
per word and one per (subject, word): r(x, y) = Σ_w c_w(y) (θ_w + Θ_{n(x), w}), n(x) the noun of the prompt. Every
pair it learns from is well formed, so nothing in its data says that an adjective said twice is not twice as good:
that is its flaw.
"""

from __future__ import annotations

import numpy as np

from minippo.lm.language import (
    NEGATIVE,
    NOUNS,
    POSITIVE,
    PROMPT_LEN,
    TOKEN,
    VOCAB,
    V,
    is_well_formed,
    make_corpus,
    sample_prompt,
)
from minippo.optimizer import Adam

# What the rater thinks of a neutral adjective depends on the subject: +1 or −1 for each (noun, word) listed
TASTES = {
    "cat": {"small": 1.0, "big": -1.0},
    "dog": {"big": 1.0, "small": -1.0},
    "film": {"new": 1.0, "old": -1.0},
    "song": {"old": 1.0, "new": -1.0},
    "meal": {"long": 1.0},
    "day": {"long": -1.0},
}
# below the worst well-formed sentence (every negative adjective once, and a neutral one the subject dislikes)
ILL_FORMED_SCORE = -(len(NEGATIVE) + 2)


def rater_score(words) -> float:
    """The rule behind the preferences, on a whole text (prompt and response; a prompt holds no adjective): if the
    sentence is well formed, #positive − #negative words plus the subject's taste (TASTES) for each of its words,
    else ILL_FORMED_SCORE (−7)."""
    words = list(words)
    if not is_well_formed(words):
        return float(ILL_FORMED_SCORE)
    taste = TASTES[words[1]]  # a well-formed sentence's second word is its noun
    return float(sum((w in POSITIVE) - (w in NEGATIVE) + taste.get(w, 0.0) for w in words))


def token_counts(tokens: np.ndarray, lengths: np.ndarray, start: int = 0) -> np.ndarray:
    """φ: how often each vocabulary entry occurs in each sequence, (n, V), counting the tokens at positions
    ``start`` to ``lengths`` − 1 (with ``start`` the prompt's length, those of the response)."""
    steps = np.arange(tokens.shape[1])[None, :]
    valid = (steps >= start) & (steps < lengths[:, None])
    counts = np.zeros((len(tokens), V))
    np.add.at(counts, (np.nonzero(valid)[0], tokens[valid]), 1.0)
    return counts


def subjects(tokens: np.ndarray, prompt_len: int) -> np.ndarray:
    """e_n(x): which noun each text's prompt (its first ``prompt_len`` tokens) names, one-hot, (n, len(NOUNS)); a row
    of zeros where the prompt holds no noun."""
    nouns = np.array([TOKEN[w] for w in NOUNS])
    return (tokens[:, :prompt_len, None] == nouns).any(axis=1).astype(float)


def make_preferences(n_pairs: int, rng: np.random.Generator, prompt_len: int = PROMPT_LEN):
    """Pairs of corpus sentences that share their first ``prompt_len`` words (the prompt), with the rater's noisy
    choice: (preferred, rejected), each (tokens, lengths) of whole texts, prompt included."""
    prompts = [sample_prompt(rng, prompt_len) for _ in range(n_pairs)]
    first, second = make_corpus(n_pairs, rng, prompts), make_corpus(n_pairs, rng, prompts)
    scores = [np.array([rater_score(VOCAB[t] for t in row[:n]) for row, n in zip(*half)]) for half in (first, second)]
    first_wins = rng.random(n_pairs) < 1.0 / (1.0 + np.exp(-(scores[0] - scores[1])))
    pick = first_wins[:, None]
    preferred = (np.where(pick, first[0], second[0]), np.where(first_wins, first[1], second[1]))
    rejected = (np.where(pick, second[0], first[0]), np.where(first_wins, second[1], first[1]))
    return preferred, rejected


def bradley_terry_loss(scores_preferred: np.ndarray, scores_rejected: np.ndarray):
    """L = −Ê[log σ(r_w − r_l)], the negative log-likelihood of the preferences under Bradley–Terry, with
    log σ(Δ) = −log(1 + e^{−Δ}) computed as −logaddexp(0, −Δ) so that it stays finite for any Δ.

    Returns (L, ∂L/∂r_w, ∂L/∂r_l): ∂L/∂r_w = −σ(−Δ)/n = −(1 − P(w ≻ l))/n, and ∂L/∂r_l = +σ(−Δ)/n.
    """
    n = len(scores_preferred)
    margin = scores_preferred - scores_rejected
    loss = float(np.logaddexp(0.0, -margin).sum()) / n
    wrong = np.exp(-np.logaddexp(0.0, margin))  # σ(−Δ), the probability the model gives the other answer
    return loss, -wrong / n, wrong / n


class RewardModel:
    """r(x, y) = φ(x, y) · θ with φ(x, y) = [c(y), e_n(x) ⊗ c(y)]: one weight per token of the vocabulary counted over
    the response y (the tokens after the prompt's ``prompt_len``), and one per (the prompt's noun, token), so that a
    word can be good for one subject and bad for another. Fitted by Bradley–Terry with an L2 penalty ½λ|θ|²."""

    def __init__(self, l2: float = 1e-3, prompt_len: int = PROMPT_LEN, by_subject: bool = True):
        self.weights = np.zeros(V + len(NOUNS) * V if by_subject else V)
        self.l2 = l2
        self.prompt_len = prompt_len
        self.by_subject = by_subject  # False: φ = c(y) alone, a model blind to the prompt (for comparison)

    def features(self, tokens: np.ndarray, lengths: np.ndarray, prompt_len: int | None = None) -> np.ndarray:
        """φ(x, y) of whole texts (n, T), prompts included, and their lengths: (n, V + len(NOUNS) V), or (n, V). The
        prompt is the first ``prompt_len`` tokens (by default the model's own), and only the tokens after it count."""
        prompt_len = self.prompt_len if prompt_len is None else prompt_len
        counts = token_counts(tokens, lengths, prompt_len)
        if not self.by_subject:
            return counts
        by_subject = subjects(tokens, prompt_len)[:, :, None] * counts[:, None, :]
        return np.concatenate([counts, by_subject.reshape(len(tokens), -1)], axis=1)

    def word_weights(self, noun: str) -> np.ndarray:
        """θ_w + Θ_{noun, w} for every token w: what one more w in a response adds to the score, for this subject."""
        if not self.by_subject:
            return self.weights.copy()
        return self.weights[:V] + self.weights[V:].reshape(len(NOUNS), V)[NOUNS.index(noun)]

    def score(self, tokens: np.ndarray, lengths: np.ndarray, prompt_len: int | None = None) -> np.ndarray:
        """The score of each response, given the whole texts (n, T) and their lengths, prompts included, and the
        prompt's length if it is not the model's own (a longer prompt's last words are not part of the response)."""
        return self.features(tokens, lengths, prompt_len) @ self.weights

    def loss_and_grad(self, features_preferred: np.ndarray, features_rejected: np.ndarray):
        """The penalised loss and ∂/∂θ = φ_wᵀ ∂L/∂r_w + φ_lᵀ ∂L/∂r_l + λθ (r is linear in θ: ∂r/∂θ = φ)."""
        loss, grad_w, grad_l = bradley_terry_loss(features_preferred @ self.weights, features_rejected @ self.weights)
        grad = features_preferred.T @ grad_w + features_rejected.T @ grad_l + self.l2 * self.weights
        return loss + 0.5 * self.l2 * float(self.weights @ self.weights), grad

    def fit(self, preferred, rejected, steps: int = 400, lr: float = 0.05) -> list[float]:
        """Full-batch Adam on the pairs (preferred and rejected are (tokens, lengths)); returns the loss per step."""
        features_w, features_l = self.features(*preferred), self.features(*rejected)
        optimizer = Adam(self.weights, lr=lr)
        history = []
        for _ in range(steps):
            loss, grad = self.loss_and_grad(features_w, features_l)
            optimizer.step(grad)
            history.append(loss)
        return history

    def accuracy(self, preferred, rejected) -> float:
        """The fraction of pairs whose preferred sentence the model scores higher (a tie counts half)."""
        first, second = self.score(*preferred), self.score(*rejected)
        return float(np.mean((first > second) + 0.5 * (first == second)))
