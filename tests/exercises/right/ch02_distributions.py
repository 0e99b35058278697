"""Other correct ways to write chapter 2."""

import numpy as np


def _logsumexp(z):
    top = z.max(axis=-1)
    return top + np.log(np.exp(z - top[:, None]).sum(axis=-1))


def log_softmax_logsumexp(logits):
    """z − logsumexp(z), the max added back outside the log."""
    return logits - _logsumexp(logits)[:, None]


def categorical_log_prob_indexed(logits, actions):
    """z_a − logsumexp(z) with fancy indexing."""
    return logits[np.arange(len(actions)), actions] - _logsumexp(logits)


def categorical_log_prob_backward_onehot(logits, actions, grad_logp):
    """(onehot − π) built from an identity matrix."""
    probs = np.exp(logits - _logsumexp(logits)[:, None])
    onehot = np.eye(logits.shape[1])[actions]
    return (onehot - probs) * grad_logp[:, None]


def categorical_entropy_where(logits):
    """−Σ π log π with the terms where π underflows to 0 set to 0 explicitly."""
    log_probs = logits - _logsumexp(logits)[:, None]
    probs = np.exp(log_probs)
    return -np.where(probs > 0, probs * log_probs, 0.0).sum(axis=-1)


def gaussian_log_prob_by_dimension(mean, log_std, actions):
    """One dimension at a time."""
    total = np.zeros(mean.shape[0])
    for i in range(mean.shape[1]):
        z = (actions[:, i] - mean[:, i]) / np.exp(log_std[i])
        total += -0.5 * z * z - log_std[i] - 0.5 * np.log(2 * np.pi)
    return total


VARIANTS = {
    "log_softmax_logsumexp": {"log_softmax": log_softmax_logsumexp},
    "categorical_log_prob_indexed": {"categorical_log_prob": categorical_log_prob_indexed},
    "categorical_log_prob_backward_onehot": {"categorical_log_prob_backward": categorical_log_prob_backward_onehot},
    "categorical_entropy_where": {"categorical_entropy": categorical_entropy_where},
    "gaussian_log_prob_by_dimension": {"gaussian_log_prob": gaussian_log_prob_by_dimension},
}


def tempered_by_rescaled_logits(logits, temperature, actions):
    """Chapter 2's log-softmax on z/τ, and ∂/∂τ written as −(z_a − E_π[z])/τ² with the expectation taken explicitly."""
    scaled = logits / temperature
    log_probs = scaled - np.logaddexp.reduce(scaled, axis=1, keepdims=True)
    probs = np.exp(log_probs)
    rows = np.arange(len(actions))
    onehot = np.zeros(logits.shape)
    onehot[rows, actions] = 1.0
    expected_logit = (probs * logits).sum(axis=1)
    grad_temperature = -(logits[rows, actions] - expected_logit) / temperature**2
    return log_probs[rows, actions], (onehot - probs) / temperature, grad_temperature


VARIANTS["tempered_by_rescaled_logits"] = {"tempered_categorical_log_prob": tempered_by_rescaled_logits}
