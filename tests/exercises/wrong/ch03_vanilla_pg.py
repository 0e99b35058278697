"""Plausible mistakes in chapter 3: L^PG's gradient and advantage normalisation."""

import numpy as np


def pg_objective_summed_gradient(logp, advantages):
    """The mean as the value but the gradient of the sum (Â_t, not Â_t / n)."""
    return float(np.mean(logp * advantages)), np.asarray(advantages, dtype=np.float64).copy()


def pg_objective_as_a_loss(logp, advantages):
    """−L^PG, the loss to minimise, where the contract asks for the objective."""
    return -float(np.mean(logp * advantages)), -advantages / len(logp)


def pg_objective_gradient_times_logp(logp, advantages):
    """log π_t Â_t / n as the gradient, as if differentiating twice."""
    return float(np.mean(logp * advantages)), logp * advantages / len(logp)


def normalize_without_epsilon(advantages):
    """No 1e-8: equal advantages give 0/0 = NaN."""
    if len(advantages) < 2:
        return advantages.copy()
    with np.errstate(invalid="ignore", divide="ignore"):
        return (advantages - advantages.mean()) / advantages.std()


def normalize_in_place(advantages):
    """Right numbers, written over the caller's array."""
    if len(advantages) > 1:
        advantages -= advantages.mean()
        advantages /= advantages.std() + 1e-8
    return advantages


def normalize_scale_only(advantages):
    """Divides by the standard deviation but keeps the mean: no baseline."""
    if len(advantages) < 2:
        return advantages.copy()
    return advantages / (advantages.std() + 1e-8)


def normalize_single_sample_to_zero(advantages):
    """Normalises a batch of one too, turning its advantage into 0."""
    return (advantages - advantages.mean()) / (advantages.std() + 1e-8)


def normalize_by_variance(advantages):
    """Divides by the variance instead of the standard deviation."""
    if len(advantages) < 2:
        return advantages.copy()
    return (advantages - advantages.mean()) / (advantages.var() + 1e-8)


VARIANTS = {
    "pg_objective_summed_gradient": {"pg_objective": pg_objective_summed_gradient},
    "pg_objective_as_a_loss": {"pg_objective": pg_objective_as_a_loss},
    "pg_objective_gradient_times_logp": {"pg_objective": pg_objective_gradient_times_logp},
    "normalize_without_epsilon": {"normalize_advantages": normalize_without_epsilon},
    "normalize_in_place": {"normalize_advantages": normalize_in_place},
    "normalize_scale_only": {"normalize_advantages": normalize_scale_only},
    "normalize_single_sample_to_zero": {"normalize_advantages": normalize_single_sample_to_zero},
    "normalize_by_variance": {"normalize_advantages": normalize_by_variance},
}


def normalize_sample_std(advantages):
    """Divides by the sample standard deviation (ddof = 1) where the contract says np.std."""
    if len(advantages) < 2:
        return advantages.copy()
    return (advantages - advantages.mean()) / (advantages.std(ddof=1) + 1e-8)


def normalize_single_returns_input(advantages):
    """Returns the caller's own array for a batch of one, not a copy."""
    if len(advantages) < 2:
        return advantages
    return (advantages - advantages.mean()) / (advantages.std() + 1e-8)


def pg_objective_value_as_array(logp, advantages):
    """The value as a one-element array instead of a float."""
    return np.array([np.mean(logp * advantages)]), advantages / len(logp)


def pg_objective_integer_length(logp, advantages):
    """Right numbers, but the gradient in float32 (advantages cast down to save memory)."""
    return float(np.mean(logp * advantages)), (advantages / len(logp)).astype(np.float32)


def normalize_epsilon_inside_the_root(advantages):
    """√(var + 1e-8) for the scale: the 1e-8 inside the square root, not added to the standard deviation."""
    if len(advantages) < 2:
        return advantages.copy()
    return (advantages - advantages.mean()) / np.sqrt(advantages.var() + 1e-8)


VARIANTS.update(
    {
        "normalize_epsilon_inside_the_root": {"normalize_advantages": normalize_epsilon_inside_the_root},
        "normalize_sample_std": {"normalize_advantages": normalize_sample_std},
        "normalize_single_returns_input": {"normalize_advantages": normalize_single_returns_input},
        "pg_objective_value_as_array": {"pg_objective": pg_objective_value_as_array},
        "pg_objective_float32_gradient": {"pg_objective": pg_objective_integer_length},
    }
)

FIRST_FAILURE = {
    "normalize_epsilon_inside_the_root": r"tiny spread.*inside the square root",
    "normalize_sample_std": r"ddof = 0",
    "normalize_single_returns_input": r"returned one of its inputs",
    "pg_objective_value_as_array": r"single number",
    "pg_objective_float32_gradient": r"float64.*not float32",
    "normalize_in_place": r"changed its input",
}


# the transfer task


def _linear_parts(features, theta, actions):
    logits = features @ theta
    log_probs = logits - np.log(np.exp(logits).sum(axis=1, keepdims=True))
    rows = np.arange(len(actions))
    score = -np.exp(log_probs)
    score[rows, actions] += 1.0
    return log_probs[rows, actions], score


def linear_pg_onehot_only(features, theta, actions, advantages):
    """The score without its −π term: as if log π(a|s) were the logit s θ[:, a]."""
    logp, _ = _linear_parts(features, theta, actions)
    onehot = np.zeros((len(actions), theta.shape[1]))
    onehot[np.arange(len(actions)), actions] = 1.0
    return float(np.mean(logp * advantages)), features.T @ (onehot * advantages[:, None]) / len(actions)


def linear_pg_summed(features, theta, actions, advantages):
    """The gradient summed over the batch, the value averaged."""
    logp, score = _linear_parts(features, theta, actions)
    return float(np.mean(logp * advantages)), features.T @ (score * advantages[:, None])


def linear_pg_of_the_probability(features, theta, actions, advantages):
    """The gradient of π(a|s) Â instead of log π(a|s) Â: the score times π(a|s)."""
    logp, score = _linear_parts(features, theta, actions)
    weight = np.exp(logp) * advantages
    return float(np.mean(logp * advantages)), features.T @ (score * weight[:, None]) / len(actions)


def linear_pg_transposed_product(features, theta, actions, advantages):
    """The outer product taken the other way round and transposed back: (score Â)ᵀ x / n, reshaped to (d, k)."""
    logp, score = _linear_parts(features, theta, actions)
    wrong = (score * advantages[:, None]).T @ features / len(actions)
    return float(np.mean(logp * advantages)), wrong.reshape(theta.shape)


VARIANTS.update(
    {
        "linear_pg_onehot_only": {"linear_softmax_policy_gradient": linear_pg_onehot_only},
        "linear_pg_summed": {"linear_softmax_policy_gradient": linear_pg_summed},
        "linear_pg_of_the_probability": {"linear_softmax_policy_gradient": linear_pg_of_the_probability},
        "linear_pg_transposed_product": {"linear_softmax_policy_gradient": linear_pg_transposed_product},
    }
)
FIRST_FAILURE.update(
    {
        "linear_pg_onehot_only": r"without its −π term",
        "linear_pg_summed": r"7 = n times too large everywhere",
        "linear_pg_of_the_probability": r"gradient of π instead of log π",
        "linear_pg_transposed_product": r"the outer product taken as \(score Â\)ᵀ x",
    }
)
