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

LOG_2PI = float(np.log(2.0 * np.pi))  # log 2π, in every Gaussian log-density


def log_softmax(logits: np.ndarray) -> np.ndarray:
    """log π_j = z_j − log Σ_i exp z_i for every row of logits z of shape (n, k); returns (n, k).

    Subtract each row's maximum first: the result is the same (log Σ exp shifts by exactly that maximum), but
    exp(z − max z) lies in (0, 1], so nothing overflows, and logits of ±1000 give finite log-probabilities such as
    −2000 rather than −inf or NaN. The other categorical functions can build on it.
    """
    shifted = logits - logits.max(axis=-1, keepdims=True)
    return shifted - np.log(np.exp(shifted).sum(axis=-1, keepdims=True))


def categorical_log_prob(logits: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """log π(a_n|s_n) = z_{n,a_n} − log Σ_j exp z_{n,j}.

    logits: (n, k) floats.  actions: (n,) integers in 0..k−1.  Returns (n,) floats, finite even when a logit is
    ±1000 (an action that is almost never taken has a very negative log-probability, not −inf or NaN).
    """
    return np.take_along_axis(log_softmax(logits), actions.astype(np.int64)[:, None], axis=-1)[:, 0]


def categorical_log_prob_backward(logits: np.ndarray, actions: np.ndarray, grad_logp: np.ndarray) -> np.ndarray:
    """∂L/∂z from ∂L/∂ log π: ∂ log π(a|s)/∂z_j = 1[j = a] − π_j.

    logits: (n, k).  actions: (n,) integers.  grad_logp: (n,), ∂L/∂ log π(a_n|s_n).
    Returns (n, k): row n is grad_logp_n · (onehot(a_n) − π(·|s_n)).
    """
    probs = np.exp(log_softmax(logits))
    grad = -probs * grad_logp[:, None]
    grad[np.arange(len(actions)), actions.astype(np.int64)] += grad_logp
    return grad


def categorical_entropy(logits: np.ndarray) -> np.ndarray:
    """S = −Σ_j π_j log π_j for every row.

    logits: (n, k).  Returns (n,), between 0 (one certain action) and log k (uniform). A probability that rounds
    to 0 contributes 0 (p log p → 0), never NaN.
    """
    log_probs = log_softmax(logits)
    return -(np.exp(log_probs) * log_probs).sum(axis=-1)


def categorical_entropy_backward(logits: np.ndarray, grad_entropy: np.ndarray) -> np.ndarray:
    """∂L/∂z from ∂L/∂S: ∂S/∂z_j = −π_j (log π_j + S).

    logits: (n, k).  grad_entropy: (n,), ∂L/∂S_n.  Returns (n, k).
    """
    log_probs = log_softmax(logits)
    probs = np.exp(log_probs)
    entropy = -(probs * log_probs).sum(axis=-1)
    return -probs * (log_probs + entropy[:, None]) * grad_entropy[:, None]


def gaussian_log_prob(mean: np.ndarray, log_std: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """log π(a|s) = Σ_i [ −½ ((a_i − μ_i)/σ_i)² − log σ_i − ½ log 2π ],  σ_i = exp(log σ_i).

    mean: (n, d).  log_std: (d,), shared by every row.  actions: (n, d).  Returns (n,).
    """
    z = (actions - mean) / np.exp(log_std)
    return -0.5 * (z * z).sum(axis=-1) - log_std.sum() - 0.5 * mean.shape[-1] * LOG_2PI


def gaussian_log_prob_backward(mean: np.ndarray, log_std: np.ndarray, actions: np.ndarray, grad_logp: np.ndarray):
    """∂L/∂μ and ∂L/∂ log σ from ∂L/∂ log π.

        ∂ log π/∂μ_i     = (a_i − μ_i) / σ_i²
        ∂ log π/∂ log σ_i = ((a_i − μ_i)/σ_i)² − 1
    grad_logp: (n,).  Returns (grad_mean of shape (n, d), grad_log_std of shape (d,)). log σ is one vector shared by
    all n rows, so its gradient is the sum over the batch of each row's contribution.
    """
    std = np.exp(log_std)
    z = (actions - mean) / std
    grad_mean = (z / std) * grad_logp[:, None]
    grad_log_std = ((z * z - 1.0) * grad_logp[:, None]).sum(axis=0)
    return grad_mean, grad_log_std


def gaussian_entropy(mean: np.ndarray, log_std: np.ndarray) -> np.ndarray:
    """S = Σ_i (log σ_i + ½ log 2πe), the same for every state.

    mean: (n, d), used only for n.  log_std: (d,).  Returns (n,), every entry equal.
    """
    value = log_std.sum() + 0.5 * mean.shape[-1] * (LOG_2PI + 1.0)
    return np.full(mean.shape[0], float(value))


def gaussian_entropy_backward(mean: np.ndarray, log_std: np.ndarray, grad_entropy: np.ndarray):
    """∂L/∂μ and ∂L/∂ log σ from ∂L/∂S: ∂S/∂μ = 0 and ∂S/∂ log σ_i = 1.

    grad_entropy: (n,).  Returns (grad_mean of shape (n, d), all zeros, and grad_log_std of shape (d,)), the latter
    summed over the batch like gaussian_log_prob_backward's.
    """
    return np.zeros_like(mean, dtype=np.float64), np.full(log_std.shape, float(np.sum(grad_entropy)))
