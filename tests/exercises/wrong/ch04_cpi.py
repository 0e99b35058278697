"""Plausible mistakes in chapter 4: the importance ratio and L^CPI."""

import numpy as np


def ratio_of_exponentials(logp, logp_old):
    """exp(log π) / exp(log π_old): both underflow to 0 near −800, giving 0/0."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.exp(logp) / np.exp(logp_old)


def ratio_inverted(logp, logp_old):
    """π_old / π."""
    return np.exp(logp_old - logp)


def ratio_of_log_probs(logp, logp_old):
    """log π / log π_old, a ratio of the logs."""
    return logp / logp_old


def cpi_gradient_without_ratio(logp, logp_old, advantages):
    """Â_t / n, the policy gradient's formula, which is right only at θ = θ_old."""
    ratio = np.exp(logp - logp_old)
    return float(np.mean(ratio * advantages)), advantages / len(logp)


def cpi_gradient_without_advantage(logp, logp_old, advantages):
    """r_t / n, dropping the advantage from the gradient."""
    ratio = np.exp(logp - logp_old)
    return float(np.mean(ratio * advantages)), ratio / len(logp)


def cpi_value_of_log_ratio(logp, logp_old, advantages):
    """Ê[(log π − log π_old) Â], the log-ratio in place of the ratio."""
    return float(np.mean((logp - logp_old) * advantages)), advantages / len(logp)


def ratio_first_order(logp, logp_old):
    """1 + (log π − log π_old), the first-order approximation of r: right only at r = 1."""
    return 1.0 + (logp - logp_old)


VARIANTS = {
    "ratio_of_exponentials": {"importance_ratio": ratio_of_exponentials},
    "ratio_inverted": {"importance_ratio": ratio_inverted},
    "ratio_first_order": {"importance_ratio": ratio_first_order},
    "ratio_of_log_probs": {"importance_ratio": ratio_of_log_probs},
    "cpi_gradient_without_ratio": {"cpi_objective": cpi_gradient_without_ratio},
    "cpi_gradient_without_advantage": {"cpi_objective": cpi_gradient_without_advantage},
    "cpi_value_of_log_ratio": {"cpi_objective": cpi_value_of_log_ratio},
}


def cpi_summed(logp, logp_old, advantages):
    """Ê as a sum over the batch: value and gradient n times too large."""
    ratio = np.exp(logp - logp_old)
    return float(np.sum(ratio * advantages)), ratio * advantages


def ratio_float32(logp, logp_old):
    """Right ratios, returned in float32."""
    return np.exp(logp - logp_old).astype(np.float32)


VARIANTS.update({"cpi_summed": {"cpi_objective": cpi_summed}, "ratio_float32": {"importance_ratio": ratio_float32}})

FIRST_FAILURE = {
    "ratio_float32": r"float64.*not float32",
    "ratio_of_exponentials": r"−800|underflow",
    "ratio_first_order": r"first-order approximation",
    "ratio_inverted": r"the inverse \(log π and log π_old swapped\?\)",
}


# the transfer task


def weighted_denominator_constant(logp, logp_old, advantages):
    """Σ r in the denominator treated as a constant: ∂/∂ log π_t = r_t Â_t / Σ r."""
    ratio = np.exp(logp - logp_old)
    return float(np.sum(ratio * advantages) / ratio.sum()), ratio * advantages / ratio.sum()


def weighted_cpi_gradient(logp, logp_old, advantages):
    """The right value with L^CPI's gradient r Â / n."""
    ratio = np.exp(logp - logp_old)
    return float(np.sum(ratio * advantages) / ratio.sum()), ratio * advantages / len(logp)


def weighted_quotient_sign(logp, logp_old, advantages):
    """The quotient rule's second term added instead of subtracted: w_t (Â_t + value)."""
    ratio = np.exp(logp - logp_old)
    weights = ratio / ratio.sum()
    value = float(np.sum(weights * advantages))
    return value, weights * (advantages + value)


def weighted_mean_of_ratios(logp, logp_old, advantages):
    """The advantages' plain mean, as if every r_t were 1 (the weights forgotten), and no gradient."""
    return float(np.mean(advantages)), np.zeros(len(logp))


VARIANTS.update(
    {
        "weighted_denominator_constant": {"weighted_cpi_objective": weighted_denominator_constant},
        "weighted_cpi_gradient": {"weighted_cpi_objective": weighted_cpi_gradient},
        "weighted_quotient_sign": {"weighted_cpi_objective": weighted_quotient_sign},
        "weighted_mean_of_ratios": {"weighted_cpi_objective": weighted_mean_of_ratios},
    }
)
FIRST_FAILURE.update(
    {
        "weighted_denominator_constant": r"denominator Σ r treated as a constant",
        "weighted_cpi_gradient": r"should sum to 0.*L\^CPI's gradient",
        "weighted_quotient_sign": r"should sum to 0.*second term added",
        "weighted_mean_of_ratios": r"the value should be",
    }
)
