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
