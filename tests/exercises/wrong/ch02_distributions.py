"""Plausible mistakes in chapter 2: log-probabilities, entropies and their gradients."""

import numpy as np

LOG_2PI = float(np.log(2.0 * np.pi))


def softmax_unshifted(logits):
    e = np.exp(logits)
    return e / e.sum(axis=-1, keepdims=True)


def softmax(logits):
    e = np.exp(logits - logits.max(axis=-1, keepdims=True))
    return e / e.sum(axis=-1, keepdims=True)


def log_softmax_unshifted(logits):
    """z − log Σ exp z without subtracting the maximum: exp(1000) overflows."""
    with np.errstate(over="ignore", invalid="ignore"):
        return logits - np.log(np.exp(logits).sum(axis=-1, keepdims=True))


def log_softmax_shift_by_mean(logits):
    """Shifts by the row's mean instead of its maximum, which still overflows when the logits are far apart."""
    shifted = logits - logits.mean(axis=-1, keepdims=True)
    with np.errstate(over="ignore", invalid="ignore"):
        return shifted - np.log(np.exp(shifted).sum(axis=-1, keepdims=True))


def log_softmax_forgets_the_shift_in_the_result(logits):
    """Computes log Σ exp of the shifted logits but subtracts it from the unshifted ones (off by max z)."""
    shifted = logits - logits.max(axis=-1, keepdims=True)
    return logits - np.log(np.exp(shifted).sum(axis=-1, keepdims=True))


def log_softmax_log_of_softmax(logits):
    """log of the (shifted) softmax: a probability that underflows to 0 gives −inf."""
    with np.errstate(divide="ignore"):
        return np.log(softmax(logits))


def categorical_log_prob_naive(logits, actions):
    """log of softmax, without subtracting the maximum first: exp(1000) overflows."""
    with np.errstate(all="ignore"):
        return np.log(softmax_unshifted(logits)[np.arange(len(actions)), actions])


def categorical_log_prob_log_of_softmax(logits, actions):
    """Shifted softmax, then log: an action with probability below 1e-308 gets log 0 = −inf."""
    with np.errstate(divide="ignore"):
        return np.log(softmax(logits)[np.arange(len(actions)), actions])


def categorical_log_prob_returns_logit(logits, actions):
    """The logit z_a itself, forgetting the normaliser log Σ exp z."""
    return logits[np.arange(len(actions)), actions].astype(np.float64)


def categorical_log_prob_backward_onehot_only(logits, actions, grad_logp):
    """Only the 1[j = a] part, forgetting −π_j."""
    grad = np.zeros_like(logits, dtype=np.float64)
    grad[np.arange(len(actions)), actions] = grad_logp
    return grad


def categorical_log_prob_backward_sign(logits, actions, grad_logp):
    """π_j − 1[j = a]: the sign flipped."""
    grad = softmax(logits) * grad_logp[:, None]
    grad[np.arange(len(actions)), actions] -= grad_logp
    return grad


def categorical_log_prob_backward_ignores_upstream(logits, actions, grad_logp):
    """1[j = a] − π_j without multiplying by ∂L/∂ log π."""
    grad = -softmax(logits)
    grad[np.arange(len(actions)), actions] += 1.0
    return grad


def categorical_entropy_zero_times_log_zero(logits):
    """−Σ p log p with p from the softmax: a probability that underflows to 0 gives 0 · (−inf) = NaN."""
    p = softmax(logits)
    with np.errstate(divide="ignore", invalid="ignore"):
        return -(p * np.log(p)).sum(axis=-1)


def categorical_entropy_sign(logits):
    """Σ p log p, the negative of the entropy."""
    log_p = logits - logits.max(axis=-1, keepdims=True)
    log_p = log_p - np.log(np.exp(log_p).sum(axis=-1, keepdims=True))
    return (np.exp(log_p) * log_p).sum(axis=-1)


def categorical_entropy_backward_without_s(logits, grad_entropy):
    """−π_j log π_j only, forgetting the + S that the normalisation brings."""
    p = softmax(logits)
    return -p * np.log(p) * grad_entropy[:, None]


def categorical_entropy_backward_wrt_probs(logits, grad_entropy):
    """∂S/∂π_j = −(log π_j + 1), the gradient with respect to the probabilities, not the logits."""
    p = softmax(logits)
    return -(np.log(p) + 1.0) * grad_entropy[:, None]


def gaussian_log_prob_no_log_std(mean, log_std, actions):
    """Drops the −Σ log σ term."""
    z = (actions - mean) / np.exp(log_std)
    return -0.5 * (z * z).sum(axis=-1) - 0.5 * mean.shape[-1] * LOG_2PI


def gaussian_log_prob_std_for_log_std(mean, log_std, actions):
    """−Σ σ where −Σ log σ belongs."""
    z = (actions - mean) / np.exp(log_std)
    return -0.5 * (z * z).sum(axis=-1) - np.exp(log_std).sum() - 0.5 * mean.shape[-1] * LOG_2PI


def gaussian_log_prob_no_constant(mean, log_std, actions):
    """Drops the −(d/2) log 2π constant (harmless for the gradient, wrong as a log-probability)."""
    z = (actions - mean) / np.exp(log_std)
    return -0.5 * (z * z).sum(axis=-1) - log_std.sum()


def gaussian_log_prob_divides_by_variance(mean, log_std, actions):
    """(a − μ)/σ² squared, dividing by the variance where the standard deviation belongs."""
    z = (actions - mean) / np.exp(2 * log_std)
    return -0.5 * (z * z).sum(axis=-1) - log_std.sum() - 0.5 * mean.shape[-1] * LOG_2PI


def gaussian_log_prob_backward_no_minus_one(mean, log_std, actions, grad_logp):
    """∂ log π/∂ log σ = z² without the −1 that the −log σ term gives."""
    std = np.exp(log_std)
    z = (actions - mean) / std
    return (z / std) * grad_logp[:, None], (z * z * grad_logp[:, None]).sum(axis=0)


def gaussian_log_prob_backward_not_summed(mean, log_std, actions, grad_logp):
    """∂L/∂ log σ left per sample, shape (n, d), although log σ is shared by all states."""
    std = np.exp(log_std)
    z = (actions - mean) / std
    return (z / std) * grad_logp[:, None], (z * z - 1.0) * grad_logp[:, None]


def gaussian_log_prob_backward_mean_over_std(mean, log_std, actions, grad_logp):
    """∂ log π/∂μ = (a − μ)/σ, one σ short."""
    std = np.exp(log_std)
    z = (actions - mean) / std
    return z * grad_logp[:, None], ((z * z - 1.0) * grad_logp[:, None]).sum(axis=0)


def gaussian_entropy_without_e(mean, log_std):
    """Σ (log σ + ½ log 2π), missing the ½ of ½ log 2πe."""
    return np.full(mean.shape[0], float(log_std.sum() + 0.5 * mean.shape[-1] * LOG_2PI))


def gaussian_entropy_scalar(mean, log_std):
    """The right number, but one float instead of one per state."""
    return float(log_std.sum() + 0.5 * mean.shape[-1] * (LOG_2PI + 1.0))


def gaussian_entropy_of_variance(mean, log_std):
    """Uses log σ² = 2 log σ where log σ belongs."""
    return np.full(mean.shape[0], float(2 * log_std.sum() + 0.5 * mean.shape[-1] * (LOG_2PI + 1.0)))


def gaussian_entropy_backward_ignores_upstream(mean, log_std, grad_entropy):
    """∂S/∂ log σ = 1 returned as it is, not multiplied by Σ ∂L/∂S."""
    return np.zeros_like(mean), np.ones_like(log_std)


def gaussian_entropy_backward_mean_over_batch(mean, log_std, grad_entropy):
    """The upstream gradients averaged instead of summed over the batch."""
    return np.zeros_like(mean), np.full(log_std.shape, float(np.mean(grad_entropy)))


VARIANTS = {
    "log_softmax_unshifted": {"log_softmax": log_softmax_unshifted},
    "log_softmax_shift_by_mean": {"log_softmax": log_softmax_shift_by_mean},
    "log_softmax_forgets_the_shift_in_the_result": {"log_softmax": log_softmax_forgets_the_shift_in_the_result},
    "log_softmax_log_of_softmax": {"log_softmax": log_softmax_log_of_softmax},
    "categorical_log_prob_naive": {"categorical_log_prob": categorical_log_prob_naive},
    "categorical_log_prob_log_of_softmax": {"categorical_log_prob": categorical_log_prob_log_of_softmax},
    "categorical_log_prob_returns_logit": {"categorical_log_prob": categorical_log_prob_returns_logit},
    "categorical_log_prob_backward_onehot_only": {
        "categorical_log_prob_backward": categorical_log_prob_backward_onehot_only
    },
    "categorical_log_prob_backward_sign": {"categorical_log_prob_backward": categorical_log_prob_backward_sign},
    "categorical_log_prob_backward_ignores_upstream": {
        "categorical_log_prob_backward": categorical_log_prob_backward_ignores_upstream
    },
    "categorical_entropy_zero_times_log_zero": {"categorical_entropy": categorical_entropy_zero_times_log_zero},
    "categorical_entropy_sign": {"categorical_entropy": categorical_entropy_sign},
    "categorical_entropy_backward_without_s": {"categorical_entropy_backward": categorical_entropy_backward_without_s},
    "categorical_entropy_backward_wrt_probs": {"categorical_entropy_backward": categorical_entropy_backward_wrt_probs},
    "gaussian_log_prob_no_log_std": {"gaussian_log_prob": gaussian_log_prob_no_log_std},
    "gaussian_log_prob_std_for_log_std": {"gaussian_log_prob": gaussian_log_prob_std_for_log_std},
    "gaussian_log_prob_no_constant": {"gaussian_log_prob": gaussian_log_prob_no_constant},
    "gaussian_log_prob_divides_by_variance": {"gaussian_log_prob": gaussian_log_prob_divides_by_variance},
    "gaussian_log_prob_backward_no_minus_one": {"gaussian_log_prob_backward": gaussian_log_prob_backward_no_minus_one},
    "gaussian_log_prob_backward_not_summed": {"gaussian_log_prob_backward": gaussian_log_prob_backward_not_summed},
    "gaussian_log_prob_backward_mean_over_std": {
        "gaussian_log_prob_backward": gaussian_log_prob_backward_mean_over_std
    },
    "gaussian_entropy_without_e": {"gaussian_entropy": gaussian_entropy_without_e},
    "gaussian_entropy_scalar": {"gaussian_entropy": gaussian_entropy_scalar},
    "gaussian_entropy_of_variance": {"gaussian_entropy": gaussian_entropy_of_variance},
    "gaussian_entropy_backward_ignores_upstream": {
        "gaussian_entropy_backward": gaussian_entropy_backward_ignores_upstream
    },
    "gaussian_entropy_backward_mean_over_batch": {
        "gaussian_entropy_backward": gaussian_entropy_backward_mean_over_batch
    },
}


def categorical_log_prob_backward_unshifted(logits, actions, grad_logp):
    """Right formula, with a softmax that does not subtract the max: exp(1000) overflows to inf, inf/inf is NaN."""
    with np.errstate(over="ignore", invalid="ignore"):
        grad = -softmax_unshifted(logits) * grad_logp[:, None]
    grad[np.arange(len(actions)), actions] += grad_logp
    return grad


def categorical_entropy_backward_unshifted(logits, grad_entropy):
    """Right formula, with an unshifted softmax."""
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        p = softmax_unshifted(logits)
        log_p = np.log(p)
        entropy = -(p * log_p).sum(axis=-1)
        return -p * (log_p + entropy[:, None]) * grad_entropy[:, None]


def gaussian_log_prob_float32(mean, log_std, actions):
    """Right numbers, computed in float32."""
    z = ((actions - mean) / np.exp(log_std)).astype(np.float32)
    return -0.5 * (z * z).sum(axis=-1) - np.float32(log_std.sum() + 0.5 * mean.shape[-1] * LOG_2PI)


def gaussian_log_prob_mean_over_dimensions(mean, log_std, actions):
    """Averages the per-dimension terms over d instead of summing them (the log of a product is a sum)."""
    z = (actions - mean) / np.exp(log_std)
    return (-0.5 * z * z - log_std - 0.5 * LOG_2PI).mean(axis=-1)


def log_softmax_wrong_axis(logits):
    """Normalises over the batch (axis 0) instead of over the actions."""
    shifted = logits - logits.max(axis=0, keepdims=True)
    return shifted - np.log(np.exp(shifted).sum(axis=0, keepdims=True))


VARIANTS.update(
    {
        "categorical_log_prob_backward_unshifted": {
            "categorical_log_prob_backward": categorical_log_prob_backward_unshifted
        },
        "categorical_entropy_backward_unshifted": {
            "categorical_entropy_backward": categorical_entropy_backward_unshifted
        },
        "gaussian_log_prob_float32": {"gaussian_log_prob": gaussian_log_prob_float32},
        "gaussian_log_prob_mean_over_dimensions": {"gaussian_log_prob": gaussian_log_prob_mean_over_dimensions},
        "log_softmax_wrong_axis": {"log_softmax": log_softmax_wrong_axis},
    }
)

FIRST_FAILURE = {
    "categorical_log_prob_backward_unshifted": r"categorical_log_prob_backward.*±1000",
    "categorical_entropy_backward_unshifted": r"categorical_entropy_backward.*±1000",
    "gaussian_log_prob_float32": r"float64.*not float32",
    "log_softmax_unshifted": r"±1000",
    "gaussian_log_prob_no_log_std": r"off by the same .* in every row",
    "gaussian_log_prob_no_constant": r"off by the same .* in every row",
}


def log_softmax_global_max(logits):
    """Subtracts the largest logit of the whole batch, not of each row: a row far below it underflows."""
    shifted = logits - logits.max()
    with np.errstate(divide="ignore"):
        return shifted - np.log(np.exp(shifted).sum(axis=-1, keepdims=True))


def log_softmax_without_keepdims(logits):
    """The row maximum without keepdims: (n, k) − (n,) does not broadcast (or does, wrongly, when n = k)."""
    shifted = logits - logits.max(axis=-1)
    return shifted - np.log(np.exp(shifted).sum(axis=-1))


VARIANTS.update(
    {
        "log_softmax_global_max": {"log_softmax": log_softmax_global_max},
        "log_softmax_without_keepdims": {"log_softmax": log_softmax_without_keepdims},
    }
)
FIRST_FAILURE.update(
    {
        "log_softmax_global_max": r"±1000",
        "log_softmax_without_keepdims": r"could not be broadcast",
    }
)


# the transfer task


def _tempered_parts(logits, temperature, actions):
    scaled = logits / temperature
    shifted = scaled - scaled.max(axis=1, keepdims=True)
    log_probs = shifted - np.log(np.exp(shifted).sum(axis=1, keepdims=True))
    score = -np.exp(log_probs)
    rows = np.arange(len(actions))
    score[rows, actions] += 1.0
    return log_probs[rows, actions], score


def tempered_no_inner_derivative(logits, temperature, actions):
    """∂ log π/∂z as chapter 2's score, without the 1/τ that z/τ brings."""
    logp, score = _tempered_parts(logits, temperature, actions)
    return logp, score, -(score * logits).sum(axis=1) / temperature**2


def tempered_temperature_sign(logits, temperature, actions):
    """∂ log π/∂τ with the sign flipped (the derivative of z/τ taken as +z/τ²)."""
    logp, score = _tempered_parts(logits, temperature, actions)
    return logp, score / temperature, (score * logits).sum(axis=1) / temperature**2


def tempered_temperature_without_the_mean(logits, temperature, actions):
    """∂ log π/∂τ = −z_a/τ², the normaliser's own dependence on τ forgotten."""
    logp, score = _tempered_parts(logits, temperature, actions)
    return logp, score / temperature, -logits[np.arange(len(actions)), actions] / temperature**2


def tempered_naive_softmax(logits, temperature, actions):
    """log of a softmax computed without subtracting the maximum: overflows for logits of 1000."""
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        probs = np.exp(logits / temperature) / np.exp(logits / temperature).sum(axis=1, keepdims=True)
        rows = np.arange(len(actions))
        score = -probs
        score[rows, actions] += 1.0
        return np.log(probs[rows, actions]), score / temperature, -(score * logits).sum(axis=1) / temperature**2


VARIANTS.update(
    {
        "tempered_no_inner_derivative": {"tempered_categorical_log_prob": tempered_no_inner_derivative},
        "tempered_temperature_sign": {"tempered_categorical_log_prob": tempered_temperature_sign},
        "tempered_temperature_without_the_mean": {
            "tempered_categorical_log_prob": tempered_temperature_without_the_mean
        },
        "tempered_naive_softmax": {"tempered_categorical_log_prob": tempered_naive_softmax},
    }
)
FIRST_FAILURE.update(
    {
        "tempered_no_inner_derivative": r"∂ log π/∂z at τ = 0\.5 .*(twice the expected everywhere|factor)",
        "tempered_temperature_sign": r"∂ log π/∂τ has the opposite sign",
        "tempered_temperature_without_the_mean": r"normaliser log Σ exp\(z/τ\) depends on τ too",
        "tempered_naive_softmax": r"logits of ±1000",
    }
)
