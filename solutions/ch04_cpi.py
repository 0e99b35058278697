"""Chapter 4: the importance ratio and the conservative policy iteration surrogate L^CPI.

The samples come from the snapshot π_θold that collected them, and we improve π_θ on them for several epochs; the
ratio r_t(θ) = π_θ(a_t|s_t) / π_θold(a_t|s_t) reweights each sample to the policy being optimised.

Every array returned is a new float64 array (never an argument itself or a view of one); every value is a float.

Grade: ``minippo grade 4``
"""

from __future__ import annotations

import numpy as np

EXERCISES = ["importance_ratio", "cpi_objective"]
TRANSFER = ["weighted_cpi_objective"]  # the chapter's idea applied to a case the book has not shown


def importance_ratio(logp: np.ndarray, logp_old: np.ndarray) -> np.ndarray:
    """r_t = π_θ(a_t|s_t) / π_θold(a_t|s_t), the book's (4.2), from the two log-probabilities.

    logp, logp_old: (n,).  Returns (n,), finite and correct even when both log-probabilities are very negative
    (−800 and −801 give e, although exp(−800) underflows to 0).
    """
    return np.exp(logp - logp_old)


def cpi_objective(logp: np.ndarray, logp_old: np.ndarray, advantages: np.ndarray):
    """L^CPI, the paper's eq. 6 (the book's (4.3)), the mean over the batch, and its gradient.

    logp: (n,) log π_θ, the variable.  logp_old: (n,) log π_θold, a constant.  advantages: (n,) constants.
    Returns (value, grad): value a float; grad = ∂L^CPI/∂ log π_θ(a_t|s_t), shape (n,). At θ = θ_old it must equal
    the gradient of L^PG.
    """
    n = len(logp)
    ratio = importance_ratio(logp, logp_old)
    return float(np.mean(ratio * advantages)), ratio * advantages / n


def weighted_cpi_objective(logp: np.ndarray, logp_old: np.ndarray, advantages: np.ndarray):
    """Transfer task: the importance-weighted surrogate with *self-normalised* weights, and its gradient.

    The value: Σ_t r_t Â_t / Σ_t r_t, the ratios r_t of chapter 4 normalised to sum to one over the batch (weighted
    importance sampling: a biased estimate with a smaller variance than L^CPI's mean). Every r_t enters the
    denominator too.
    logp: (n,) the variable.  logp_old, advantages: (n,) constants.
    Returns (value, grad): value a float, finite for log-probabilities near −800; grad = ∂value/∂ log π_θ(a_t|s_t),
    shape (n,).
    """
    log_ratio = logp - logp_old
    weights = np.exp(log_ratio - log_ratio.max())
    weights = weights / weights.sum()  # r_t / Σ r: the common factor cancels
    value = float(np.sum(weights * advantages))
    return value, weights * (advantages - value)
