"""Plausible mistakes in chapter 13: the Bradley–Terry loss and its gradient, and the KL-shaped per-token reward."""

import numpy as np


def bt_reversed(scores_preferred, scores_rejected):
    """−log σ(r_l − r_w): prefers the rejected answer."""
    n, margin = len(scores_preferred), scores_rejected - scores_preferred
    wrong = np.exp(-np.logaddexp(0.0, margin))
    return float(np.logaddexp(0.0, -margin).sum()) / n, wrong / n, -wrong / n


def bt_log_of_sigmoid(scores_preferred, scores_rejected):
    """log(σ(Δ)) computed directly: σ underflows to 0 for a margin of −1000 and the loss is infinite."""
    n, margin = len(scores_preferred), scores_preferred - scores_rejected
    with np.errstate(over="ignore", divide="ignore"):
        sigma = 1.0 / (1.0 + np.exp(-margin))
        loss = -float(np.log(sigma).sum()) / n
    return loss, -(1.0 - sigma) / n, (1.0 - sigma) / n


def bt_gradient_with_sigma_of_margin(scores_preferred, scores_rejected):
    """∂L/∂r_w = −σ(Δ)/n: the probability of the right answer where that of the wrong one belongs."""
    n, margin = len(scores_preferred), scores_preferred - scores_rejected
    right = np.exp(-np.logaddexp(0.0, -margin))
    return float(np.logaddexp(0.0, -margin).sum()) / n, -right / n, right / n


def bt_gradient_not_averaged(scores_preferred, scores_rejected):
    """The gradient of the sum, not of the mean."""
    n, margin = len(scores_preferred), scores_preferred - scores_rejected
    wrong = np.exp(-np.logaddexp(0.0, margin))
    return float(np.logaddexp(0.0, -margin).sum()) / n, -wrong, wrong


def bt_gradient_on_preferred_only(scores_preferred, scores_rejected):
    """Forgets that the rejected score is a variable too."""
    n, margin = len(scores_preferred), scores_preferred - scores_rejected
    wrong = np.exp(-np.logaddexp(0.0, margin))
    return float(np.logaddexp(0.0, -margin).sum()) / n, -wrong / n, np.zeros(n)


def _inside(logp, lengths):
    return np.arange(logp.shape[1])[None, :] < lengths[:, None]


def _last(logp, lengths):
    return np.arange(logp.shape[1])[None, :] == lengths[:, None] - 1


def rewards_kl_sign(logp, logp_ref, scores, lengths, beta):
    """+β (log π − log π_ref): pays the policy for moving away from the reference."""
    rewards = np.where(_inside(logp, lengths), beta * (logp - logp_ref), 0.0)
    return rewards + np.where(_last(logp, lengths), scores[:, None], 0.0)


def rewards_score_one_step_late(logp, logp_ref, scores, lengths, beta):
    """The score at t = length, one step after the last token (in the padding, or lost at T)."""
    steps = np.arange(logp.shape[1])[None, :]
    rewards = np.where(_inside(logp, lengths), -beta * (logp - logp_ref), 0.0)
    return rewards + np.where(steps == lengths[:, None], scores[:, None], 0.0)


def rewards_score_on_every_token(logp, logp_ref, scores, lengths, beta):
    """The score added at every token of the sequence instead of once at its end."""
    inside = _inside(logp, lengths)
    return np.where(inside, -beta * (logp - logp_ref) + scores[:, None], 0.0)


def rewards_penalty_on_padding(logp, logp_ref, scores, lengths, beta):
    """Charges the KL on the padding after the end too."""
    return -beta * (logp - logp_ref) + np.where(_last(logp, lengths), scores[:, None], 0.0)


def rewards_beta_on_the_score(logp, logp_ref, scores, lengths, beta):
    """−β (log π − log π_ref − R): the score scaled by β as well."""
    rewards = np.where(_inside(logp, lengths), -beta * (logp - logp_ref), 0.0)
    return rewards + np.where(_last(logp, lengths), beta * scores[:, None], 0.0)


def rewards_kl_at_the_end(logp, logp_ref, scores, lengths, beta):
    """The whole sequence's penalty −β Σ_t log π/π_ref paid at the last token only."""
    total = np.where(_inside(logp, lengths), logp - logp_ref, 0.0).sum(axis=1)
    return np.where(_last(logp, lengths), (scores - beta * total)[:, None], 0.0)


VARIANTS = {
    "bt_reversed": {"bradley_terry_loss": bt_reversed},
    "bt_log_of_sigmoid": {"bradley_terry_loss": bt_log_of_sigmoid},
    "bt_gradient_with_sigma_of_margin": {"bradley_terry_loss": bt_gradient_with_sigma_of_margin},
    "bt_gradient_not_averaged": {"bradley_terry_loss": bt_gradient_not_averaged},
    "bt_gradient_on_preferred_only": {"bradley_terry_loss": bt_gradient_on_preferred_only},
    "rewards_kl_sign": {"kl_shaped_rewards": rewards_kl_sign},
    "rewards_score_one_step_late": {"kl_shaped_rewards": rewards_score_one_step_late},
    "rewards_score_on_every_token": {"kl_shaped_rewards": rewards_score_on_every_token},
    "rewards_penalty_on_padding": {"kl_shaped_rewards": rewards_penalty_on_padding},
    "rewards_beta_on_the_score": {"kl_shaped_rewards": rewards_beta_on_the_score},
    "rewards_kl_at_the_end": {"kl_shaped_rewards": rewards_kl_at_the_end},
}


def rewards_score_by_column_index(logp, logp_ref, scores, lengths, beta):
    """rewards[:, lengths − 1] += scores: a column index for every row at once, so each sequence's score lands on every
    sequence, at every sequence's last position."""
    rewards = np.where(_inside(logp, lengths), -beta * (logp - logp_ref), 0.0)
    rewards[:, lengths - 1] += scores
    return rewards


VARIANTS["rewards_score_by_column_index"] = {"kl_shaped_rewards": rewards_score_by_column_index}

# what the first failing test's message must say (a regular expression), so that the scoreboard names the mistake
FIRST_FAILURE = {
    "bt_log_of_sigmoid": r"±1000 \(use np\.logaddexp",
    "bt_gradient_not_averaged": r"n times too large everywhere",
    "bt_gradient_on_preferred_only": r"∂L/∂r_l",
    "rewards_score_one_step_late": r"token t = 2: padding after the end, t ≥ length.*got 3, expected 0",
    "rewards_penalty_on_padding": r"padding after the end",
    "rewards_beta_on_the_score": r"its last token, t = length − 1.*R\(x\) = 3, β = 0\.5\): got 1\.5, expected 3",
    "rewards_score_by_column_index": r"sequence \d of length \d, token t = \d",
}


# the transfer task


def pl_all_pairs(scores):
    """Bradley–Terry on every pair (i ranked above j), not one choice after another."""
    n, K = scores.shape
    loss, grad = 0.0, np.zeros(scores.shape)
    for i in range(K):
        for j in range(i + 1, K):
            margin = scores[:, i] - scores[:, j]
            loss += float(np.logaddexp(0.0, -margin).sum())
            wrong = np.exp(-np.logaddexp(0.0, margin))
            grad[:, i] -= wrong
            grad[:, j] += wrong
    return loss / n, grad / n


def pl_full_softmax(scores):
    """Each choice's softmax over all K responses, the ones already chosen included."""
    n, K = scores.shape
    log_norm = np.logaddexp.reduce(scores, axis=1)
    loss = float(np.sum((K - 1) * log_norm - scores[:, : K - 1].sum(axis=1)))
    grad = (K - 1) * np.exp(scores - log_norm[:, None])
    grad[:, : K - 1] -= 1.0
    return loss / n, grad / n


def pl_naive_exp(scores):
    """The softmax's normaliser as np.log(np.sum(np.exp(...))): infinite for scores of 1000."""
    n, K = scores.shape
    loss, grad = 0.0, np.zeros(scores.shape)
    with np.errstate(over="ignore", invalid="ignore"):
        for i in range(K - 1):
            rest = np.exp(scores[:, i:])
            norm = rest.sum(axis=1)
            loss += float(np.sum(np.log(norm) - scores[:, i]))
            grad[:, i:] += rest / norm[:, None]
            grad[:, i] -= 1.0
    return loss / n, grad / n


def pl_summed(scores):
    """Summed over the rankings instead of averaged."""
    n, K = scores.shape
    loss, grad = 0.0, np.zeros(scores.shape)
    for i in range(K - 1):
        log_norm = np.logaddexp.reduce(scores[:, i:], axis=1)
        loss += float(np.sum(log_norm - scores[:, i]))
        grad[:, i:] += np.exp(scores[:, i:] - log_norm[:, None])
        grad[:, i] -= 1.0
    return loss, grad


VARIANTS.update(
    {
        "pl_all_pairs": {"plackett_luce_loss": pl_all_pairs},
        "pl_full_softmax": {"plackett_luce_loss": pl_full_softmax},
        "pl_naive_exp": {"plackett_luce_loss": pl_naive_exp},
        "pl_summed": {"plackett_luce_loss": pl_summed},
    }
)
FIRST_FAILURE.update(
    {
        "pl_all_pairs": r"every pair, not one choice after another",
        "pl_full_softmax": r"ones already chosen included",
        "pl_naive_exp": r"scores of ±1000",
        "pl_summed": r"K = 2 .*(8 times|n times)",
    }
)
