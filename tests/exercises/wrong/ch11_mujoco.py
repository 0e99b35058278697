"""Plausible mistakes in chapter 11's transfer task: the likelihood of clipped actions."""

import math

import numpy as np


def _tail(x):
    return math.log(0.5 * math.erfc(-x / math.sqrt(2.0)))


def _clipped(mean, log_std, actions, low, high, upper, lower, inside=None):
    std = np.exp(log_std)
    z = (actions - mean) / std
    logp, grad_mean, grad_log_std = np.zeros(actions.shape), np.zeros(actions.shape), np.zeros(actions.shape)
    for index in np.ndindex(actions.shape):
        i, x = index[-1], float(z[index])
        log_phi = -0.5 * x * x - 0.5 * math.log(2 * math.pi)
        if actions[index] >= high[i]:
            logp[index], grad_mean[index], grad_log_std[index] = upper(x, log_phi, std[i])
        elif actions[index] <= low[i]:
            logp[index], grad_mean[index], grad_log_std[index] = lower(x, log_phi, std[i])
        else:
            logp[index], grad_mean[index], grad_log_std[index] = log_phi - log_std[i], x / std[i], x * x - 1
    return logp.sum(axis=1), grad_mean, grad_log_std.sum(axis=0)


def _upper(x, log_phi, std):
    h = math.exp(log_phi - _tail(-x))
    return _tail(-x), h / std, h * x


def _lower(x, log_phi, std):
    h = math.exp(log_phi - _tail(x))
    return _tail(x), -h / std, -h * x


def clipped_density_everywhere(mean, log_std, actions, low, high):
    """The Gaussian's density at every action, the bounds included, as if nothing were clipped."""
    std = np.exp(log_std)
    z = (actions - mean) / std
    logp = (-0.5 * z * z - log_std - 0.5 * math.log(2 * math.pi)).sum(axis=1)
    return logp, z / std, (z * z - 1).sum(axis=0)


def clipped_tails_swapped(mean, log_std, actions, low, high):
    """The upper bound given P(u ≤ high) and the lower P(u ≥ low): each bound the other side's mass."""
    return _clipped(mean, log_std, actions, low, high, _lower, _upper)


def clipped_gradient_without_sigma(mean, log_std, actions, low, high):
    """∂/∂μ of a bound's log-mass without the 1/σ of ∂x/∂μ."""

    def upper(x, log_phi, std):
        h = math.exp(log_phi - _tail(-x))
        return _tail(-x), h, h * x

    def lower(x, log_phi, std):
        h = math.exp(log_phi - _tail(x))
        return _tail(x), -h, -h * x

    return _clipped(mean, log_std, actions, low, high, upper, lower)


def clipped_log_of_one_minus_cdf(mean, log_std, actions, low, high):
    """log(1 − Φ) computed as 1 minus the cdf: −inf far in the upper tail, log(0) far in the lower one."""

    def cdf(x):
        return 0.5 * (1 + math.erf(x / math.sqrt(2.0)))

    def upper(x, log_phi, std):
        mass = max(1 - cdf(x), 1e-300)
        h = math.exp(log_phi) / mass
        return math.log(mass), h / std, h * x

    def lower(x, log_phi, std):
        mass = max(cdf(x), 1e-300)
        h = math.exp(log_phi) / mass
        return math.log(mass), -h / std, -h * x

    return _clipped(mean, log_std, actions, low, high, upper, lower)


VARIANTS = {
    "clipped_density_everywhere": {"clipped_gaussian_log_prob": clipped_density_everywhere},
    "clipped_tails_swapped": {"clipped_gaussian_log_prob": clipped_tails_swapped},
    "clipped_gradient_without_sigma": {"clipped_gaussian_log_prob": clipped_gradient_without_sigma},
    "clipped_log_of_one_minus_cdf": {"clipped_gaussian_log_prob": clipped_log_of_one_minus_cdf},
}

FIRST_FAILURE = {
    "clipped_density_everywhere": r"upper bound a = 1.*density at the bound",
    "clipped_tails_swapped": r"upper bound a = 1.*mass of the other side",
    "clipped_gradient_without_sigma": r"−1/σ of the standardised bound",
    "clipped_log_of_one_minus_cdf": r"25 σ away",
}
