"""DPO (Rafailov et al. 2023): the optimum of the KL-regularised objective, reached from the preference pairs directly.

The optimum π*(y|x) ∝ π_ref(y|x) exp(R(x, y)/β) turned round says R(x, y) = β log π*(y|x)/π_ref(y|x) + β log Z(x).
Put that reward into the Bradley–Terry model of the preferences, where Z(x) cancels between two responses to the same
prompt, and fit the policy itself by maximum likelihood of the observed choices:

    L^DPO = −Ê[log σ(Δ)],   Δ = β [(log π_θ(y_w|x) − log π_ref(y_w|x)) − (log π_θ(y_l|x) − log π_ref(y_l|x))],

    ∂L/∂ log π_θ(y_w|x) = −β σ(−Δ)/n,   ∂L/∂ log π_θ(y_l|x) = +β σ(−Δ)/n.

No reward model, no sampling, no value network: log π_θ(y|x) is the sum of the response's token log-probabilities,
and the gradient reaches each token through the categorical's log_prob_backward, as in pretraining.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from minippo.agent import ActorCritic
from minippo.distributions import Categorical
from minippo.lm.language import PROMPT_LEN, sequence_features
from minippo.lm.reward_model import bradley_terry_loss
from minippo.minibatches import epochs_of
from minippo.optimizer import Adam, clip_grad_norm


@dataclass
class DPOConfig:
    seed: int = 0
    beta: float = 0.1  # β: the strength of the KL to π_ref that the optimum it aims at is regularised by
    epochs: int = 4  # passes over the preference pairs
    minibatch_pairs: int = 64
    lr: float = 1e-3  # Adam's step size
    max_grad_norm: float = 0.5
    prompt_len: int = PROMPT_LEN


def dpo_loss(logp_preferred, logp_rejected, ref_preferred, ref_rejected, beta: float):
    """L = −Ê[log σ(β (log π/π_ref of y_w − log π/π_ref of y_l))] over n pairs, from sequence log-probabilities.

    It is the Bradley–Terry loss on the implicit rewards β log π/π_ref, so its gradient is β times that loss's:
    returns (L, ∂L/∂ log π(y_w|x) = −β σ(−Δ)/n, ∂L/∂ log π(y_l|x) = +β σ(−Δ)/n).
    """
    loss, grad_w, grad_l = bradley_terry_loss(
        beta * (logp_preferred - ref_preferred), beta * (logp_rejected - ref_rejected)
    )
    return loss, beta * grad_w, beta * grad_l


def response_tokens(tokens: np.ndarray, lengths: np.ndarray, prompt_len: int) -> dict:
    """The response tokens of whole texts (n, T), flattened: their states, the tokens, and the text each belongs to."""
    steps = np.arange(tokens.shape[1])[None, :]
    valid = (steps >= prompt_len) & (steps < lengths[:, None])
    return {
        "obs": sequence_features(tokens)[valid],
        "actions": tokens[valid],
        "text": np.nonzero(valid)[0],
    }


def sequence_log_probs(policy, data: dict, n: int):
    """log π(y|x) of each of n responses, the sum of its tokens' log-probabilities, and a function that turns
    ∂L/∂ log π(y|x) (n,) into ∂L/∂θ, written into ``policy.grads``."""
    logits, cache = policy.forward(data["obs"])
    dist = Categorical(logits)
    token_logp = dist.log_prob(data["actions"])

    def backward(grad_sequences: np.ndarray) -> None:
        (grad_logits,) = dist.log_prob_backward(data["actions"], grad_sequences[data["text"]])
        policy.backward(cache, grad_logits)

    return np.bincount(data["text"], weights=token_logp, minlength=n), backward


def dpo_loss_and_grad(policy, preferred: dict, rejected: dict, ref_preferred, ref_rejected, beta: float) -> float:
    """L^DPO of a minibatch of pairs (preferred and rejected as from response_tokens, of the same n pairs), its
    gradient written into ``policy.grads``."""
    n = len(ref_preferred)
    both = {key: np.concatenate([preferred[key], rejected[key]]) for key in ("obs", "actions")}
    both["text"] = np.concatenate([preferred["text"], rejected["text"] + n])
    logp, backward = sequence_log_probs(policy, both, 2 * n)
    loss, grad_w, grad_l = dpo_loss(logp[:n], logp[n:], ref_preferred, ref_rejected, beta)
    backward(np.concatenate([grad_w, grad_l]))
    return loss


def _select(data: dict, texts: np.ndarray) -> dict:
    """The tokens of the texts ``texts`` (indices into the original n), renumbered 0 … len(texts) − 1."""
    position = np.full(data["text"].max() + 1, -1)
    position[texts] = np.arange(len(texts))
    keep = position[data["text"]] >= 0
    return {"obs": data["obs"][keep], "actions": data["actions"][keep], "text": position[data["text"][keep]]}


def train_dpo(pretrained: ActorCritic, preferred, rejected, config: DPOConfig, on_epoch=None):
    """Fine-tune a copy of ``pretrained`` (π_ref, never changed) with DPO on the pairs (preferred, rejected), each
    (tokens, lengths) of whole texts sharing their prompt. ``on_epoch(stats, policy)`` after every epoch.
    Returns (the fine-tuned model, one dict per epoch: the mean loss and the implicit reward margin's accuracy)."""
    rng = np.random.default_rng(config.seed)
    agent, reference = pretrained.copy(), pretrained.copy()
    policy = agent.nets["policy"]
    optimizer = Adam(policy.params, lr=config.lr)
    n = len(preferred[1])
    data_w = response_tokens(*preferred, config.prompt_len)
    data_l = response_tokens(*rejected, config.prompt_len)
    ref_w = sequence_log_probs(reference.nets["policy"], data_w, n)[0]
    ref_l = sequence_log_probs(reference.nets["policy"], data_l, n)[0]
    history = []
    for number, epoch in enumerate(epochs_of(n, config.epochs, config.minibatch_pairs, rng), start=1):
        epoch_losses = []
        for pairs in epoch:
            take = np.sort(pairs)
            loss = dpo_loss_and_grad(
                policy, _select(data_w, take), _select(data_l, take), ref_w[take], ref_l[take], config.beta
            )
            clip_grad_norm(policy.grads, config.max_grad_norm)
            optimizer.step(policy.grads)
            epoch_losses.append(loss)
        margin = sequence_log_probs(policy, data_w, n)[0] - ref_w - sequence_log_probs(policy, data_l, n)[0] + ref_l
        stats = {"epoch": number, "loss": float(np.mean(epoch_losses)), "accuracy": float(np.mean(margin > 0))}
        history.append(stats)
        if on_epoch is not None:
            on_epoch(stats, agent)
    return agent, history
