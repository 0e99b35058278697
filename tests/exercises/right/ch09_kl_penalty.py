"""Other correct ways to write chapter 9."""

import numpy as np


def adaptive_beta_other_order(beta, kl, kl_target):
    """Eq. 8's rule with the doubling tested first."""
    if kl > 1.5 * kl_target:
        return 2.0 * beta
    if kl < kl_target / 1.5:
        return 0.5 * beta
    return float(beta)


def categorical_kl_logsumexp(logits_old, logits):
    """KL from log-probabilities made with a log-sum-exp."""

    def log_probs(z):
        top = z.max(axis=-1, keepdims=True)
        return z - top - np.log(np.exp(z - top).sum(axis=-1, keepdims=True))

    old, new = log_probs(logits_old), log_probs(logits)
    return np.einsum("nk,nk->n", np.exp(old), old - new)


VARIANTS = {
    "adaptive_beta_other_order": {"adaptive_beta": adaptive_beta_other_order},
    "categorical_kl_logsumexp": {"categorical_kl": categorical_kl_logsumexp},
}


def reverse_kl_by_jacobian(logits_old, logits, grad_kl):
    """The softmax's Jacobian applied to ∂KL/∂π_j = log π_j − log π_old,j + 1, row by row."""
    n, k = logits.shape
    kl, grad = np.zeros(n), np.zeros((n, k))
    for i in range(n):
        log_new = logits[i] - np.logaddexp.reduce(logits[i])
        log_old = logits_old[i] - np.logaddexp.reduce(logits_old[i])
        probs = np.exp(log_new)
        kl[i] = probs @ (log_new - log_old)
        jacobian = np.diag(probs) - np.outer(probs, probs)
        grad[i] = jacobian @ (log_new - log_old + 1.0) * grad_kl[i]
    return kl, grad


VARIANTS["reverse_kl_by_jacobian"] = {"reverse_kl_backward": reverse_kl_by_jacobian}
