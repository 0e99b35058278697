"""Other correct ways to write chapter 14."""

import math

import numpy as np


def advantages_group_by_group(scores, eps=1e-8):
    """A loop over the prompts, the standard deviation written out as the root of the mean square deviation."""
    scores = np.asarray(scores, dtype=np.float64)
    advantages = np.zeros_like(scores)
    for i, group in enumerate(scores):
        deviations = group - group.sum() / len(group)
        advantages[i] = deviations / (np.sqrt(np.mean(deviations**2)) + eps)
    return advantages


def grpo_objective_case_by_case(logp, logp_old, logp_ref, advantages, weights, epsilon, beta):
    """The min written as its cases: for Â ≥ 0 the ratio is capped at 1 + ε, for Â < 0 floored at 1 − ε; k3 through
    u = π_ref/π_θ, its derivative d(u − log u − 1)/d log π_θ = −u + 1."""
    ratio = np.exp(logp - logp_old)
    capped = np.where(advantages >= 0, np.minimum(ratio, 1.0 + epsilon), np.maximum(ratio, 1.0 - epsilon))
    moving = np.where(advantages >= 0, ratio <= 1.0 + epsilon, ratio >= 1.0 - epsilon)
    u = np.exp(logp_ref - logp)
    value = np.sum(weights * (capped * advantages)) - beta * np.sum(weights * (u - np.log(u) - 1.0))
    grad = weights * np.where(moving, ratio * advantages, 0.0) + beta * weights * (u - 1.0)
    return float(value), grad


def grpo_objective_token_by_token(logp, logp_old, logp_ref, advantages, weights, epsilon, beta):
    """A loop over the tokens, with math's scalar functions; k3 written with log π_θ − log π_ref = d."""
    value, grad = 0.0, np.zeros(len(logp))
    for t in range(len(logp)):
        r = math.exp(logp[t] - logp_old[t])
        a = advantages[t]
        low, high = r * a, min(max(r, 1.0 - epsilon), 1.0 + epsilon) * a
        d = logp[t] - logp_ref[t]
        value += weights[t] * (min(low, high) - beta * (math.exp(-d) + d - 1.0))
        grad[t] = weights[t] * ((r * a if low <= high else 0.0) - beta * (1.0 - math.exp(-d)))
    return value, grad


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
    "advantages_group_by_group": {"group_advantages": advantages_group_by_group},
    "grpo_objective_case_by_case": {"grpo_objective": grpo_objective_case_by_case},
    "grpo_objective_token_by_token": {"grpo_objective": grpo_objective_token_by_token},
    "dpo_with_log1p": {"dpo_loss": dpo_with_log1p},
}


def ipo_through_the_margin(logp_preferred, logp_rejected, ref_preferred, ref_rejected, tau):
    """The mean squared error of h against its target, with ∂/∂h first and the two signs of ∂h applied after."""
    h = logp_preferred - logp_rejected - (ref_preferred - ref_rejected)
    residual = h - 0.5 / tau
    grad_h = 2.0 * residual / len(h)
    return float(residual @ residual / len(h)), grad_h, -grad_h


VARIANTS["ipo_through_the_margin"] = {"ipo_loss": ipo_through_the_margin}
