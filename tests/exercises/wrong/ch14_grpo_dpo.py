"""Plausible mistakes in chapter 14: GRPO's group-relative advantages and the DPO loss with its gradient."""

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
    "advantages_over_the_batch": {"grpo_advantages": advantages_over_the_batch},
    "advantages_sample_std": {"grpo_advantages": advantages_sample_std},
    "advantages_without_eps": {"grpo_advantages": advantages_without_eps},
    "advantages_centred_only": {"grpo_advantages": advantages_centred_only},
    "advantages_over_the_wrong_axis": {"grpo_advantages": advantages_over_the_wrong_axis},
    "dpo_missing_beta": {"dpo_loss": dpo_missing_beta},
    "dpo_beta_missing_from_the_gradient": {"dpo_loss": dpo_beta_missing_from_the_gradient},
    "dpo_log_ratio_of_the_wrong_model": {"dpo_loss": dpo_log_ratio_of_the_wrong_model},
    "dpo_without_the_reference": {"dpo_loss": dpo_without_the_reference},
    "dpo_log_of_sigmoid": {"dpo_loss": dpo_log_of_sigmoid},
    "dpo_gradient_on_preferred_only": {"dpo_loss": dpo_gradient_on_preferred_only},
}

# what the first failing test's message must say (a regular expression), so that the scoreboard names the mistake
FIRST_FAILURE = {
    "advantages_sample_std": r"ddof = 0",
    "advantages_without_eps": r"NaN or infinite|add eps",
    "dpo_missing_beta": r"β = 0\.3",
    "dpo_log_of_sigmoid": r"±1000",
    "dpo_gradient_on_preferred_only": r"the rejected response is a variable too",
}
