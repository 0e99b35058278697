"""Chapter 10: everything together. Algorithm 1's "optimise the surrogate for K epochs with minibatches of size M",
assembled from the pieces of the earlier chapters.

The rest of Algorithm 1 (running π_θold for T steps, computing Â with GAE) is minippo's: the grading test runs
minippo's rollout and advantages around your update, and your update must make CartPole-v1 learn.

The agent is a ``minippo.agent.ActorCritic``, whose parameters live in one flat vector ``agent.params`` with the
gradient in ``agent.grads``:
    out, values, cache = agent.forward(obs)       # logits or means (n, ·), values V(s) (n,), cache for backward
    dist = agent.distribution(out)                # minippo.distributions.Categorical or DiagGaussian
    dist.log_prob(actions), dist.entropy()        # (n,) each
    dist.log_prob_backward(actions, grad_logp)    # -> a tuple: (∂/∂logits,) or (∂/∂mean, ∂/∂log σ)
    dist.entropy_backward(grad_entropy)           # -> a tuple of the same form
    agent.backward(cache, grad_out, grad_values, grad_log_std)   # writes ∂loss/∂θ into agent.grads
minippo.losses has clip_objective and value_loss (chapters 6 and 8) and minippo.optimizer has clip_grad_norm.

Grade: ``minippo grade 10``
"""

from __future__ import annotations

import numpy as np

from minippo import losses
from minippo.optimizer import clip_grad_norm

EXERCISES = ["loss_and_grad", "ppo_update"]


def loss_and_grad(agent, minibatch: dict, config) -> float:
    """The loss to minimise on one minibatch, −L^{CLIP+VF+S} (eq. 9), with its gradient written into agent.grads.

    minibatch: a dict of arrays with n rows: "obs" (n, obs_dim), "actions", "logp" (log π_θold(a_t|s_t)),
    "advantages" (Â_t), "returns" (V^targ_t); ignore any other keys.
    config: a minippo.ppo.Config; use clip_epsilon (ε), value_coef (c1), entropy_coef (c2), normalize_advantages,
    whatever their values (the tests change each of them).
        1. Â ← (Â − mean Â) / (std Â + 1e-8) over this minibatch, if config.normalize_advantages and n > 1 (np.std,
           the population standard deviation; chapter 3)
        2. L^CLIP with ε and its gradient in log π                                     (chapter 6)
        3. L^VF = ½ Ê[(V − V^targ)²] and its gradient in V (no value clipping here)     (chapter 8)
        4. S = Ê[entropy of π_θ(·|s_t)], only when c2 ≠ 0                               (chapter 2)
        5. loss = −(L^CLIP − c1 L^VF + c2 S); carry ∂loss/∂ log π and ∂loss/∂S back through the distribution (add up
           what their *_backward return), then call agent.backward with those and ∂loss/∂V.
    Returns the loss as a float; agent.grads holds ∂loss/∂θ afterwards. agent.params and the minibatch are unchanged.
    """
    out, values, cache = agent.forward(minibatch["obs"])
    dist = agent.distribution(out)
    actions = minibatch["actions"]
    logp = dist.log_prob(actions)
    n = len(logp)
    advantages = minibatch["advantages"]
    if config.normalize_advantages and n > 1:
        advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)

    clip_value, grad_logp = losses.clip_objective(logp, minibatch["logp"], advantages, config.clip_epsilon)
    value_loss, grad_values = losses.value_loss(values, minibatch["returns"])
    loss = -clip_value + config.value_coef * value_loss
    # the loss is minimised, so every objective's gradient enters with a minus
    grads = list(dist.log_prob_backward(actions, -grad_logp))
    if config.entropy_coef:
        loss -= config.entropy_coef * float(np.mean(dist.entropy()))
        grad_entropy = np.full(n, -config.entropy_coef / n)
        grads = [g + e for g, e in zip(grads, dist.entropy_backward(grad_entropy))]
    grad_log_std = grads[1] if len(grads) > 1 else None
    agent.backward(cache, grads[0], config.value_coef * grad_values, grad_log_std)
    return float(loss)


def ppo_update(agent, optimizer, data: dict, config, rng: np.random.Generator) -> int:
    """K epochs of minibatch updates on one batch (Algorithm 1's inner optimisation).

    data: a dict of arrays with the same n rows (the keys of loss_and_grad's minibatch, and perhaps more).
    optimizer: has step(grads), one descent step of agent.params given the loss gradient (a minippo.optimizer.Adam).
    config: uses epochs (K), minibatch_size (M), shuffle_minibatches, grad_norm_clipping, max_grad_norm, and what
    loss_and_grad uses.  rng: a NumPy Generator for the shuffling.
    For each of the K epochs: order = rng.permutation(n) if config.shuffle_minibatches, else 0 … n−1 (a new
    permutation at the start of every epoch, drawn from this rng and nothing else, which makes no other draws from
    it); cut it into consecutive minibatches of M rows (the last may be smaller; every row is used once per epoch);
    for each minibatch, loss_and_grad on those rows (which normalises the advantages over that minibatch only), then
    scale agent.grads so that its global L2 norm is at most config.max_grad_norm (if config.grad_norm_clipping),
    then optimizer.step(agent.grads). data is left unchanged.
    Returns the number of optimizer steps taken, K · ceil(n / M).
    """
    n = len(data["logp"])
    steps = 0
    for _ in range(config.epochs):
        order = rng.permutation(n) if config.shuffle_minibatches else np.arange(n)
        for start in range(0, n, config.minibatch_size):
            index = order[start : start + config.minibatch_size]
            minibatch = {key: value[index] for key, value in data.items()}
            loss_and_grad(agent, minibatch, config)
            if config.grad_norm_clipping:
                clip_grad_norm(agent.grads, config.max_grad_norm)
            optimizer.step(agent.grads)
            steps += 1
    return steps
