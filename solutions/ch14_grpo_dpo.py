"""Chapter 14: GRPO and DPO beside PPO. Two pieces that are new in PPO's descendants: GRPO's advantages, measured
within the group of responses to one prompt, and DPO's loss, the Bradley–Terry loss on the implicit reward
β log π_θ(y|x)/π_ref(y|x), with its gradient with respect to the policy's sequence log-probabilities.

Grade: ``minippo grade 14``
"""

from __future__ import annotations

import numpy as np

EXERCISES = ["grpo_advantages", "dpo_loss"]


def grpo_advantages(scores: np.ndarray, eps: float = 1e-8) -> np.ndarray:
    """The group-relative advantage of every response: its score minus the mean of its group, divided by the
    standard deviation of its group (the population one, ddof = 0) plus ``eps``.

    scores: (m, G), row i the scores of the G responses to prompt i.  Returns (m, G) float64.
    """
    scores = np.asarray(scores, dtype=np.float64)
    centred = scores - scores.mean(axis=1, keepdims=True)
    return centred / (scores.std(axis=1, keepdims=True) + eps)


def dpo_loss(logp_preferred, logp_rejected, ref_preferred, ref_rejected, beta: float):
    """The DPO loss over n pairs, L = −Ê[log σ(Δ)] with the margin of implicit rewards
    Δ = β [(log π_θ(y_w|x) − log π_ref(y_w|x)) − (log π_θ(y_l|x) − log π_ref(y_l|x))], and its gradient.

    logp_preferred, logp_rejected: (n,) sequence log-probabilities of the preferred (y_w) and rejected (y_l)
    responses under the policy π_θ; ref_preferred, ref_rejected: the same under the frozen reference π_ref.
    Returns (loss, grad_preferred, grad_rejected): the loss as a float, and ∂L/∂ log π_θ(y_w|x) and
    ∂L/∂ log π_θ(y_l|x), both (n,). It must stay finite for margins of ±1000.
    """
    n = len(logp_preferred)
    margin = beta * ((logp_preferred - ref_preferred) - (logp_rejected - ref_rejected))
    loss = float(np.logaddexp(0.0, -margin).sum()) / n
    wrong = np.exp(-np.logaddexp(0.0, margin))  # σ(−Δ)
    return loss, -beta * wrong / n, beta * wrong / n
