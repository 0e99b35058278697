"""Plausible mistakes in chapter 8: the value loss, its clipped form, and the signs in L^{CLIP+VF+S}."""

import numpy as np

from minippo.losses import clip_objective


def value_loss_without_half(values, value_targets):
    """Ê[(V − V^targ)²] with the gradient of the ½ version."""
    error = values - value_targets
    return float(np.mean(error**2)), error / len(values)


def value_loss_gradient_sign(values, value_targets):
    """∂L/∂V = (V^targ − V)/n: the sign flipped."""
    error = values - value_targets
    return 0.5 * float(np.mean(error**2)), -error / len(values)


def value_loss_summed(values, value_targets):
    """Summed over the batch instead of averaged."""
    error = values - value_targets
    return 0.5 * float(np.sum(error**2)), error


def clipped_value_loss_min(values, value_targets, values_old, epsilon):
    """The smaller of the two errors: optimistic, the opposite of the pessimistic max."""
    error = values - value_targets
    clipped_error = values_old + np.clip(values - values_old, -epsilon, epsilon) - value_targets
    use_clipped = clipped_error**2 < error**2
    inside = np.abs(values - values_old) <= epsilon
    grad = np.where(use_clipped, np.where(inside, clipped_error, 0.0), error) / len(values)
    return 0.5 * float(np.mean(np.minimum(error**2, clipped_error**2))), grad


def clipped_value_loss_gradient_through_clip(values, value_targets, values_old, epsilon):
    """The right loss, but the clipped branch passes a gradient even outside the band, where it is flat."""
    error = values - value_targets
    clipped_error = values_old + np.clip(values - values_old, -epsilon, epsilon) - value_targets
    use_clipped = clipped_error**2 > error**2
    grad = np.where(use_clipped, clipped_error, error) / len(values)
    return 0.5 * float(np.mean(np.maximum(error**2, clipped_error**2))), grad


def clipped_value_loss_clips_the_value(values, value_targets, values_old, epsilon):
    """Clips V itself to [−ε, ε] instead of its change from V_old."""
    error = values - value_targets
    clipped_error = np.clip(values, -epsilon, epsilon) - value_targets
    use_clipped = clipped_error**2 > error**2
    inside = np.abs(values) <= epsilon
    grad = np.where(use_clipped, np.where(inside, clipped_error, 0.0), error) / len(values)
    return 0.5 * float(np.mean(np.maximum(error**2, clipped_error**2))), grad


def _parts(logp, logp_old, advantages, values, value_targets, epsilon):
    clip_value, grad_logp = clip_objective(logp, logp_old, advantages, epsilon)
    error = values - value_targets
    return clip_value, grad_logp, 0.5 * float(np.mean(error**2)), error / len(values)


def objective_adds_the_value_loss(logp, logp_old, advantages, values, value_targets, entropy, epsilon, c1, c2):
    """L^CLIP + c1 L^VF + c2 S: rewards a worse value fit."""
    clip_value, grad_logp, vf, vf_grad = _parts(logp, logp_old, advantages, values, value_targets, epsilon)
    n = len(logp)
    return clip_value + c1 * vf + c2 * float(np.mean(entropy)), grad_logp, c1 * vf_grad, np.full(n, c2 / n)


def objective_subtracts_the_entropy(logp, logp_old, advantages, values, value_targets, entropy, epsilon, c1, c2):
    """L^CLIP − c1 L^VF − c2 S: punishes exploration."""
    clip_value, grad_logp, vf, vf_grad = _parts(logp, logp_old, advantages, values, value_targets, epsilon)
    n = len(logp)
    return clip_value - c1 * vf - c2 * float(np.mean(entropy)), grad_logp, -c1 * vf_grad, np.full(n, -c2 / n)


def objective_value_gradient_without_c1(logp, logp_old, advantages, values, value_targets, entropy, epsilon, c1, c2):
    """The right value, but ∂L/∂V = −(V − V^targ)/n without its c1."""
    clip_value, grad_logp, vf, vf_grad = _parts(logp, logp_old, advantages, values, value_targets, epsilon)
    n = len(logp)
    return clip_value - c1 * vf + c2 * float(np.mean(entropy)), grad_logp, -vf_grad, np.full(n, c2 / n)


def objective_entropy_gradient_not_averaged(
    logp, logp_old, advantages, values, value_targets, entropy, epsilon, c1, c2
):
    """∂L/∂S_t = c2 instead of c2 / n."""
    clip_value, grad_logp, vf, vf_grad = _parts(logp, logp_old, advantages, values, value_targets, epsilon)
    n = len(logp)
    return clip_value - c1 * vf + c2 * float(np.mean(entropy)), grad_logp, -c1 * vf_grad, np.full(n, c2)


VARIANTS = {
    "value_loss_without_half": {"value_loss": value_loss_without_half},
    "value_loss_gradient_sign": {"value_loss": value_loss_gradient_sign},
    "value_loss_summed": {"value_loss": value_loss_summed},
    "clipped_value_loss_min": {"clipped_value_loss": clipped_value_loss_min},
    "clipped_value_loss_gradient_through_clip": {"clipped_value_loss": clipped_value_loss_gradient_through_clip},
    "clipped_value_loss_clips_the_value": {"clipped_value_loss": clipped_value_loss_clips_the_value},
    "objective_adds_the_value_loss": {"clip_vf_s_objective": objective_adds_the_value_loss},
    "objective_subtracts_the_entropy": {"clip_vf_s_objective": objective_subtracts_the_entropy},
    "objective_value_gradient_without_c1": {"clip_vf_s_objective": objective_value_gradient_without_c1},
    "objective_entropy_gradient_not_averaged": {"clip_vf_s_objective": objective_entropy_gradient_not_averaged},
}


def clipped_value_loss_epsilon_fixed(values, value_targets, values_old, epsilon):
    """ε = 0.2 written into the code."""
    error = values - value_targets
    clipped_error = values_old + np.clip(values - values_old, -0.2, 0.2) - value_targets
    use_clipped = clipped_error**2 > error**2
    inside = np.abs(values - values_old) <= 0.2
    grad = np.where(use_clipped, np.where(inside, clipped_error, 0.0), error) / len(values)
    return 0.5 * float(np.mean(np.maximum(error**2, clipped_error**2))), grad


def clipped_value_loss_around_the_target(values, value_targets, values_old, epsilon):
    """Clips V around V^targ instead of around V_old."""
    error = values - value_targets
    clipped_error = np.clip(values - value_targets, -epsilon, epsilon)
    use_clipped = clipped_error**2 > error**2
    grad = np.where(use_clipped, 0.0, error) / len(values)
    return 0.5 * float(np.mean(np.maximum(error**2, clipped_error**2))), grad


def objective_epsilon_fixed(logp, logp_old, advantages, values, value_targets, entropy, epsilon, c1, c2):
    """ε = 0.2 written into the call to L^CLIP."""
    clip_value, grad_logp, vf, vf_grad = _parts(logp, logp_old, advantages, values, value_targets, 0.2)
    n = len(logp)
    return clip_value - c1 * vf + c2 * float(np.mean(entropy)), grad_logp, -c1 * vf_grad, np.full(n, c2 / n)


VARIANTS.update(
    {
        "clipped_value_loss_epsilon_fixed": {"clipped_value_loss": clipped_value_loss_epsilon_fixed},
        "clipped_value_loss_around_the_target": {"clipped_value_loss": clipped_value_loss_around_the_target},
        "objective_epsilon_fixed": {"clip_vf_s_objective": objective_epsilon_fixed},
    }
)

FIRST_FAILURE = {
    "clipped_value_loss_min": r"V moved 0\.5 > ε away.*the clipped loss is pessimistic, it takes the max\?$",
    "clipped_value_loss_around_the_target": r", not [-\d.]+: V clipped around V\^targ instead of around V_old",
    "clipped_value_loss_clips_the_value": r", not [-\d.]+: V itself clipped to \[−ε, ε\]",
    "clipped_value_loss_gradient_through_clip": r"V\^clip is a constant",
    "clipped_value_loss_epsilon_fixed": r"ε = 0\.4.*ε fixed at 0\.2",
    "objective_epsilon_fixed": r"ε = 0\.35.*ε fixed at 0\.2",
    "objective_adds_the_value_loss": r"value loss enters with −c1|the value loss added",
    "objective_subtracts_the_entropy": r"the bonus enters with \+c2|entropy bonus subtracted",
}


# the transfer task


def huber_gradient_unclipped(values, value_targets, delta):
    """The loss right, the gradient the squared error's, e / n, everywhere."""
    error = values - value_targets
    loss = np.where(np.abs(error) <= delta, 0.5 * error**2, delta * (np.abs(error) - 0.5 * delta))
    return float(np.mean(loss)), error / len(values)


def huber_line_without_offset(values, value_targets, delta):
    """The linear part δ |e|, which does not meet the parabola at |e| = δ."""
    error = values - value_targets
    loss = np.where(np.abs(error) <= delta, 0.5 * error**2, delta * np.abs(error))
    return float(np.mean(loss)), np.clip(error, -delta, delta) / len(values)


def huber_gradient_sign_only(values, value_targets, delta):
    """Beyond δ, the gradient sign(e) / n, without the line's slope δ."""
    error = values - value_targets
    loss = np.where(np.abs(error) <= delta, 0.5 * error**2, delta * (np.abs(error) - 0.5 * delta))
    return float(np.mean(loss)), np.where(np.abs(error) <= delta, error, np.sign(error)) / len(values)


def huber_summed(values, value_targets, delta):
    """Summed over the batch, loss and gradient."""
    error = values - value_targets
    loss = np.where(np.abs(error) <= delta, 0.5 * error**2, delta * (np.abs(error) - 0.5 * delta))
    return float(np.sum(loss)), np.clip(error, -delta, delta)


VARIANTS.update(
    {
        "huber_gradient_unclipped": {"huber_value_loss": huber_gradient_unclipped},
        "huber_line_without_offset": {"huber_value_loss": huber_line_without_offset},
        "huber_gradient_sign_only": {"huber_value_loss": huber_gradient_sign_only},
        "huber_summed": {"huber_value_loss": huber_summed},
    }
)
FIRST_FAILURE.update(
    {
        "huber_gradient_unclipped": r"e = 3\.0 .*gradient e, unclipped",
        "huber_line_without_offset": r"e = 3\.0 .*without the −½δ²",
        "huber_gradient_sign_only": r"without the line's slope δ",
        "huber_summed": r"mean Huber loss.*a sum over the batch where the mean belongs",
    }
)
