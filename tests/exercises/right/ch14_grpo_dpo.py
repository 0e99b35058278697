"""Other correct ways to write chapter 14."""

import numpy as np


def advantages_group_by_group(scores, eps=1e-8):
    """A loop over the prompts, the standard deviation written out as the root of the mean square deviation."""
    scores = np.asarray(scores, dtype=np.float64)
    advantages = np.zeros_like(scores)
    for i, group in enumerate(scores):
        deviations = group - group.sum() / len(group)
        advantages[i] = deviations / (np.sqrt(np.mean(deviations**2)) + eps)
    return advantages


def dpo_with_log1p(logp_preferred, logp_rejected, ref_preferred, ref_rejected, beta):
    """−log σ(Δ) written as max(−Δ, 0) + log1p(e^{−|Δ|}), and σ(−Δ) from the same stable pieces."""
    n = len(logp_preferred)
    rewards_w = beta * (logp_preferred - ref_preferred)
    rewards_l = beta * (logp_rejected - ref_rejected)
    margin = rewards_w - rewards_l
    loss = np.maximum(-margin, 0.0) + np.log1p(np.exp(-np.abs(margin)))
    small = np.exp(-np.abs(margin))
    wrong = np.where(margin >= 0, small / (1.0 + small), 1.0 / (1.0 + small))  # σ(−Δ)
    return float(np.mean(loss)), -beta * wrong / n, beta * wrong / n


VARIANTS = {
    "advantages_group_by_group": {"grpo_advantages": advantages_group_by_group},
    "dpo_with_log1p": {"dpo_loss": dpo_with_log1p},
}
