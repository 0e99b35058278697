"""Chapter 8: the value loss and the entropy bonus, and the combined objective L^{CLIP+VF+S} (eq. 9).

With one network for the policy and the value, one objective trains both:
    L^{CLIP+VF+S} = Ê[L^CLIP_t − c1 L^VF_t + c2 S[π_θ](s_t)].
This course's value loss carries a factor ½ (so its gradient is the plain error): L^VF = ½ Ê[(V_θ(s_t) − V^targ_t)²].

Every array returned is a new float64 array (never an argument itself or a view of one); every value is a float.

Grade: ``minippo grade 8``
"""

from __future__ import annotations

import numpy as np

from minippo.losses import clip_objective

EXERCISES = ["value_loss", "clipped_value_loss", "clip_vf_s_objective"]
TRANSFER = ["huber_value_loss"]  # the chapter's idea applied to a case the book has not shown


def value_loss(values: np.ndarray, value_targets: np.ndarray):
    """L^VF = ½ Ê[(V_θ(s_t) − V^targ_t)²] (the book's (8.2), with its ½), a loss to *minimise*, and its gradient.

    values: (n,) V_θ(s_t), the variable.  value_targets: (n,) V^targ_t, constants.
    Returns (loss, grad): loss a float; grad = ∂L^VF/∂V_θ(s_t), shape (n,).
    """
    n = len(values)
    error = values - value_targets
    return 0.5 * float(np.mean(error * error)), error / n


def clipped_value_loss(values: np.ndarray, value_targets: np.ndarray, values_old: np.ndarray, epsilon: float):
    """The value loss with the update of V clipped to ±ε around the rollout's values (one of the "37 details"):
    V^clip_t = V_old,t + clip(V_t − V_old,t, −ε, ε), and the loss takes, sample by sample, the larger of the two squared
    errors, (V_t − V^targ_t)² and (V^clip_t − V^targ_t)², with value_loss's ½ and mean.

    values: (n,) the variable.  value_targets, values_old: (n,) constants.  epsilon: ε > 0.
    Returns (loss, grad), grad = ∂L/∂V_t of shape (n,). Where the two errors are equal, use the unclipped one's
    derivative; V_t exactly on an edge of the band, |V_t − V_old,t| = ε, counts as inside it.
    """
    n = len(values)
    error = values - value_targets
    clipped_error = values_old + np.clip(values - values_old, -epsilon, epsilon) - value_targets
    use_clipped = clipped_error * clipped_error > error * error
    inside = np.abs(values - values_old) <= epsilon
    grad = np.where(use_clipped, np.where(inside, clipped_error, 0.0), error) / n
    return 0.5 * float(np.mean(np.maximum(error * error, clipped_error * clipped_error))), grad


def clip_vf_s_objective(
    logp: np.ndarray,
    logp_old: np.ndarray,
    advantages: np.ndarray,
    values: np.ndarray,
    value_targets: np.ndarray,
    entropy: np.ndarray,
    epsilon: float,
    c1: float,
    c2: float,
):
    """L^{CLIP+VF+S}, the paper's eq. 9 (the book's (8.1)), an objective to *maximise*, and its three gradients.

    logp, logp_old, advantages: (n,) as for L^CLIP (chapter 6; minippo.losses.clip_objective computes it).
    values, value_targets: (n,) as for value_loss (with its ½).  entropy: (n,) S[π_θ](s_t), the variable of the bonus.
    epsilon, c1, c2: ε and the paper's coefficients.
    Returns (value, grad_logp, grad_values, grad_entropy): value a float, and ∂L/∂ log π_t, ∂L/∂V_t, ∂L/∂S_t, each of
    shape (n,).
    """
    n = len(logp)
    clip_value, grad_logp = clip_objective(logp, logp_old, advantages, epsilon)
    vf_value, vf_grad = value_loss(values, value_targets)
    objective = clip_value - c1 * vf_value + c2 * float(np.mean(entropy))
    return objective, grad_logp, -c1 * vf_grad, np.full(n, c2 / n)


def huber_value_loss(values: np.ndarray, value_targets: np.ndarray, delta: float):
    """Transfer task: a value loss that grows linearly for large errors, and its gradient.

    The Huber loss (Huber 1964) of each error e_t = V_t − V^targ_t with threshold δ > 0: ½ e² where |e| ≤ δ, and
    beyond it the straight line that continues ½ e² with the same value and slope at |e| = δ. The loss is its mean
    over the batch, a loss to *minimise*.
    values: (n,) the variable.  value_targets: (n,) constants.  delta: δ > 0.
    Returns (loss, grad): loss a float; grad = ∂loss/∂V_t, shape (n,).
    """
    error = values - value_targets
    size = np.abs(error)
    loss = np.where(size <= delta, 0.5 * error * error, delta * (size - 0.5 * delta))
    return float(np.mean(loss)), np.clip(error, -delta, delta) / len(values)
