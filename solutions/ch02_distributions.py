"""Chapter 2: the two policy distributions, their log-probabilities and entropies, and the gradients of both.

Categorical (discrete actions): π(a|s) = softmax(z)_a for logits z of shape (n, k), one row per state.
Diagonal Gaussian (continuous actions): π(a|s) = N(a; μ(s), diag σ²) with a mean of shape (n, d) per state and one
log standard deviation vector log σ of shape (d,) shared by all states.
Every ``*_backward`` takes the upstream gradient ∂L/∂(quantity), one number per sample, and returns ∂L/∂(parameters).
All arrays are float64 except actions of a categorical, which are integers.

Every array returned is a new float64 array (never an argument itself or a view of one); every value is a float.

Grade: ``minippo grade 2``
"""

from __future__ import annotations

import numpy as np

EXERCISES = [
    "log_softmax",
    "categorical_log_prob",
    "categorical_log_prob_backward",
    "categorical_entropy",
    "categorical_entropy_backward",
    "gaussian_log_prob",
    "gaussian_log_prob_backward",
    "gaussian_entropy",
    "gaussian_entropy_backward",
]
TRANSFER = ["tempered_categorical_log_prob"]  # the chapter's idea applied to a case the book has not shown

LOG_2PI = float(np.log(2.0 * np.pi))  # log 2π, in every Gaussian log-density


def log_softmax(logits: np.ndarray) -> np.ndarray:
    """log π_j = log softmax(z)_j for every row of logits z of shape (n, k); returns (n, k).

    It must stay finite for logits of ±1000 (log-probabilities such as −2000, never −inf or NaN): find a way to
    compute it in which nothing overflows. The other categorical functions can build on it.
    """
    shifted = logits - logits.max(axis=-1, keepdims=True)
    return shifted - np.log(np.exp(shifted).sum(axis=-1, keepdims=True))


def categorical_log_prob(logits: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """log π(a_n|s_n) of the categorical (2.1), the log-probability of each row's action.

    logits: (n, k) floats, k actions.  actions: (n,) integers in 0..k−1.  Returns (n,) floats, finite even when a logit
    is ±1000 (an action that is almost never taken has a very negative log-probability, not −inf or NaN).
    """
    return np.take_along_axis(log_softmax(logits), actions.astype(np.int64)[:, None], axis=-1)[:, 0]


def categorical_log_prob_backward(logits: np.ndarray, actions: np.ndarray, grad_logp: np.ndarray) -> np.ndarray:
    """∂L/∂z from ∂L/∂ log π: the categorical's score (2.4), times the upstream gradient.

    logits: (n, k).  actions: (n,) integers.  grad_logp: (n,), ∂L/∂ log π(a_n|s_n).  Returns ∂L/∂z, (n, k).
    """
    probs = np.exp(log_softmax(logits))
    grad = -probs * grad_logp[:, None]
    grad[np.arange(len(actions)), actions.astype(np.int64)] += grad_logp
    return grad


def categorical_entropy(logits: np.ndarray) -> np.ndarray:
    """The entropy S[π(·|s_n)] of every row's categorical, in nats.

    logits: (n, k).  Returns (n,), between 0 (one certain action) and log k (uniform). A probability that rounds
    to 0 contributes 0, never NaN.
    """
    log_probs = log_softmax(logits)
    return -(np.exp(log_probs) * log_probs).sum(axis=-1)


def categorical_entropy_backward(logits: np.ndarray, grad_entropy: np.ndarray) -> np.ndarray:
    """∂L/∂z from ∂L/∂S, S the entropy of categorical_entropy: derive ∂S/∂z yourself.

    logits: (n, k).  grad_entropy: (n,), ∂L/∂S_n.  Returns (n, k).
    """
    log_probs = log_softmax(logits)
    probs = np.exp(log_probs)
    entropy = -(probs * log_probs).sum(axis=-1)
    return -probs * (log_probs + entropy[:, None]) * grad_entropy[:, None]


def gaussian_log_prob(mean: np.ndarray, log_std: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """log π(a|s) of the diagonal Gaussian (2.2) with mean μ(s) and standard deviations σ = exp(log σ).

    mean: (n, d), d the action's dimensions.  log_std: (d,), shared by every row.  actions: (n, d).  Returns (n,).
    """
    z = (actions - mean) / np.exp(log_std)
    return -0.5 * (z * z).sum(axis=-1) - log_std.sum() - 0.5 * mean.shape[-1] * LOG_2PI


def gaussian_log_prob_backward(mean: np.ndarray, log_std: np.ndarray, actions: np.ndarray, grad_logp: np.ndarray):
    """∂L/∂μ and ∂L/∂ log σ from ∂L/∂ log π, the Gaussian's scores (2.5) and (2.6) times the upstream gradient.

    mean: (n, d).  log_std: (d,).  actions: (n, d).  grad_logp: (n,).  Returns (grad_mean of shape (n, d),
    grad_log_std of shape (d,)). log σ is one vector shared by all n rows.
    """
    std = np.exp(log_std)
    z = (actions - mean) / std
    grad_mean = (z / std) * grad_logp[:, None]
    grad_log_std = ((z * z - 1.0) * grad_logp[:, None]).sum(axis=0)
    return grad_mean, grad_log_std


def gaussian_entropy(mean: np.ndarray, log_std: np.ndarray) -> np.ndarray:
    """The entropy of the diagonal Gaussian (2.2), in nats, the same for every state: derive it from the density.

    mean: (n, d), used only for n and d.  log_std: (d,).  Returns (n,), every entry equal.
    """
    value = log_std.sum() + 0.5 * mean.shape[-1] * (LOG_2PI + 1.0)
    return np.full(mean.shape[0], float(value))


def gaussian_entropy_backward(mean: np.ndarray, log_std: np.ndarray, grad_entropy: np.ndarray):
    """∂L/∂μ and ∂L/∂ log σ from ∂L/∂S, S the entropy of gaussian_entropy.

    mean: (n, d).  log_std: (d,).  grad_entropy: (n,).  Returns (grad_mean of shape (n, d), grad_log_std of shape (d,)),
    log σ shared by all rows as in gaussian_log_prob_backward.
    """
    return np.zeros_like(mean, dtype=np.float64), np.full(log_std.shape, float(np.sum(grad_entropy)))


def tempered_categorical_log_prob(logits: np.ndarray, temperature: float, actions: np.ndarray):
    """Transfer task: a categorical policy with a temperature τ, π = softmax(z / τ), and its score.

    logits: (n, k).  temperature: τ > 0, one number shared by every row.  actions: (n,) integers in 0..k−1.
    Returns (logp, grad_logits, grad_temperature): logp (n,) the log-probability of each row's action;
    grad_logits (n, k) = ∂ log π(a_n|s_n)/∂z_n; grad_temperature (n,) = ∂ log π(a_n|s_n)/∂τ, one per row (not summed).
    Finite for logits of ±1000 with τ ≥ 0.5. τ = 1 is chapter 2's categorical.
    """
    scaled = logits / temperature
    shifted = scaled - scaled.max(axis=1, keepdims=True)
    log_probs = shifted - np.log(np.exp(shifted).sum(axis=1, keepdims=True))
    probs = np.exp(log_probs)
    rows = np.arange(len(actions))
    actions = actions.astype(np.int64)
    grad_scaled = -probs
    grad_scaled[rows, actions] += 1.0
    # log π depends on τ only through z / τ, whose derivative in τ is −z / τ²
    grad_temperature = (grad_scaled * logits).sum(axis=1) * (-1.0 / temperature**2)
    return log_probs[rows, actions], grad_scaled / temperature, grad_temperature
