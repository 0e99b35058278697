"""Chapter 9: the KL penalty and its adaptive coefficient β (eq. 8).

The penalised surrogate is L^KLPEN = Ê[r_t Â_t − β KL[π_θold(·|s_t), π_θ(·|s_t)]]; after each policy update,
β is halved if the measured KL d was well below the target and doubled if it was well above.
The KL is taken with the old policy first: KL[π_old ‖ π] = Σ_a π_old(a) (log π_old(a) − log π(a)).

Every array returned is a new float64 array (never an argument itself or a view of one); every value is a float.

Grade: ``minippo grade 9``
"""

from __future__ import annotations

import numpy as np

EXERCISES = ["categorical_kl", "categorical_kl_backward", "kl_penalty_objective", "adaptive_beta"]
TRANSFER = ["reverse_kl_backward"]  # the chapter's idea applied to a case the book has not shown


def log_softmax(logits: np.ndarray) -> np.ndarray:
    """Chapter 2's log-softmax, given: log π_j = z_j − log Σ_i exp z_i for every row, after subtracting the max."""
    shifted = logits - logits.max(axis=-1, keepdims=True)
    return shifted - np.log(np.exp(shifted).sum(axis=-1, keepdims=True))


def categorical_kl(logits_old: np.ndarray, logits: np.ndarray) -> np.ndarray:
    """KL[π_old ‖ π] for every row, the old policy first (the book's (2.1)): ≥ 0, and 0 only where the two agree.

    logits_old, logits: (n, k).  Returns (n,), finite for logits of ±1000.
    """
    log_old, log_new = log_softmax(logits_old), log_softmax(logits)
    return (np.exp(log_old) * (log_old - log_new)).sum(axis=-1)


def categorical_kl_backward(logits_old: np.ndarray, logits: np.ndarray, grad_kl: np.ndarray) -> np.ndarray:
    """∂L/∂z for the new logits z (the old policy is a constant) from ∂L/∂KL, KL as in categorical_kl: derive ∂KL/∂z.

    logits_old, logits: (n, k).  grad_kl: (n,).  Returns (n, k).
    """
    probs_old, probs = np.exp(log_softmax(logits_old)), np.exp(log_softmax(logits))
    return (probs - probs_old) * grad_kl[:, None]


def kl_penalty_objective(logp, logp_old, advantages, kl, beta: float):
    """L^KLPEN, eq. 8's surrogate (the book's (9.1)), to maximise, and its gradients with respect to both variables.

    logp: (n,) the variable of the first term.  logp_old, advantages: (n,) constants.  kl: (n,) KL_t, the variable of
    the penalty (categorical_kl, or the Gaussian one).  beta: β ≥ 0.
    Returns (value, grad_logp, grad_kl): value a float; grad_logp = ∂L/∂ log π_θ(a_t|s_t) and grad_kl = ∂L/∂KL_t,
    both (n,).
    """
    n = len(logp)
    ratio = np.exp(logp - logp_old)
    value = float(np.mean(ratio * advantages)) - beta * float(np.mean(kl))
    return value, ratio * advantages / n, np.full(n, -beta / n)


def adaptive_beta(beta: float, kl: float, kl_target: float) -> float:
    """Eq. 8's rule for β, applied after each policy update with d = Ê[KL] measured on the batch against the target
    d_targ, with the paper's constants 1.5 and 2. At exactly d_targ / 1.5 or d_targ × 1.5, β is unchanged.

    beta: the current β.  kl: d.  kl_target: d_targ.  Returns the new β as a float.
    """
    if kl < kl_target / 1.5:
        return beta / 2.0
    if kl > kl_target * 1.5:
        return beta * 2.0
    return float(beta)


def reverse_kl_backward(logits_old: np.ndarray, logits: np.ndarray, grad_kl: np.ndarray):
    """Transfer task: the other KL, KL[π ‖ π_old] (the new policy first), and its gradient in the new logits.

    logits_old, logits: (n, k).  grad_kl: (n,), ∂L/∂KL_n.
    Returns (kl, grad_logits): kl (n,) = KL[π(·|s_n) ‖ π_old(·|s_n)] per row, ≥ 0, finite for logits of ±1000;
    grad_logits (n, k) = ∂L/∂z for the new logits z (the old policy a constant).
    """

    def log_softmax(z):
        shifted = z - z.max(axis=1, keepdims=True)
        return shifted - np.log(np.exp(shifted).sum(axis=1, keepdims=True))

    log_old, log_new = log_softmax(logits_old), log_softmax(logits)
    probs = np.exp(log_new)
    gap = log_new - log_old
    kl = (probs * gap).sum(axis=1)
    return kl, probs * (gap - kl[:, None]) * grad_kl[:, None]
