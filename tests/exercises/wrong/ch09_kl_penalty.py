"""Plausible mistakes in chapter 9: the KL, its gradient, the penalised surrogate and eq. 8's β rule."""

import numpy as np


def _log_softmax(logits):
    shifted = logits - logits.max(axis=-1, keepdims=True)
    return shifted - np.log(np.exp(shifted).sum(axis=-1, keepdims=True))


def kl_reversed(logits_old, logits):
    """KL[π ‖ π_old]: the new policy first."""
    log_old, log_new = _log_softmax(logits_old), _log_softmax(logits)
    return (np.exp(log_new) * (log_new - log_old)).sum(axis=-1)


def kl_log_of_softmax(logits_old, logits):
    """log of the softmax probabilities: a probability that underflows gives log 0 and NaN."""
    p = np.exp(_log_softmax(logits_old))
    q = np.exp(_log_softmax(logits))
    with np.errstate(divide="ignore", invalid="ignore"):
        return (p * (np.log(p) - np.log(q))).sum(axis=-1)


def kl_without_weights(logits_old, logits):
    """Σ (log π_old − log π), forgetting to weight by π_old."""
    return (_log_softmax(logits_old) - _log_softmax(logits)).sum(axis=-1)


def kl_backward_sign(logits_old, logits, grad_kl):
    """π_old − π: the sign flipped."""
    return (np.exp(_log_softmax(logits_old)) - np.exp(_log_softmax(logits))) * grad_kl[:, None]


def kl_backward_old_logits(logits_old, logits, grad_kl):
    """The gradient with respect to the old logits, which are constants."""
    p, q = np.exp(_log_softmax(logits_old)), np.exp(_log_softmax(logits))
    kl = (p * (np.log(p) - np.log(q))).sum(axis=-1)
    return p * (np.log(p) - np.log(q) - kl[:, None]) * grad_kl[:, None]


def penalty_added(logp, logp_old, advantages, kl, beta):
    """r Â + β KL: rewards moving away from π_old."""
    n, ratio = len(logp), np.exp(logp - logp_old)
    return float(np.mean(ratio * advantages + beta * kl)), ratio * advantages / n, np.full(n, beta / n)


def penalty_gradient_not_averaged(logp, logp_old, advantages, kl, beta):
    """∂L/∂KL_t = −β instead of −β/n."""
    n, ratio = len(logp), np.exp(logp - logp_old)
    return float(np.mean(ratio * advantages - beta * kl)), ratio * advantages / n, np.full(n, -beta)


def penalty_on_the_log_ratio(logp, logp_old, advantages, kl, beta):
    """Ê[log r Â − β KL], the log-ratio in place of the ratio."""
    n = len(logp)
    value = float(np.mean((logp - logp_old) * advantages - beta * kl))
    return value, advantages / n, np.full(n, -beta / n)


def beta_rule_swapped(beta, kl, kl_target):
    """Doubles β when the KL is small and halves it when large."""
    if kl < kl_target / 1.5:
        return beta * 2.0
    if kl > kl_target * 1.5:
        return beta / 2.0
    return beta


def beta_rule_by_1_5(beta, kl, kl_target):
    """Scales β by 1.5 (the threshold factor) instead of 2."""
    if kl < kl_target / 1.5:
        return beta / 1.5
    if kl > kl_target * 1.5:
        return beta * 1.5
    return beta


def beta_rule_against_the_target(beta, kl, kl_target):
    """Compares d with d_targ itself: β changes after almost every update."""
    if kl < kl_target:
        return beta / 2.0
    if kl > kl_target:
        return beta * 2.0
    return beta


def beta_rule_inclusive(beta, kl, kl_target):
    """≤ and ≥ where eq. 8 says < and >: β moves at the thresholds themselves."""
    if kl <= kl_target / 1.5:
        return beta / 2.0
    if kl >= kl_target * 1.5:
        return beta * 2.0
    return beta


def beta_rule_resets(beta, kl, kl_target):
    """Sets β to ½ or 2 instead of scaling the current β."""
    if kl < kl_target / 1.5:
        return 0.5
    if kl > kl_target * 1.5:
        return 2.0
    return beta


VARIANTS = {
    "kl_reversed": {"categorical_kl": kl_reversed},
    "kl_log_of_softmax": {"categorical_kl": kl_log_of_softmax},
    "kl_without_weights": {"categorical_kl": kl_without_weights},
    "kl_backward_sign": {"categorical_kl_backward": kl_backward_sign},
    "kl_backward_old_logits": {"categorical_kl_backward": kl_backward_old_logits},
    "penalty_added": {"kl_penalty_objective": penalty_added},
    "penalty_gradient_not_averaged": {"kl_penalty_objective": penalty_gradient_not_averaged},
    "penalty_on_the_log_ratio": {"kl_penalty_objective": penalty_on_the_log_ratio},
    "beta_rule_swapped": {"adaptive_beta": beta_rule_swapped},
    "beta_rule_by_1_5": {"adaptive_beta": beta_rule_by_1_5},
    "beta_rule_against_the_target": {"adaptive_beta": beta_rule_against_the_target},
    "beta_rule_inclusive": {"adaptive_beta": beta_rule_inclusive},
    "beta_rule_resets": {"adaptive_beta": beta_rule_resets},
}


def kl_backward_unshifted(logits_old, logits, grad_kl):
    """π − π_old with softmaxes that do not subtract the max: NaN for logits near ±1000."""
    with np.errstate(over="ignore", invalid="ignore"):
        p = np.exp(logits_old) / np.exp(logits_old).sum(axis=-1, keepdims=True)
        q = np.exp(logits) / np.exp(logits).sum(axis=-1, keepdims=True)
    return (q - p) * grad_kl[:, None]


def penalty_beta_fixed(logp, logp_old, advantages, kl, beta):
    """β = 3 written into the gradient, whatever beta is passed."""
    n, ratio = len(logp), np.exp(logp - logp_old)
    return float(np.mean(ratio * advantages - beta * kl)), ratio * advantages / n, np.full(n, -3.0 / n)


def beta_rule_thresholds_of_2(beta, kl, kl_target):
    """The factor 2 used for the thresholds too: d < d_targ/2 and d > 2·d_targ instead of d_targ/1.5 and 1.5·d_targ."""
    if kl < kl_target / 2.0:
        return beta / 2.0
    if kl > kl_target * 2.0:
        return beta * 2.0
    return beta


VARIANTS.update(
    {
        "beta_rule_thresholds_of_2": {"adaptive_beta": beta_rule_thresholds_of_2},
        "kl_backward_unshifted": {"categorical_kl_backward": kl_backward_unshifted},
        "penalty_beta_fixed": {"kl_penalty_objective": penalty_beta_fixed},
    }
)

FIRST_FAILURE = {
    "kl_backward_unshifted": r"categorical_kl_backward.*±1000",
    "penalty_beta_fixed": r"β = 0\.25",
    "beta_rule_inclusive": r"exactly",
    "beta_rule_against_the_target": r"d = 2\.5 .*halved only below d_targ/1\.5\), β = 1 should become 1\.0, not 0\.5",
    "beta_rule_thresholds_of_2": r"d = 1\.99 .*should become 0\.5, not 1",
    "beta_rule_swapped": r"d = 0\.5 .*halved.*should become 0\.5, not 2",
    "beta_rule_by_1_5": r"should become 0\.5, not 0\.666667",
}


# the transfer task


def _kl_logs(logits_old, logits):
    def log_softmax(z):
        shifted = z - z.max(axis=1, keepdims=True)
        return shifted - np.log(np.exp(shifted).sum(axis=1, keepdims=True))

    return log_softmax(logits_old), log_softmax(logits)


def reverse_kl_forward_gradient(logits_old, logits, grad_kl):
    """The reverse KL's value with the forward KL's gradient π − π_old."""
    log_old, log_new = _kl_logs(logits_old, logits)
    probs = np.exp(log_new)
    return (probs * (log_new - log_old)).sum(axis=1), (probs - np.exp(log_old)) * grad_kl[:, None]


def reverse_kl_without_the_mean(logits_old, logits, grad_kl):
    """π_j (log π_j − log π_old,j): the −KL term, from the softmax's normaliser, forgotten."""
    log_old, log_new = _kl_logs(logits_old, logits)
    probs = np.exp(log_new)
    gap = log_new - log_old
    return (probs * gap).sum(axis=1), probs * gap * grad_kl[:, None]


def reverse_kl_forward_value(logits_old, logits, grad_kl):
    """KL[π_old ‖ π], chapter 9's order, with its gradient."""
    log_old, log_new = _kl_logs(logits_old, logits)
    probs_old = np.exp(log_old)
    return (probs_old * (log_old - log_new)).sum(axis=1), (np.exp(log_new) - probs_old) * grad_kl[:, None]


def reverse_kl_log_of_softmax(logits_old, logits, grad_kl):
    """np.log of a softmax computed without the max shift: NaN or infinite for logits of ±1000."""
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        probs = np.exp(logits) / np.exp(logits).sum(axis=1, keepdims=True)
        probs_old = np.exp(logits_old) / np.exp(logits_old).sum(axis=1, keepdims=True)
        gap = np.log(probs) - np.log(probs_old)
        kl = (probs * gap).sum(axis=1)
        return kl, probs * (gap - kl[:, None]) * grad_kl[:, None]


VARIANTS.update(
    {
        "reverse_kl_forward_gradient": {"reverse_kl_backward": reverse_kl_forward_gradient},
        "reverse_kl_without_the_mean": {"reverse_kl_backward": reverse_kl_without_the_mean},
        "reverse_kl_forward_value": {"reverse_kl_backward": reverse_kl_forward_value},
        "reverse_kl_log_of_softmax": {"reverse_kl_backward": reverse_kl_log_of_softmax},
    }
)
FIRST_FAILURE.update(
    {
        "reverse_kl_forward_gradient": r"gradient of KL\[π_old ‖ π\], not of KL\[π ‖ π_old\]",
        "reverse_kl_without_the_mean": r"without subtracting KL",
        "reverse_kl_forward_value": r"KL\[π_old ‖ π\], chapter 9's order",
        "reverse_kl_log_of_softmax": r"logits of ±1000",
    }
)
