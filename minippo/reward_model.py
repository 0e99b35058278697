"""The preferences, and a reward model learned from them with the Bradley–Terry loss.

The rater here is a rule a reader can check: it scores a sentence by its positive words minus its negative words,
and it puts any sentence that is not well formed (off the grammar, or repeating an adjective) below every one that is.
A pair is two responses to the same prompt (two sentences of the corpus that start with the same subject), and the
rater prefers one with the Bradley–Terry probability P(a ≻ b) = σ(score(a) − score(b)), so its labels are noisy like
a person's.

The reward model scores a response y to a prompt x, linearly in the counts of the response's tokens:
r(x, y) = Σ_w c_w(y) θ_w. Every pair it learns from is well formed, so nothing in its data says that an adjective
said twice is not twice as good: that is its flaw.
"""

from __future__ import annotations

import numpy as np

from minippo.language import (
    NEGATIVE,
    POSITIVE,
    PROMPT_LEN,
    VOCAB,
    V,
    is_well_formed,
    make_corpus,
    sample_prompt,
)
from minippo.optimizer import Adam

ILL_FORMED_SCORE = -(len(NEGATIVE) + 1)  # below the worst well-formed sentence (every negative adjective once)


def rater_score(words) -> float:
    """The rule behind the preferences, on a whole text (prompt and response; a prompt holds no adjective):
    #positive − #negative words if the sentence is well formed, else −6."""
    words = list(words)
    if not is_well_formed(words):
        return float(ILL_FORMED_SCORE)
    return float(sum(w in POSITIVE for w in words) - sum(w in NEGATIVE for w in words))


def token_counts(tokens: np.ndarray, lengths: np.ndarray, start: int = 0) -> np.ndarray:
    """φ: how often each vocabulary entry occurs in each sequence, (n, V), counting the tokens at positions
    ``start`` to ``lengths`` − 1 (with ``start`` the prompt's length, those of the response)."""
    steps = np.arange(tokens.shape[1])[None, :]
    valid = (steps >= start) & (steps < lengths[:, None])
    counts = np.zeros((len(tokens), V))
    np.add.at(counts, (np.nonzero(valid)[0], tokens[valid]), 1.0)
    return counts


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
    """r(x, y) = φ(y) · θ, one weight per token of the vocabulary counted over the response y (the tokens after the
    prompt's ``prompt_len``), fitted by Bradley–Terry with an L2 penalty ½λ|θ|²."""

    def __init__(self, l2: float = 1e-3, prompt_len: int = PROMPT_LEN):
        self.weights = np.zeros(V)
        self.l2 = l2
        self.prompt_len = prompt_len

    def score(self, tokens: np.ndarray, lengths: np.ndarray) -> np.ndarray:
        """The score of each response, given the whole texts (n, T) and their lengths, prompts included."""
        return token_counts(tokens, lengths, self.prompt_len) @ self.weights

    def loss_and_grad(self, counts_preferred: np.ndarray, counts_rejected: np.ndarray):
        """The penalised loss and ∂/∂θ = φ_wᵀ ∂L/∂r_w + φ_lᵀ ∂L/∂r_l + λθ."""
        loss, grad_w, grad_l = bradley_terry_loss(counts_preferred @ self.weights, counts_rejected @ self.weights)
        grad = counts_preferred.T @ grad_w + counts_rejected.T @ grad_l + self.l2 * self.weights
        return loss + 0.5 * self.l2 * float(self.weights @ self.weights), grad

    def fit(self, preferred, rejected, steps: int = 400, lr: float = 0.05) -> list[float]:
        """Full-batch Adam on the pairs (preferred and rejected are (tokens, lengths)); returns the loss per step."""
        counts_w, counts_l = token_counts(*preferred, self.prompt_len), token_counts(*rejected, self.prompt_len)
        optimizer = Adam(self.weights, lr=lr)
        history = []
        for _ in range(steps):
            loss, grad = self.loss_and_grad(counts_w, counts_l)
            optimizer.step(grad)
            history.append(loss)
        return history

    def accuracy(self, preferred, rejected) -> float:
        """The fraction of pairs whose preferred sentence the model scores higher (a tie counts half)."""
        first, second = self.score(*preferred), self.score(*rejected)
        return float(np.mean((first > second) + 0.5 * (first == second)))
