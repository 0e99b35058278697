"""Chapter 11: MuJoCo. The chapter trains PPO on the paper's continuous-control tasks; its exercise is a transfer task
only: the likelihood of an action that the environment clips to its bounds.

Every array returned is a new float64 array (never an argument itself or a view of one); every value is a float.

Grade: ``minippo grade 11``
"""

from __future__ import annotations

import math

import numpy as np

EXERCISES = []  # the chapter runs minippo as it is; nothing of it to write
TRANSFER = ["clipped_gaussian_log_prob"]


def _log_normal_cdf(z: float) -> float:
    """log Φ(z), accurate in both tails (erfc keeps the relative precision that 1 − erf loses)."""
    return math.log(0.5 * math.erfc(-z / math.sqrt(2.0)))


def clipped_gaussian_log_prob(mean: np.ndarray, log_std: np.ndarray, actions: np.ndarray, low, high):
    """Transfer task: the log-likelihood of actions clipped to the bounds, under the diagonal Gaussian policy whose
    samples were clipped, and its gradient.

    The environment gets clip(u, low, high) for u ~ N(μ, diag σ²). That action's distribution has, in each dimension,
    the Gaussian's density strictly between the bounds and a probability mass on each bound: all of the Gaussian's
    probability beyond it. The log-likelihood of an action is the sum over its dimensions of the log of that density
    or that mass (Fujita & Maeda 2018, "Clipped action policy gradient").
    mean: (n, d).  log_std: (d,), shared by every row.  actions: (n, d), each entry in [low_i, high_i]; an entry equal
    to a bound (exactly) means the sample was clipped there.  low, high: (d,) with low < high.
    Returns (logp, grad_mean, grad_log_std): logp (n,); grad_mean (n, d) = ∂ log p/∂μ; grad_log_std (d,) =
    ∂(Σ_n log p_n)/∂ log σ. Finite while every standardised bound (bound − μ)/σ lies within ±30.
    """
    std = np.exp(log_std)
    z = (actions - mean) / std
    logp = np.zeros(actions.shape)
    grad_mean = np.zeros(actions.shape)
    grad_log_std = np.zeros(actions.shape)
    for index in np.ndindex(actions.shape):
        i = index[-1]
        x = float(z[index])
        log_phi = -0.5 * x * x - 0.5 * math.log(2.0 * math.pi)
        if actions[index] >= high[i]:  # the mass P(u ≥ high) = Φ(−x)
            logp[index] = _log_normal_cdf(-x)
            hazard = math.exp(log_phi - logp[index])  # φ(x) / Φ(−x)
            grad_mean[index] = hazard / std[i]
            grad_log_std[index] = hazard * x
        elif actions[index] <= low[i]:  # the mass P(u ≤ low) = Φ(x)
            logp[index] = _log_normal_cdf(x)
            hazard = math.exp(log_phi - logp[index])  # φ(x) / Φ(x)
            grad_mean[index] = -hazard / std[i]
            grad_log_std[index] = -hazard * x
        else:  # chapter 2's density
            logp[index] = log_phi - log_std[i]
            grad_mean[index] = x / std[i]
            grad_log_std[index] = x * x - 1.0
    return logp.sum(axis=1), grad_mean, grad_log_std.sum(axis=0)
