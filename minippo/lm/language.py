"""A language model in miniature: a grammar that writes the corpus, the vocabulary, and the policy that reads a
prefix and gives a categorical over the next token, pretrained by maximum likelihood.

The corpus is short sentences of the form ``the film was very good and new .``: a determiner, a noun, a verb, then
one to three adjectives joined by "and" or "but", each perhaps after "very", all different, then the full stop. The
language model is minippo's ActorCritic with a discrete head: its "observation" is a fixed description of the prefix
(the last ``WINDOW`` tokens one-hot, the count of every token so far, and the position), its "action" the next token.
Its value network is not used until the RL fine-tuning (minippo.lm.rlhf).

A prompt is the start of a sentence, its subject (``the film``); a response is what follows it (``was very good .``).
Pretraining reads whole sentences; the fine-tuning gives the policy a prompt and lets it write the response.
"""

from __future__ import annotations

import numpy as np

from minippo.agent import ActorCritic, AgentSpec
from minippo.distributions import Categorical
from minippo.minibatches import epochs_of
from minippo.optimizer import Adam

DETERMINERS = ("the", "a", "my")
NOUNS = ("cat", "dog", "film", "song", "meal", "day")
VERBS = ("is", "was", "seems", "felt")
POSITIVE = ("good", "great", "happy", "lovely", "fine")
NEGATIVE = ("bad", "sad", "awful", "dull", "poor")
NEUTRAL = ("big", "small", "old", "new", "long")
ADJECTIVES = POSITIVE + NEGATIVE + NEUTRAL
BOS, EOS = "<s>", "."
VOCAB = (BOS, EOS, *DETERMINERS, *NOUNS, *VERBS, "very", "and", "but", *ADJECTIVES)
TOKEN = {word: i for i, word in enumerate(VOCAB)}
V = len(VOCAB)
WINDOW = 3  # the policy sees the last three tokens one-hot (and the counts of all the earlier ones)
MAX_LEN = 16  # tokens generated at most; the grammar's longest sentence has 12
OBS_DIM = WINDOW * V + V + MAX_LEN
PROMPT_LEN = 2  # a prompt is the subject, DET NOUN


def sample_prompt(rng: np.random.Generator, length: int = PROMPT_LEN) -> list[str]:
    """The first ``length`` words (1 to 3) of a sentence of the grammar: DET, then NOUN, then VERB."""
    return [str(rng.choice(words)) for words in (DETERMINERS, NOUNS, VERBS)[:length]]


def make_prompts(n: int, rng: np.random.Generator, length: int = PROMPT_LEN) -> np.ndarray:
    """``n`` prompts of ``length`` words as a (n, length) token array."""
    return np.array([encode(sample_prompt(rng, length)) for _ in range(n)], dtype=np.int64).reshape(n, length)


def sample_sentence(rng: np.random.Generator, prompt: list[str] | None = None) -> list[str]:
    """One sentence of the grammar: DET NOUN VERB ADJP ((and | but) ADJP){0,2} . with ADJP = [very] ADJ, the
    adjectives all different; if ``prompt`` (from sample_prompt) is given, the sentence continues it."""
    if prompt is None:
        words = [rng.choice(DETERMINERS), rng.choice(NOUNS), rng.choice(VERBS)]
    else:
        words = list(prompt) + [rng.choice(choices) for choices in (DETERMINERS, NOUNS, VERBS)[len(prompt) :]]
    count = 1 + rng.choice(3, p=[0.4, 0.4, 0.2])
    for i, adjective in enumerate(rng.choice(ADJECTIVES, size=count, replace=False)):
        if i:
            words.append(rng.choice(("and", "but")))
        if rng.random() < 0.3:
            words.append("very")
        words.append(adjective)
    return [str(w) for w in words] + [EOS]


def is_well_formed(words) -> bool:
    """Whether ``words`` is a sentence of the grammar above, allowing any number of adjectives (all different)."""
    words = list(words)
    if len(words) < 5 or words[-1] != EOS or EOS in words[:-1]:
        return False
    if words[0] not in DETERMINERS or words[1] not in NOUNS or words[2] not in VERBS:
        return False
    rest, seen, i = words[3:-1], [], 0
    while True:
        if i < len(rest) and rest[i] == "very":
            i += 1
        if i >= len(rest) or rest[i] not in ADJECTIVES or rest[i] in seen:
            return False
        seen.append(rest[i])
        i += 1
        if i == len(rest):
            return True
        if rest[i] not in ("and", "but"):
            return False
        i += 1


def encode(words) -> np.ndarray:
    return np.array([TOKEN[w] for w in words], dtype=np.int64)


def decode(tokens, length: int | None = None) -> str:
    return " ".join(VOCAB[t] for t in list(tokens)[:length])


def make_corpus(n: int, rng: np.random.Generator, prompts=None) -> tuple[np.ndarray, np.ndarray]:
    """``n`` sentences as a (n, MAX_LEN) token array (padded with BOS after the full stop) and their lengths; with
    ``prompts`` (a list of n word lists), sentence i continues prompt i."""
    tokens = np.full((n, MAX_LEN), TOKEN[BOS], dtype=np.int64)
    lengths = np.zeros(n, dtype=np.int64)
    for i in range(n):
        sentence = encode(sample_sentence(rng, None if prompts is None else prompts[i]))
        tokens[i, : len(sentence)] = sentence
        lengths[i] = len(sentence)
    return tokens, lengths


def prefix_features(tokens: np.ndarray, t: int) -> np.ndarray:
    """The state s_t for predicting token t of every row of ``tokens`` (n, ≥ t): the last WINDOW tokens one-hot
    (BOS before the start), the count of each token among the first t, and t one-hot."""
    n = len(tokens)
    obs = np.zeros((n, OBS_DIM))
    rows = np.arange(n)
    for k in range(WINDOW):  # slot k holds token t − 1 − k
        previous = tokens[:, t - 1 - k] if t - 1 - k >= 0 else np.full(n, TOKEN[BOS])
        obs[rows, k * V + previous] = 1.0
    if t:
        np.add.at(obs, (np.repeat(rows, t), WINDOW * V + tokens[:, :t].reshape(-1)), 1.0)
    obs[:, WINDOW * V + V + t] = 1.0
    return obs


def sequence_features(tokens: np.ndarray) -> np.ndarray:
    """The states s_0 … s_{T−1} of every row, as an array (n, T, OBS_DIM)."""
    return np.stack([prefix_features(tokens, t) for t in range(tokens.shape[1])], axis=1)


def new_language_model(rng: np.random.Generator, hidden: int = 64) -> ActorCritic:
    """An untrained policy over the vocabulary (one tanh layer of ``hidden`` units), with its value network."""
    return ActorCritic(AgentSpec(OBS_DIM, "discrete", V, (hidden,), dtype="float64"), rng)


def nll_and_grad(model: ActorCritic, obs: np.ndarray, targets: np.ndarray) -> float:
    """The mean negative log-likelihood −Ê[log π(y_t | s_t)] of the next tokens, its gradient written into the
    policy network's part of ``model.grads`` (∂(−log π_y)/∂z_j = π_j − 1[j = y], from Categorical.log_prob_backward)."""
    n = len(targets)
    logits, cache = model.nets["policy"].forward(obs)
    dist = Categorical(logits)
    loss = -float(dist.log_prob(targets).sum()) / n
    (grad_logits,) = dist.log_prob_backward(targets, np.full(n, -1.0 / n))
    model.nets["policy"].backward(cache, grad_logits)
    return loss


def pretrain(
    model: ActorCritic,
    tokens: np.ndarray,
    lengths: np.ndarray,
    rng: np.random.Generator,
    epochs: int = 6,
    batch_size: int = 128,
    lr: float = 3e-3,
) -> list[float]:
    """Maximum likelihood on the corpus: Adam on −log π(y_t | s_t) over every token of every sentence (the full stop
    included, so the model learns to end). Returns the mean loss of each epoch."""
    features = sequence_features(tokens)
    valid = np.arange(tokens.shape[1])[None, :] < lengths[:, None]
    obs, targets = features[valid], tokens[valid]
    policy = model.nets["policy"]
    optimizer = Adam(policy.params, lr=lr)
    history = []
    for epoch in epochs_of(len(targets), epochs, batch_size, rng):
        losses = []
        for batch in epoch:
            losses.append(nll_and_grad(model, obs[batch], targets[batch]))
            optimizer.step(policy.grads)
        history.append(float(np.mean(losses)))
    return history


def generate(model: ActorCritic, n: int, rng: np.random.Generator, greedy: bool = False, prompts=None):
    """Sample ``n`` sequences token by token, each continuing its row of ``prompts`` (n, P) if given. Returns
    (tokens (n, MAX_LEN), lengths), prompts included: a sequence ends with its first full stop, or after MAX_LEN tokens
    without one; the tokens after the end are BOS."""
    tokens = np.full((n, MAX_LEN), TOKEN[BOS], dtype=np.int64)
    lengths = np.full(n, MAX_LEN, dtype=np.int64)
    done = np.zeros(n, dtype=bool)
    start = 0 if prompts is None else prompts.shape[1]
    if start:
        tokens[:, :start] = prompts
    for t in range(start, MAX_LEN):
        dist = Categorical(model.policy_output(prefix_features(tokens, t)))
        action = dist.mode() if greedy else dist.sample(rng)
        tokens[:, t] = np.where(done, TOKEN[BOS], action)
        ended = ~done & (action == TOKEN[EOS])
        lengths[ended] = t + 1
        done |= ended
    return tokens, lengths
