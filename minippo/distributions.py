"""The two policy distributions, each with its log-probability, entropy and KL, and their hand-derived gradients.

Every forward quantity has a ``*_backward`` next to it that takes dL/d(quantity), one value per sample, and returns
dL/d(parameters of the distribution). The parameters are the logits (categorical) or the mean and the
state-independent log standard deviation (diagonal Gaussian).
"""

from __future__ import annotations

import numpy as np

LOG_2PI = float(np.log(2.0 * np.pi))


def _where_possible(probs: np.ndarray, terms) -> np.ndarray:
    """``terms(probs)`` with 0 where the probability is 0: p·log p → 0 as p → 0, but 0·(−∞) is NaN in floating point
    (computed, then discarded, so the warning it raises is silenced)."""
    with np.errstate(invalid="ignore"):
        return np.where(probs > 0.0, terms(probs), 0.0)


def sample_categorical(logits: np.ndarray, uniforms: np.ndarray) -> np.ndarray:
    """One action per row of ``logits`` (n, k) by the inverse CDF: the first a with u·Σ_j p_j < Σ_{j≤a} p_j, where
    p = e^(z − max z) need not be normalised and u ~ U[0, 1) is one of ``uniforms`` (n,)."""
    probs = np.exp(logits - logits.max(axis=-1, keepdims=True))
    cumulative = np.cumsum(probs, axis=-1)
    below = uniforms[:, None] * cumulative[:, -1:] > cumulative
    return np.minimum(below.sum(axis=-1), logits.shape[-1] - 1)


class Categorical:
    """π(a|s) = softmax(z)_a for a batch of logits z of shape (n, k), for discrete action spaces."""

    def __init__(self, logits: np.ndarray):
        self.logits = logits
        shifted = logits - logits.max(axis=-1, keepdims=True)
        self.log_probs = shifted - np.log(np.exp(shifted).sum(axis=-1, keepdims=True))
        self.probs = np.exp(self.log_probs)

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        return sample_categorical(self.logits, rng.random(self.logits.shape[0]))

    def mode(self) -> np.ndarray:
        return self.logits.argmax(axis=-1)

    def log_prob(self, actions: np.ndarray) -> np.ndarray:
        """log π(a|s) = z_a − log Σ_j exp z_j."""
        return np.take_along_axis(self.log_probs, actions.astype(np.int64)[:, None], axis=-1)[:, 0]

    def log_prob_backward(self, actions: np.ndarray, grad_logp: np.ndarray):
        """∂ log π(a|s) / ∂z_j = 1[j = a] − π_j, scaled by dL/dlog π."""
        grad = -self.probs * grad_logp[:, None]
        grad[np.arange(len(actions)), actions.astype(np.int64)] += grad_logp
        return (grad,)

    def entropy(self) -> np.ndarray:
        """S = −Σ_j π_j log π_j, where an action of probability 0 adds 0 (the limit of p log p), not 0·(−∞)."""
        return -_where_possible(self.probs, lambda p: p * self.log_probs).sum(axis=-1)

    def entropy_backward(self, grad_entropy: np.ndarray):
        """∂S/∂z_j = −π_j (log π_j + S)."""
        entropy = self.entropy()
        terms = _where_possible(self.probs, lambda p: p * (self.log_probs + entropy[:, None]))
        return (-terms * grad_entropy[:, None],)

    def kl(self, other: Categorical) -> np.ndarray:
        """KL[other ‖ self] = Σ_j π'_j (log π'_j − log π_j), with ``other`` the old policy π' (eq. 8's order); an
        action the old policy never takes (π'_j = 0) adds 0."""
        return _where_possible(other.probs, lambda p: p * (other.log_probs - self.log_probs)).sum(axis=-1)

    def kl_backward(self, other: Categorical, grad_kl: np.ndarray):
        """∂KL[π' ‖ π]/∂z_j = π_j − π'_j: only this (the new) policy's logits get a gradient."""
        return ((self.probs - other.probs) * grad_kl[:, None],)


class DiagGaussian:
    """π(a|s) = N(a; μ(s), diag σ²) with log σ a free vector shared by all states, for continuous actions.

    ``log_std`` has shape (k,) for the policy being trained. The old policy π_θold of a stored batch may carry it as
    (n, k), one copy per sample, since the batch is shuffled and cut into minibatches like every other per-sample
    array; its log-probability, entropy and KL read it the same way (the backward functions are for the (k,) case).

    The distribution keeps its own copy of log σ, as a Categorical keeps its own log-probabilities: a π_θ built now
    stays this π_θ when an optimiser later moves the agent's log σ in place, so it can serve as a fixed π_θold."""

    def __init__(self, mean: np.ndarray, log_std: np.ndarray):
        self.mean = mean
        self.log_std = np.array(log_std)
        self.std = np.exp(log_std)

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        return self.mean + self.std * rng.standard_normal(self.mean.shape)

    def mode(self) -> np.ndarray:
        return self.mean

    def log_prob(self, actions: np.ndarray) -> np.ndarray:
        """log π(a|s) = −½ Σ_i ((a_i − μ_i)/σ_i)² − Σ_i log σ_i − (k/2) log 2π."""
        z = (actions - self.mean) / self.std
        return -0.5 * (z * z).sum(axis=-1) - self.log_std.sum(axis=-1) - 0.5 * self.mean.shape[-1] * LOG_2PI

    def log_prob_backward(self, actions: np.ndarray, grad_logp: np.ndarray):
        """∂ log π/∂μ_i = (a_i − μ_i)/σ_i²;  ∂ log π/∂ log σ_i = ((a_i − μ_i)/σ_i)² − 1 (summed over the batch)."""
        z = (actions - self.mean) / self.std
        grad_mean = (z / self.std) * grad_logp[:, None]
        grad_log_std = ((z * z - 1.0) * grad_logp[:, None]).sum(axis=0)
        return grad_mean, grad_log_std

    def entropy(self) -> np.ndarray:
        """S = Σ_i (log σ_i + ½ log 2πe), the same for every state."""
        value = self.log_std.sum(axis=-1) + 0.5 * self.mean.shape[-1] * (LOG_2PI + 1.0)
        return np.full(self.mean.shape[0], float(value)) if np.ndim(value) == 0 else value

    def entropy_backward(self, grad_entropy: np.ndarray):
        """∂S/∂μ = 0;  ∂S/∂ log σ_i = 1."""
        return np.zeros_like(self.mean), np.full(self.log_std.shape, grad_entropy.sum())

    def kl(self, other: DiagGaussian) -> np.ndarray:
        """KL[other ‖ self] = Σ_i log σ_i/σ'_i + (σ'_i² + (μ'_i − μ_i)²) / (2σ_i²) − ½, ``other`` the old policy.

        With d_i = log σ_i − log σ'_i, the σ terms are d_i + ½(e^(−2d_i) − 1), computed with expm1: written as
        σ'²/(2σ²) − ½ they subtract two numbers near ½ and keep only ~1e-4 of the KL's digits when σ barely moved."""
        d = self.log_std - other.log_std
        return (d + 0.5 * np.expm1(-2.0 * d) + (other.mean - self.mean) ** 2 / (2.0 * self.std**2)).sum(axis=-1)

    def kl_backward(self, other: DiagGaussian, grad_kl: np.ndarray):
        """∂KL/∂μ_i = (μ_i − μ'_i)/σ_i²;  ∂KL/∂ log σ_i = 1 − (σ'_i² + (μ'_i − μ_i)²)/σ_i², with 1 − σ'_i²/σ_i² computed
        as −expm1(−2d_i).

        Only this (the new) policy gets a gradient: π_θold, ``other``, is held fixed, its σ' included."""
        var = self.std**2
        diff = self.mean - other.mean
        grad_mean = diff / var * grad_kl[:, None]
        d = self.log_std - other.log_std
        grad_log_std = ((-np.expm1(-2.0 * d) - diff**2 / var) * grad_kl[:, None]).sum(axis=0)
        return grad_mean, grad_log_std
