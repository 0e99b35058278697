"""Chapter 10: everything together. Algorithm 1's "run policy π_θold in the environment for T timesteps" (collect)
and its "optimise the surrogate for K epochs with minibatches of size M" (loss_and_grad, ppo_update), assembled from
the pieces of the earlier chapters.

collect is graded on small scripted environments whose episodes end at known steps, then against minippo's own
rollout on CartPole-v1. For the update, the grading test runs minippo's rollout and advantages around your
ppo_update, and your update must make CartPole-v1 learn.

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

EXERCISES = ["loss_and_grad", "ppo_update", "collect"]
TRANSFER = ["shared_trunk_gradient"]  # the chapter's idea applied to a case the book has not shown


def loss_and_grad(agent, minibatch: dict, config) -> float:
    """The loss to minimise on one minibatch, −L^{CLIP+VF+S} (eq. 9), with its gradient written into agent.grads.

    minibatch: a dict of arrays with n rows: "obs" (n, obs_dim), "actions", "logp" (log π_θold(a_t|s_t)),
    "advantages" (Â_t), "returns" (V^targ_t); ignore any other keys.
    config: a minippo.ppo.Config; use clip_epsilon (ε), value_coef (c1), entropy_coef (c2), normalize_advantages,
    whatever their values (the tests change each of them).
    The pieces: the advantages normalised over this minibatch as chapter 3's normalize_advantages does, when
    config.normalize_advantages and n > 1; L^CLIP (chapter 6); L^VF with chapter 8's ½ and no value clipping; the mean
    entropy S of π_θ(·|s_t) (chapter 2), computed only when c2 ≠ 0. Carry the loss's gradient back through the
    distribution and the network (the agent's methods above) into agent.grads.
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


def collect(policy, envs, obs_normalizer, raw_obs, horizon: int, action_bounds=None) -> dict:
    """Run the snapshot policy π_θold for T = horizon steps in each of the N = len(envs) environments and return the
    batch (Algorithm 1's "run policy π_θold in the environment for T timesteps"; minippo's Rollout.collect, without
    the reward scaling that minippo applies to the batch afterwards).

    policy: π_θold and its value function V, frozen for the whole call:
        policy.sample(o)            o: the (N, obs_dim) normalised observations of one step -> the N actions drawn
                                    from π_θold: (N,) int64, or (N, act_dim) float64 for continuous actions. Every
                                    call draws the next step's random numbers: call it once per step, with all N.
        policy.log_prob(o, a)       o (..., obs_dim), a (...) or (..., act_dim) -> log π_θold(a|o), shape (...)
        policy.value(o)             o (..., obs_dim) -> V(o), shape (...)
    envs: N environments with Gymnasium's API, each in the middle of an episode:
        env.step(action) -> (observation, reward, terminated, truncated, info)
        env.reset() -> (observation, info)       call it, without arguments, right after a step that ended the
                                                 episode (terminated or truncated), and never otherwise
    obs_normalizer: obs_normalizer(s) -> the normalised observations, same shape as s (..., obs_dim);
        obs_normalizer.update(s) folds the raw observations s into its running mean and variance (chapter 10).
    raw_obs: (N, obs_dim) s_0, the raw (unnormalised) observations the environments are at; leave it unchanged.
    action_bounds: None, or (low, high), two arrays of shape (act_dim,): the environments then get
        np.clip(a_t, low, high), while the batch keeps a_t as it was sampled.

    For t = 0 … T−1:  o_t = obs_normalizer(s_t);  a_t = policy.sample(o_t);  each environment i steps with its
    action a_t[i] (clipped, with action_bounds) and returns r_t and its flags; s_{t+1}[i] is the observation it
    returned, or, if the step ended the episode, the one env.reset() returned.
        logp[t] = log π_θold(a_t|o_t)        of a_t as sampled, never of the clipped action the environment got
        values[t] = V(o_t)
        terminated[t, i] = the step's terminated;  truncated[t, i] = its truncated and not terminated (a step that
            reports both counts as a termination)
        next_values[t, i] = 0                                  where terminated[t, i]: nothing follows
                          = V(obs_normalizer(final))           where truncated[t, i]: final is the observation that
                                                               step returned, before the reset (a time limit is not
                                                               a terminal state: bootstrap from it)
                          = V(o_{t+1}), with V(o_T) = V(obs_normalizer(s_T)) after the last step, elsewhere
    (minippo's Batch keeps V of the next episode's first observation where an episode terminated, which GAE
    multiplies by 0; here it is 0.)
    The statistics: every observation of the call (s_0 … s_T and the final observations) is normalised with the
    statistics obs_normalizer had when the call began. Call obs_normalizer.update once, last, after every
    observation has been normalised, with the T·N raw observations the policy acted on, s_0 … s_{T−1}, as one array
    of shape (T·N, obs_dim) or (T, N, obs_dim) (rows in any order): not s_T, not the final observations. The next
    batch is normalised with the new statistics.

    Returns a dict of new arrays:
        "obs" (T, N, obs_dim) float64            o_t, the normalised observations the policy acted on
        "actions" (T, N) int64 or (T, N, act_dim) float64     a_t as sampled
        "logp", "values", "next_values", "rewards" (T, N) float64      rewards r_t as the environments returned them
        "terminated", "truncated" (T, N) bool
        "raw_obs" (N, obs_dim) float64           s_T, raw: where the next call starts
    """
    T, N = horizon, len(envs)
    raw = [np.array(raw_obs, dtype=np.float64)]  # s_0 … s_T, one (N, obs_dim) array per step
    obs, actions = [], []
    rewards = np.zeros((T, N))
    terminated = np.zeros((T, N), dtype=bool)
    truncated = np.zeros((T, N), dtype=bool)
    finals = {}  # (t, i) -> the normalised final observation of an episode a time limit cut at step t
    for t in range(T):
        o = obs_normalizer(raw[t])  # the statistics the whole batch is normalised with
        a = policy.sample(o)
        obs.append(o)
        actions.append(a)
        sent = a if action_bounds is None else np.clip(a, action_bounds[0], action_bounds[1])
        following = np.empty_like(raw[t])
        for i, env in enumerate(envs):
            observation, reward, term, trunc, _ = env.step(sent[i])
            rewards[t, i] = reward
            terminated[t, i] = term
            truncated[t, i] = trunc and not term
            if truncated[t, i]:
                finals[(t, i)] = obs_normalizer(np.asarray(observation, dtype=np.float64))
            if term or trunc:
                observation, _ = env.reset()
            following[i] = observation
        raw.append(following)
    obs, actions = np.array(obs, dtype=np.float64), np.array(actions)
    flat = obs.reshape(T * N, -1)
    logp = policy.log_prob(flat, actions.reshape(T * N, *actions.shape[2:])).reshape(T, N)
    values = policy.value(flat).reshape(T, N)
    next_values = np.empty((T, N))
    next_values[:-1] = values[1:]
    next_values[-1] = policy.value(obs_normalizer(raw[T]))
    for (t, i), final in finals.items():
        next_values[t, i] = policy.value(final)
    next_values[terminated] = 0.0
    obs_normalizer.update(np.array(raw[:T]).reshape(T * N, -1))  # last: s_0 … s_{T−1}, what the policy acted on
    return {
        "obs": obs,
        "actions": actions,
        "logp": np.asarray(logp, dtype=np.float64),
        "values": np.asarray(values, dtype=np.float64),
        "next_values": next_values,
        "rewards": rewards,
        "terminated": terminated,
        "truncated": truncated,
        "raw_obs": raw[T].copy(),
    }


def shared_trunk_gradient(
    features, policy_weights, value_weights, actions, logp_old, advantages, returns, epsilon: float, value_coef: float
):
    """Transfer task: where the policy's and the value's gradients meet, the output of a shared trunk.

    A trunk (not given) maps each observation to features h_t; two linear heads read them: the logits
    z_t = h_t W_π of a categorical policy, and the value V_t = h_t w_V.
    features: (n, d) h, the variable.  policy_weights: (d, k) W_π.  value_weights: (d,) w_V.  actions: (n,) integers.
    logp_old, advantages, returns: (n,) log π_θold(a_t|s_t), Â_t (used as given, not normalised) and V^targ_t.
    epsilon: ε of L^CLIP.  value_coef: c1.  No entropy bonus here.
    Returns (loss, grad_features): the loss to minimise, −(L^CLIP − c1 L^VF) with chapter 8's L^VF (its ½), as a
    float, and ∂loss/∂h, shape (n, d).
    """
    n = len(actions)
    rows, actions = np.arange(n), actions.astype(np.int64)
    logits = features @ policy_weights
    shifted = logits - logits.max(axis=1, keepdims=True)
    log_probs = shifted - np.log(np.exp(shifted).sum(axis=1, keepdims=True))
    clip_value, grad_logp = losses.clip_objective(log_probs[rows, actions], logp_old, advantages, epsilon)
    values = features @ value_weights
    error = values - returns
    loss = -clip_value + value_coef * 0.5 * float(np.mean(error * error))
    score = -np.exp(log_probs)
    score[rows, actions] += 1.0
    grad_logits = -score * grad_logp[:, None]
    grad_values = value_coef * error / n
    # both heads read the same h: their gradients add up there
    return float(loss), grad_logits @ policy_weights.T + grad_values[:, None] * value_weights[None, :]
