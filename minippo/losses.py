"""The paper's objectives, each returning its value and its gradient.

Surrogates are written as the paper writes them, as objectives L to *maximise*, averaged over a minibatch of n
samples. Each returns (L, ∂L/∂ log π_θ(a_t|s_t)), one gradient entry per sample: the distribution's
``log_prob_backward`` carries it on to the network's outputs. With r_t = π_θ/π_θold = exp(log π_θ − log π_θold),
∂r_t/∂ log π_θ = r_t, which is all the chain rule needs here.
"""

from __future__ import annotations

import numpy as np


def mean(x) -> float:
    """Ê[x], the average over the minibatch, as a Python float: Σ x / n (np.mean's bookkeeping outweighs the sum on
    a minibatch this small)."""
    return float(x.sum()) / x.size


def pg_objective(logp, advantages):
    """L^PG = Ê[log π_θ(a_t|s_t) Â_t] (eq. 2); ∂L/∂ log π_t = Â_t / n."""
    n = len(logp)
    return mean(logp * advantages), advantages / n


def cpi_objective(logp, logp_old, advantages):
    """L^CPI = Ê[r_t Â_t] (eq. 6); ∂L/∂ log π_t = r_t Â_t / n."""
    n = len(logp)
    ratio = np.exp(logp - logp_old)
    return mean(ratio * advantages), ratio * advantages / n


def clip_objective(logp, logp_old, advantages, epsilon: float):
    """L^CLIP = Ê[min(r_t Â_t, clip(r_t, 1−ε, 1+ε) Â_t)] (eq. 7).

    The clipped term is a constant outside the band, so the gradient is r_t Â_t / n where the unclipped term is
    the smaller one (or the two are equal), and 0 where the clipped term wins: r_t > 1+ε with Â_t > 0, or
    r_t < 1−ε with Â_t < 0. A move that makes things worse is never clipped away.
    """
    n = len(logp)
    ratio = np.exp(logp - logp_old)
    unclipped = ratio * advantages
    clipped = np.clip(ratio, 1.0 - epsilon, 1.0 + epsilon) * advantages
    active = unclipped <= clipped
    return mean(np.minimum(unclipped, clipped)), np.where(active, unclipped, 0.0) / n


def kl_penalty_objective(logp, logp_old, advantages, kl, beta: float):
    """L^KLPEN = Ê[r_t Â_t − β KL[π_θold(·|s_t), π_θ(·|s_t)]] (eq. 8's surrogate).

    Returns (L, ∂L/∂ log π_t, ∂L/∂KL_t); the distribution's ``kl_backward`` carries the last one on.
    """
    n = len(logp)
    value, grad_logp = cpi_objective(logp, logp_old, advantages)
    return value - beta * mean(kl), grad_logp, np.full(n, -beta / n, dtype=logp.dtype)


def adaptive_beta(beta: float, kl: float, kl_target: float) -> float:
    """Eq. 8's update after each policy update: d = Ê[KL]; β ← β/2 if d < d_targ/1.5; β ← 2β if d > 1.5 d_targ."""
    if kl < kl_target / 1.5:
        return beta / 2.0
    if kl > kl_target * 1.5:
        return beta * 2.0
    return beta


def value_loss(values, value_targets, values_old=None, clip_epsilon: float | None = None):
    """L^VF = ½ Ê[(V_θ(s_t) − V^targ_t)²], the ½ making ∂L/∂V_t = (V_t − V^targ_t)/n.

    With ``clip_epsilon`` (the "37 details" value clipping), V is also clipped to within ±ε of the rollout's value
    V_old, and the larger of the two squared errors is taken (pessimistic, like L^CLIP's min).
    """
    n = len(values)
    error = values - value_targets
    if clip_epsilon is None:
        return 0.5 * mean(error * error), error / n
    moved = values - values_old
    clipped_error = values_old + np.clip(moved, -clip_epsilon, clip_epsilon) - value_targets
    squared, clipped_squared = error * error, clipped_error * clipped_error
    use_clipped = clipped_squared > squared
    # the clipped value is flat in V outside ±ε, so its branch passes a gradient only inside the band
    inside = np.abs(moved) <= clip_epsilon
    grad = np.where(use_clipped, np.where(inside, clipped_error, 0.0), error) / n
    return 0.5 * mean(np.maximum(squared, clipped_squared)), grad


def entropy_bonus(entropy):
    """S = Ê[S[π_θ](s_t)] (eq. 9's bonus); ∂S/∂S_t = 1/n."""
    n = len(entropy)
    return mean(entropy), np.full(n, 1.0 / n, dtype=entropy.dtype)


def approx_kl(logp, logp_old) -> float:
    """An estimate of KL[π_old ‖ π] from samples of π_old: Ê[(r − 1) − log r], unbiased and ≥ 0 (Schulman 2020)."""
    log_ratio = logp - logp_old
    return mean(np.expm1(log_ratio) - log_ratio)


def clip_fraction(logp, logp_old, epsilon: float) -> float:
    """The fraction of samples whose ratio left the band [1−ε, 1+ε]."""
    return mean(np.abs(np.exp(logp - logp_old) - 1.0) > epsilon)


def explained_variance(predictions, targets) -> float:
    """1 − Var[y − ŷ] / Var[y]: 1 is a perfect value function, 0 no better than a constant."""
    variance = np.var(targets)
    return float("nan") if variance == 0 else float(1.0 - np.var(targets - predictions) / variance)
