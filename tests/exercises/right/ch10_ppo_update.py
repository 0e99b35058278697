"""Other correct ways to write chapter 10."""

import numpy as np

from minippo.optimizer import clip_grad_norm
from solutions.ch10_ppo_update import loss_and_grad


def ppo_update_shuffle_in_place(agent, optimizer, data, config, rng):
    """rng.shuffle of 0 … n−1 (what rng.permutation(n) does), and each minibatch's end found with min."""
    n = len(data["logp"])
    steps = 0
    for _ in range(config.epochs):
        order = np.arange(n)
        if config.shuffle_minibatches:
            rng.shuffle(order)
        for start in range(0, n, config.minibatch_size):
            rows = order[start : min(start + config.minibatch_size, n)]
            loss_and_grad(agent, {key: data[key][rows] for key in data}, config)
            if config.grad_norm_clipping:
                clip_grad_norm(agent.grads, config.max_grad_norm)
            optimizer.step(agent.grads)
            steps += 1
    return steps


def collect_step_by_step(policy, envs, obs_normalizer, raw_obs, horizon, action_bounds=None):
    """Log-probabilities and values asked for one step at a time, a truncated episode's bootstrap value computed
    before the reset, the clip written with np.minimum and np.maximum, the next values masked with (1 − terminated),
    and the statistics updated with a (T, N, obs_dim) array."""
    T, N = horizon, len(envs)
    current = np.array(raw_obs, dtype=np.float64)
    acted, obs, actions, logp, values = [], [], [], [], []
    rewards, terminated, truncated = np.zeros((T, N)), np.zeros((T, N), dtype=bool), np.zeros((T, N), dtype=bool)
    final_values = np.zeros((T, N))
    for t in range(T):
        o = obs_normalizer(current)
        a = policy.sample(o)
        acted.append(current)
        obs.append(o)
        actions.append(a)
        logp.append(policy.log_prob(o, a))
        values.append(policy.value(o))
        sent = a
        if action_bounds is not None:
            sent = np.minimum(np.maximum(a, action_bounds[0]), action_bounds[1])
        following = []
        for i, env in enumerate(envs):
            observation, reward, term, trunc, _ = env.step(sent[i])
            rewards[t, i] = float(reward)
            terminated[t, i] = bool(term)
            truncated[t, i] = bool(trunc) and not bool(term)
            if truncated[t, i]:
                final_values[t, i] = policy.value(obs_normalizer(np.asarray(observation, dtype=np.float64)[None]))[0]
            if term or trunc:
                observation = env.reset()[0]
            following.append(np.asarray(observation, dtype=np.float64))
        current = np.stack(following)
    values = np.array(values)
    following_values = np.concatenate([values[1:], policy.value(obs_normalizer(current))[None]])
    next_values = (1.0 - terminated) * np.where(truncated, final_values, following_values)
    obs_normalizer.update(np.array(acted))
    return {
        "obs": np.array(obs),
        "actions": np.array(actions),
        "logp": np.array(logp, dtype=np.float64),
        "values": values,
        "next_values": next_values,
        "rewards": rewards,
        "terminated": terminated,
        "truncated": truncated,
        "raw_obs": current,
    }


def collect_preallocated(policy, envs, obs_normalizer, raw_obs, horizon, action_bounds=None):
    """Arrays of the batch allocated up front (T + 1 rows of raw observations), the environments' final observations
    kept in a list and their values asked for in one call, and the statistics updated with the rows environment by
    environment (the contract takes them in any order)."""
    T, N = horizon, len(envs)
    raw = np.empty((T + 1,) + np.shape(raw_obs))
    raw[0] = raw_obs
    obs = np.empty_like(raw[:T])
    rewards = np.empty((T, N))
    terminated = np.empty((T, N), dtype=bool)
    truncated = np.empty((T, N), dtype=bool)
    actions = None
    cut, finals = [], []
    for t in range(T):
        obs[t] = obs_normalizer(raw[t])
        a = np.asarray(policy.sample(obs[t]))
        if actions is None:
            actions = np.empty((T,) + a.shape, dtype=a.dtype)
        actions[t] = a
        sent = a if action_bounds is None else np.clip(a, *action_bounds)
        for i in range(N):
            step = envs[i].step(sent[i])
            rewards[t, i] = step[1]
            terminated[t, i], truncated[t, i] = step[2], step[3] and not step[2]
            raw[t + 1, i] = step[0]
            if truncated[t, i]:
                cut.append((t, i))
                finals.append(obs_normalizer(raw[t + 1, i]))
            if step[2] or step[3]:
                raw[t + 1, i] = envs[i].reset()[0]
    logp = policy.log_prob(obs, actions)
    values = policy.value(obs)
    next_values = np.zeros((T, N))
    next_values[:-1] = values[1:]
    next_values[-1] = policy.value(obs_normalizer(raw[T]))
    if finals:
        bootstrap = policy.value(np.array(finals))
        for (t, i), value in zip(cut, bootstrap):
            next_values[t, i] = value
    next_values[terminated] = 0.0
    obs_normalizer.update(raw[:T].transpose(1, 0, 2).reshape(T * N, -1))
    return {
        "obs": obs,
        "actions": actions,
        "logp": logp,
        "values": values,
        "next_values": next_values,
        "rewards": rewards,
        "terminated": terminated,
        "truncated": truncated,
        "raw_obs": raw[T].copy(),
    }


VARIANTS = {
    "ppo_update_shuffle_in_place": {"ppo_update": ppo_update_shuffle_in_place},
    "collect_step_by_step": {"collect": collect_step_by_step},
    "collect_preallocated": {"collect": collect_preallocated},
}


def trunk_through_the_logits_jacobian(features, policy_weights, value_weights, actions, logp_old, advantages, returns,
                                      epsilon, value_coef):  # fmt: skip
    """Sample by sample: ∂ log π(a|s)/∂h = W_π[:, a] − W_π π, the two heads' paths added, no log-softmax matrix."""
    n = len(actions)
    loss, grad = 0.0, np.zeros(features.shape)
    for t in range(n):
        logits = features[t] @ policy_weights
        probs = np.exp(logits - logits.max())
        probs /= probs.sum()
        ratio = probs[actions[t]] / np.exp(logp_old[t])
        a = advantages[t]
        clipped = min(max(ratio, 1 - epsilon), 1 + epsilon)
        loss -= min(ratio * a, clipped * a) / n
        score_h = policy_weights[:, actions[t]] - policy_weights @ probs
        if ratio * a <= clipped * a:
            grad[t] -= ratio * a * score_h / n
        error = features[t] @ value_weights - returns[t]
        loss += value_coef * 0.5 * error * error / n
        grad[t] += value_coef * error * value_weights / n
    return float(loss), grad


VARIANTS["trunk_through_the_logits_jacobian"] = {"shared_trunk_gradient": trunk_through_the_logits_jacobian}
