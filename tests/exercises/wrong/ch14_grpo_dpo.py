"""Plausible mistakes in chapter 14: GRPO's group-relative advantages, GRPO's objective with k3 and its gradient, and
the DPO loss with its gradient."""

import numpy as np


def advantages_over_the_batch(scores, eps=1e-8):
    """Normalised over the whole batch, as PPO's advantages are, instead of within each group."""
    scores = np.asarray(scores, dtype=np.float64)
    return (scores - scores.mean()) / (scores.std() + eps)


def advantages_sample_std(scores, eps=1e-8):
    """The sample standard deviation (ddof = 1) where the contract says the population one."""
    scores = np.asarray(scores, dtype=np.float64)
    return (scores - scores.mean(axis=1, keepdims=True)) / (scores.std(axis=1, ddof=1, keepdims=True) + eps)


def advantages_without_eps(scores, eps=1e-8):
    """No eps: a group whose responses all scored the same divides 0 by 0."""
    scores = np.asarray(scores, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (scores - scores.mean(axis=1, keepdims=True)) / scores.std(axis=1, keepdims=True)


def advantages_centred_only(scores, eps=1e-8):
    """The group's mean subtracted, but no division by its standard deviation."""
    scores = np.asarray(scores, dtype=np.float64)
    return scores - scores.mean(axis=1, keepdims=True)


def advantages_over_the_wrong_axis(scores, eps=1e-8):
    """Mean and std taken down the columns (over prompts) instead of along each row (over a prompt's responses)."""
    scores = np.asarray(scores, dtype=np.float64)
    return (scores - scores.mean(axis=0, keepdims=True)) / (scores.std(axis=0, keepdims=True) + eps)


def _grpo(logp, logp_old, logp_ref, advantages, weights, epsilon, beta, kl=None, kl_grad=None, surrogate_grad=None):
    """GRPO's objective with one piece replaced: the KL estimate and its derivative as functions of log(π_ref/π_θ),
    the surrogate's derivative as a function of (ratio, Â, unclipped, clipped)."""
    ratio = np.exp(logp - logp_old)
    unclipped = ratio * advantages
    clipped = np.clip(ratio, 1.0 - epsilon, 1.0 + epsilon) * advantages
    log_u = logp_ref - logp
    kl = (lambda x: np.exp(x) - x - 1.0) if kl is None else kl
    kl_grad = (lambda x: 1.0 - np.exp(x)) if kl_grad is None else kl_grad
    if surrogate_grad is None:
        surrogate_grad = lambda r, a, u, c: np.where(u <= c, u, 0.0)  # noqa: E731
    value = float(np.sum(weights * (np.minimum(unclipped, clipped) - beta * kl(log_u))))
    grad = weights * (surrogate_grad(ratio, advantages, unclipped, clipped) - beta * kl_grad(log_u))
    return value, grad


def grpo_k3_of_the_reverse_ratio(logp, logp_old, logp_ref, advantages, weights, epsilon, beta):
    """k3 with the ratio upside down, π_θ/π_ref − log(π_θ/π_ref) − 1, and its derivative π_θ/π_ref − 1: an estimate of
    KL[π_ref ‖ π_θ] under samples from π_ref, not of KL[π_θ ‖ π_ref] under the policy's own samples."""
    return _grpo(logp, logp_old, logp_ref, advantages, weights, epsilon, beta,
                 kl=lambda x: np.exp(-x) + x - 1.0, kl_grad=lambda x: np.exp(-x) - 1.0)  # fmt: skip


def grpo_k3_gradient_of_the_reverse_kl(logp, logp_old, logp_ref, advantages, weights, epsilon, beta):
    """The right k3, but its gradient taken as log(π_θ/π_ref), the per-sample gradient of the reverse KL[π_θ ‖ π_ref]
    that k3 estimates, instead of k3's own derivative 1 − π_ref/π_θ."""
    return _grpo(logp, logp_old, logp_ref, advantages, weights, epsilon, beta, kl_grad=lambda x: -x)


def grpo_k1_gradient(logp, logp_old, logp_ref, advantages, weights, epsilon, beta):
    """The KL term differentiated as if it were k1 = log π_θ − log π_ref: a derivative of 1 on every token."""
    return _grpo(logp, logp_old, logp_ref, advantages, weights, epsilon, beta, kl_grad=lambda x: np.ones_like(x))


def grpo_kl_gradient_sign_flipped(logp, logp_old, logp_ref, advantages, weights, epsilon, beta):
    """The KL term's gradient added where it is subtracted: the penalty pushes the policy away from π_ref."""
    return _grpo(logp, logp_old, logp_ref, advantages, weights, epsilon, beta, kl_grad=lambda x: np.exp(x) - 1.0)


def grpo_surrogate_gradient_with_respect_to_the_ratio(logp, logp_old, logp_ref, advantages, weights, epsilon, beta):
    """∂(r Â)/∂r = Â where the chain rule through r = exp(log π_θ − log π_θold) asks for r Â."""
    return _grpo(logp, logp_old, logp_ref, advantages, weights, epsilon, beta,
                 surrogate_grad=lambda r, a, u, c: np.where(u <= c, a, 0.0))  # fmt: skip


def grpo_gradient_through_the_clipped_term(logp, logp_old, logp_ref, advantages, weights, epsilon, beta):
    """The min's gradient always taken from the unclipped term, even where the clipped term is the smaller."""
    return _grpo(logp, logp_old, logp_ref, advantages, weights, epsilon, beta,
                 surrogate_grad=lambda r, a, u, c: u)  # fmt: skip


def grpo_clip_without_the_min(logp, logp_old, logp_ref, advantages, weights, epsilon, beta):
    """The clipped term alone, clip(r, 1 − ε, 1 + ε) Â, where the min with r Â belongs."""
    inside = lambda r, a, u, c: np.where((r > 1 - epsilon) & (r < 1 + epsilon), u, 0.0)  # noqa: E731
    _, grad = _grpo(logp, logp_old, logp_ref, advantages, weights, epsilon, beta, surrogate_grad=inside)
    ratio = np.exp(logp - logp_old)
    clipped = np.clip(ratio, 1.0 - epsilon, 1.0 + epsilon) * advantages
    return float(np.sum(weights * (clipped - beta * (np.exp(logp_ref - logp) - (logp_ref - logp) - 1.0)))), grad


def grpo_kl_term_not_weighted(logp, logp_old, logp_ref, advantages, weights, epsilon, beta):
    """The weights applied to the surrogate only: the KL term counts every token once, whatever its response."""
    ratio = np.exp(logp - logp_old)
    unclipped = ratio * advantages
    clipped = np.clip(ratio, 1.0 - epsilon, 1.0 + epsilon) * advantages
    log_u = logp_ref - logp
    value = float(np.sum(weights * np.minimum(unclipped, clipped) - beta * (np.exp(log_u) - log_u - 1.0)))
    grad = weights * np.where(unclipped <= clipped, unclipped, 0.0) - beta * (1.0 - np.exp(log_u))
    return value, grad


def _sigma_of_minus(margin):
    return np.exp(-np.logaddexp(0.0, margin))


def dpo_missing_beta(logp_preferred, logp_rejected, ref_preferred, ref_rejected, beta):
    """β left out of the margin (and so of the gradient): β = 1 whatever is asked."""
    n = len(logp_preferred)
    margin = (logp_preferred - ref_preferred) - (logp_rejected - ref_rejected)
    wrong = _sigma_of_minus(margin)
    return float(np.logaddexp(0.0, -margin).sum()) / n, -wrong / n, wrong / n


def dpo_beta_missing_from_the_gradient(logp_preferred, logp_rejected, ref_preferred, ref_rejected, beta):
    """The right loss, but the chain rule forgets the β in front of the log-ratios."""
    n = len(logp_preferred)
    margin = beta * ((logp_preferred - ref_preferred) - (logp_rejected - ref_rejected))
    wrong = _sigma_of_minus(margin)
    return float(np.logaddexp(0.0, -margin).sum()) / n, -wrong / n, wrong / n


def dpo_log_ratio_of_the_wrong_model(logp_preferred, logp_rejected, ref_preferred, ref_rejected, beta):
    """log π_ref − log π_θ: the reference's log-ratio to the policy, the wrong way round."""
    n = len(logp_preferred)
    margin = beta * ((ref_preferred - logp_preferred) - (ref_rejected - logp_rejected))
    wrong = _sigma_of_minus(margin)
    return float(np.logaddexp(0.0, -margin).sum()) / n, beta * wrong / n, -beta * wrong / n


def dpo_without_the_reference(logp_preferred, logp_rejected, ref_preferred, ref_rejected, beta):
    """β (log π_θ(y_w) − log π_θ(y_l)): the reference left out, so nothing anchors the policy."""
    n = len(logp_preferred)
    margin = beta * (logp_preferred - logp_rejected)
    wrong = _sigma_of_minus(margin)
    return float(np.logaddexp(0.0, -margin).sum()) / n, -beta * wrong / n, beta * wrong / n


def dpo_log_of_sigmoid(logp_preferred, logp_rejected, ref_preferred, ref_rejected, beta):
    """log(σ(Δ)) computed directly: σ underflows to 0 for a margin of −1000 and the loss is infinite."""
    n = len(logp_preferred)
    margin = beta * ((logp_preferred - ref_preferred) - (logp_rejected - ref_rejected))
    with np.errstate(over="ignore", divide="ignore"):
        sigma = 1.0 / (1.0 + np.exp(-margin))
        loss = -float(np.log(sigma).sum()) / n
    return loss, -beta * (1.0 - sigma) / n, beta * (1.0 - sigma) / n


def dpo_gradient_on_preferred_only(logp_preferred, logp_rejected, ref_preferred, ref_rejected, beta):
    """Forgets that the rejected response's log-probability is a variable too."""
    n = len(logp_preferred)
    margin = beta * ((logp_preferred - ref_preferred) - (logp_rejected - ref_rejected))
    wrong = _sigma_of_minus(margin)
    return float(np.logaddexp(0.0, -margin).sum()) / n, -beta * wrong / n, np.zeros(n)


VARIANTS = {
    "advantages_over_the_batch": {"group_advantages": advantages_over_the_batch},
    "advantages_sample_std": {"group_advantages": advantages_sample_std},
    "advantages_without_eps": {"group_advantages": advantages_without_eps},
    "advantages_centred_only": {"group_advantages": advantages_centred_only},
    "advantages_over_the_wrong_axis": {"group_advantages": advantages_over_the_wrong_axis},
    "grpo_k3_of_the_reverse_ratio": {"grpo_objective": grpo_k3_of_the_reverse_ratio},
    "grpo_k3_gradient_of_the_reverse_kl": {"grpo_objective": grpo_k3_gradient_of_the_reverse_kl},
    "grpo_k1_gradient": {"grpo_objective": grpo_k1_gradient},
    "grpo_kl_gradient_sign_flipped": {"grpo_objective": grpo_kl_gradient_sign_flipped},
    "grpo_surrogate_gradient_with_respect_to_the_ratio": {
        "grpo_objective": grpo_surrogate_gradient_with_respect_to_the_ratio
    },
    "grpo_gradient_through_the_clipped_term": {"grpo_objective": grpo_gradient_through_the_clipped_term},
    "grpo_clip_without_the_min": {"grpo_objective": grpo_clip_without_the_min},
    "grpo_kl_term_not_weighted": {"grpo_objective": grpo_kl_term_not_weighted},
    "dpo_missing_beta": {"dpo_loss": dpo_missing_beta},
    "dpo_beta_missing_from_the_gradient": {"dpo_loss": dpo_beta_missing_from_the_gradient},
    "dpo_log_ratio_of_the_wrong_model": {"dpo_loss": dpo_log_ratio_of_the_wrong_model},
    "dpo_without_the_reference": {"dpo_loss": dpo_without_the_reference},
    "dpo_log_of_sigmoid": {"dpo_loss": dpo_log_of_sigmoid},
    "dpo_gradient_on_preferred_only": {"dpo_loss": dpo_gradient_on_preferred_only},
}

# what the first failing test's message must say (a regular expression), so that the scoreboard names the mistake
FIRST_FAILURE = {
    "grpo_k3_of_the_reverse_ratio": r"1 − π_ref/π_θ",
    "grpo_k3_gradient_of_the_reverse_kl": r"1 − π_ref/π_θ",
    "grpo_k1_gradient": r"1 − π_ref/π_θ",
    "grpo_kl_gradient_sign_flipped": r"1 − π_ref/π_θ",
    "grpo_surrogate_gradient_with_respect_to_the_ratio": r"not to r",
    "grpo_gradient_through_the_clipped_term": r"0 where the clipped one is",
    "advantages_sample_std": r"ddof = 0",
    "advantages_without_eps": r"NaN or infinite|add eps",
    "dpo_missing_beta": r"β = 0\.3",
    "dpo_log_of_sigmoid": r"±1000",
    "dpo_gradient_on_preferred_only": r"the rejected response is a variable too",
}


# the transfer task


def _ipo_gap(logp_preferred, logp_rejected, ref_preferred, ref_rejected, tau):
    return (logp_preferred - ref_preferred) - (logp_rejected - ref_rejected) - 1.0 / (2.0 * tau)


def ipo_without_factor_two(logp_preferred, logp_rejected, ref_preferred, ref_rejected, tau):
    """The square's derivative taken without its factor 2."""
    gap = _ipo_gap(logp_preferred, logp_rejected, ref_preferred, ref_rejected, tau)
    n = len(gap)
    return float(np.mean(gap * gap)), gap / n, -gap / n


def ipo_same_sign(logp_preferred, logp_rejected, ref_preferred, ref_rejected, tau):
    """The rejected response's gradient with the preferred one's sign."""
    gap = _ipo_gap(logp_preferred, logp_rejected, ref_preferred, ref_rejected, tau)
    n = len(gap)
    return float(np.mean(gap * gap)), 2 * gap / n, 2 * gap / n


def ipo_target_one_over_tau(logp_preferred, logp_rejected, ref_preferred, ref_rejected, tau):
    """The target 1/τ instead of 1/(2τ)."""
    gap = _ipo_gap(logp_preferred, logp_rejected, ref_preferred, ref_rejected, tau) - 1.0 / (2.0 * tau)
    n = len(gap)
    return float(np.mean(gap * gap)), 2 * gap / n, -2 * gap / n


def ipo_summed(logp_preferred, logp_rejected, ref_preferred, ref_rejected, tau):
    """Summed over the pairs: loss and gradients."""
    gap = _ipo_gap(logp_preferred, logp_rejected, ref_preferred, ref_rejected, tau)
    return float(np.sum(gap * gap)), 2 * gap, -2 * gap


VARIANTS.update(
    {
        "ipo_without_factor_two": {"ipo_loss": ipo_without_factor_two},
        "ipo_same_sign": {"ipo_loss": ipo_same_sign},
        "ipo_target_one_over_tau": {"ipo_loss": ipo_target_one_over_tau},
        "ipo_summed": {"ipo_loss": ipo_summed},
    }
)
FIRST_FAILURE.update(
    {
        "ipo_without_factor_two": r"without its factor 2",
        "ipo_same_sign": r"with the same sign",
        "ipo_target_one_over_tau": r"target 1/τ",
        "ipo_summed": r"the loss, τ = 0\.1.*a sum over the batch",
    }
)
