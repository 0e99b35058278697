"""Plausible mistakes in chapter 10: the assembled loss and the epoch and minibatch loop."""

import dataclasses

import numpy as np

from minippo import losses
from minippo.optimizer import clip_grad_norm
from solutions.ch10_ppo_update import loss_and_grad


def _assemble(agent, minibatch, config, normalize=True, normalize_one=False, value_sign=1.0, grad_sign=1.0,
              entropy=True, c1_in_gradient=True, old_values=False):  # fmt: skip
    """loss_and_grad with switches for its usual mistakes."""
    out, values, cache = agent.forward(minibatch["obs"])
    dist = agent.distribution(out)
    logp = dist.log_prob(minibatch["actions"])
    n = len(logp)
    advantages = minibatch["advantages"]
    if normalize and config.normalize_advantages and (n > 1 or normalize_one):
        advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
    clip_value, grad_logp = losses.clip_objective(logp, minibatch["logp"], advantages, config.clip_epsilon)
    value_loss, grad_values = losses.value_loss(minibatch["values"] if old_values else values, minibatch["returns"])
    if old_values:  # the stored values are constants: nothing flows into the value network
        grad_values = np.zeros_like(grad_values)
    loss = -clip_value + value_sign * config.value_coef * value_loss
    grads = list(dist.log_prob_backward(minibatch["actions"], -grad_sign * grad_logp))
    if entropy and config.entropy_coef:
        loss -= config.entropy_coef * float(np.mean(dist.entropy()))
        extra = dist.entropy_backward(np.full(n, -grad_sign * config.entropy_coef / n))
        grads = [g + e for g, e in zip(grads, extra)]
    value_scale = config.value_coef if c1_in_gradient else 1.0
    agent.backward(cache, grads[0], grad_sign * value_sign * value_scale * grad_values, grads[1] if len(grads) > 1
                   else None)  # fmt: skip
    return float(loss)


def loss_is_the_objective(agent, minibatch, config):
    """Returns L^{CLIP+VF+S} and its gradient, where the contract asks for the loss to minimise (its negative)."""
    loss = _assemble(agent, minibatch, config)
    agent.grads *= -1.0
    return -loss


def loss_ignores_normalize_advantages(agent, minibatch, config):
    """Never normalises the advantages."""
    return _assemble(agent, minibatch, config, normalize=False)


def loss_normalises_a_single_sample(agent, minibatch, config):
    """Normalises a minibatch of one too, which turns its advantage into 0."""
    return _assemble(agent, minibatch, config, normalize_one=True)


def loss_adds_the_value_term_with_a_minus(agent, minibatch, config):
    """−L^CLIP − c1 L^VF: the value loss rewarded instead of minimised."""
    return _assemble(agent, minibatch, config, value_sign=-1.0)


def loss_forgets_the_entropy(agent, minibatch, config):
    """Leaves out the entropy bonus even when entropy_coef is not 0."""
    return _assemble(agent, minibatch, config, entropy=False)


def gradient_of_the_objective(agent, minibatch, config):
    """The right loss, but the gradient written into agent.grads is that of the objective (the sign flipped)."""
    loss = _assemble(agent, minibatch, config)
    agent.grads *= -1.0
    return loss


def value_gradient_without_c1(agent, minibatch, config):
    """The value head's gradient is not scaled by value_coef."""
    return _assemble(agent, minibatch, config, c1_in_gradient=False)


def _loop(agent, optimizer, data, config, rng, epochs=None, drop_last=False, shuffle=True, clip="norm",
          same_minibatch=False, sign=1.0):  # fmt: skip
    n, steps = len(data["logp"]), 0
    for _ in range(config.epochs if epochs is None else epochs):
        order = rng.permutation(n) if shuffle and config.shuffle_minibatches else np.arange(n)
        starts = range(0, n - config.minibatch_size + 1 if drop_last else n, config.minibatch_size)
        for start in starts:
            begin = 0 if same_minibatch else start
            index = order[begin : begin + config.minibatch_size]
            loss_and_grad(agent, {key: value[index] for key, value in data.items()}, config)
            if config.grad_norm_clipping and clip == "norm":
                clip_grad_norm(agent.grads, config.max_grad_norm)
            elif config.grad_norm_clipping and clip == "each":
                np.clip(agent.grads, -config.max_grad_norm, config.max_grad_norm, out=agent.grads)
            optimizer.step(sign * agent.grads)
            steps += 1
    return steps


def update_one_epoch_only(agent, optimizer, data, config, rng):
    """Goes over the batch once, whatever config.epochs says."""
    return _loop(agent, optimizer, data, config, rng, epochs=1)


def update_drops_the_last_minibatch(agent, optimizer, data, config, rng):
    """Skips the last, smaller minibatch of each epoch."""
    return _loop(agent, optimizer, data, config, rng, drop_last=True)


def update_never_shuffles(agent, optimizer, data, config, rng):
    """Always takes the rows in order, so every epoch sees the same minibatches."""
    return _loop(agent, optimizer, data, config, rng, shuffle=False)


def update_without_gradient_clipping(agent, optimizer, data, config, rng):
    """Ignores grad_norm_clipping."""
    return _loop(agent, optimizer, data, config, rng, clip=None)


def update_clips_each_entry(agent, optimizer, data, config, rng):
    """Clips every entry of the gradient to ±max_grad_norm instead of scaling its global norm."""
    return _loop(agent, optimizer, data, config, rng, clip="each")


def update_same_minibatch_every_step(agent, optimizer, data, config, rng):
    """Slices the first minibatch of the order at every step."""
    return _loop(agent, optimizer, data, config, rng, same_minibatch=True)


def update_ascends_the_loss(agent, optimizer, data, config, rng):
    """Hands the optimizer −∂loss/∂θ, so it climbs the loss."""
    return _loop(agent, optimizer, data, config, rng, sign=-1.0)


VARIANTS = {
    "loss_is_the_objective": {"loss_and_grad": loss_is_the_objective},
    "loss_ignores_normalize_advantages": {"loss_and_grad": loss_ignores_normalize_advantages},
    "loss_normalises_a_single_sample": {"loss_and_grad": loss_normalises_a_single_sample},
    "loss_adds_the_value_term_with_a_minus": {"loss_and_grad": loss_adds_the_value_term_with_a_minus},
    "loss_forgets_the_entropy": {"loss_and_grad": loss_forgets_the_entropy},
    "gradient_of_the_objective": {"loss_and_grad": gradient_of_the_objective},
    "value_gradient_without_c1": {"loss_and_grad": value_gradient_without_c1},
    "update_one_epoch_only": {"ppo_update": update_one_epoch_only},
    "update_drops_the_last_minibatch": {"ppo_update": update_drops_the_last_minibatch},
    "update_never_shuffles": {"ppo_update": update_never_shuffles},
    "update_without_gradient_clipping": {"ppo_update": update_without_gradient_clipping},
    "update_clips_each_entry": {"ppo_update": update_clips_each_entry},
    "update_same_minibatch_every_step": {"ppo_update": update_same_minibatch_every_step},
    "update_ascends_the_loss": {"ppo_update": update_ascends_the_loss},
}


def _with(config, **changes):
    return dataclasses.replace(config, **changes)


def loss_epsilon_fixed(agent, minibatch, config):
    """ε = 0.2 written into the code instead of config.clip_epsilon."""
    return _assemble(agent, minibatch, _with(config, clip_epsilon=0.2))


def loss_band_on_log_ratio(agent, minibatch, config):
    """L^CLIP written case by case, with the clip's cases tested on log r against ±ε instead of r against 1 ± ε."""
    out, values, cache = agent.forward(minibatch["obs"])
    dist = agent.distribution(out)
    logp = dist.log_prob(minibatch["actions"])
    n, eps = len(logp), config.clip_epsilon
    advantages = minibatch["advantages"]
    if config.normalize_advantages and n > 1:
        advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
    log_ratio = logp - minibatch["logp"]
    ratio = np.exp(log_ratio)
    clipped = ((log_ratio > eps) & (advantages > 0)) | ((log_ratio < -eps) & (advantages < 0))
    objective = np.where(clipped, np.where(advantages > 0, 1 + eps, 1 - eps) * advantages, ratio * advantages)
    grad_logp = np.where(clipped, 0.0, ratio * advantages) / n
    value_loss, grad_values = losses.value_loss(values, minibatch["returns"])
    loss = -float(np.mean(objective)) + config.value_coef * value_loss
    grads = list(dist.log_prob_backward(minibatch["actions"], -grad_logp))
    if config.entropy_coef:
        loss -= config.entropy_coef * float(np.mean(dist.entropy()))
        grads = [g + e for g, e in zip(grads, dist.entropy_backward(np.full(n, -config.entropy_coef / n)))]
    agent.backward(cache, grads[0], config.value_coef * grad_values, grads[1] if len(grads) > 1 else None)
    return float(loss)


def loss_sample_std(agent, minibatch, config):
    """Normalises the advantages with the sample standard deviation (ddof = 1) where the contract says np.std."""
    n = len(minibatch["advantages"])
    if config.normalize_advantages and n > 1:
        a = minibatch["advantages"]
        minibatch = dict(minibatch, advantages=(a - a.mean()) / (a.std(ddof=1) + 1e-8))
    return _assemble(agent, minibatch, config, normalize=False)


def loss_value_coef_fixed(agent, minibatch, config):
    """c1 = 0.5 written into the code instead of config.value_coef."""
    return _assemble(agent, minibatch, _with(config, value_coef=0.5))


def loss_entropy_coef_fixed(agent, minibatch, config):
    """c2 = 0.0 (the paper's MuJoCo setting) written into the code instead of config.entropy_coef."""
    return _assemble(agent, minibatch, _with(config, entropy_coef=0.0))


def update_normalises_the_whole_batch(agent, optimizer, data, config, rng):
    """Normalises the advantages once over the whole batch, then turns the per-minibatch normalisation off."""
    a = data["advantages"]
    data = dict(data, advantages=(a - a.mean()) / (a.std() + 1e-8))
    return _loop(agent, optimizer, data, _with(config, normalize_advantages=False), rng)


def update_shuffles_once(agent, optimizer, data, config, rng):
    """One permutation for all the epochs."""
    n, steps = len(data["logp"]), 0
    order = rng.permutation(n) if config.shuffle_minibatches else np.arange(n)
    for _ in range(config.epochs):
        for start in range(0, n, config.minibatch_size):
            index = order[start : start + config.minibatch_size]
            loss_and_grad(agent, {key: value[index] for key, value in data.items()}, config)
            if config.grad_norm_clipping:
                clip_grad_norm(agent.grads, config.max_grad_norm)
            optimizer.step(agent.grads)
            steps += 1
    return steps


class _GlobalRandom:
    def permutation(self, n):
        return np.random.permutation(n)


def update_global_random(agent, optimizer, data, config, rng):
    """Shuffles with np.random.permutation, ignoring the rng passed in."""
    return _loop(agent, optimizer, data, config, _GlobalRandom())


def update_fresh_generator(agent, optimizer, data, config, rng):
    """Makes a new Generator from config.seed at every call, so every update shuffles the same way."""
    return _loop(agent, optimizer, data, config, np.random.default_rng(config.seed))


def update_always_shuffles(agent, optimizer, data, config, rng):
    """Ignores shuffle_minibatches: shuffles even when it is False."""
    return _loop(agent, optimizer, data, _with(config, shuffle_minibatches=True), rng)


def update_returns_nothing(agent, optimizer, data, config, rng):
    """Right updates, but no return value."""
    _loop(agent, optimizer, data, config, rng)


def update_clips_after_the_step(agent, optimizer, data, config, rng):
    """Clips the gradient after optimizer.step has used it."""
    n, steps = len(data["logp"]), 0
    for _ in range(config.epochs):
        order = rng.permutation(n) if config.shuffle_minibatches else np.arange(n)
        for start in range(0, n, config.minibatch_size):
            index = order[start : start + config.minibatch_size]
            loss_and_grad(agent, {key: value[index] for key, value in data.items()}, config)
            optimizer.step(agent.grads)
            if config.grad_norm_clipping:
                clip_grad_norm(agent.grads, config.max_grad_norm)
            steps += 1
    return steps


def update_normalises_data_in_place(agent, optimizer, data, config, rng):
    """Normalises data["advantages"] in place over the whole batch (the caller's array changes)."""
    a = data["advantages"]
    a -= a.mean()
    a /= a.std() + 1e-8
    return _loop(agent, optimizer, data, config, rng)


VARIANTS.update(
    {
        "loss_epsilon_fixed": {"loss_and_grad": loss_epsilon_fixed},
        "loss_band_on_log_ratio": {"loss_and_grad": loss_band_on_log_ratio},
        "loss_sample_std": {"loss_and_grad": loss_sample_std},
        "loss_value_coef_fixed": {"loss_and_grad": loss_value_coef_fixed},
        "loss_entropy_coef_fixed": {"loss_and_grad": loss_entropy_coef_fixed},
        "update_normalises_the_whole_batch": {"ppo_update": update_normalises_the_whole_batch},
        "update_shuffles_once": {"ppo_update": update_shuffles_once},
        "update_global_random": {"ppo_update": update_global_random},
        "update_fresh_generator": {"ppo_update": update_fresh_generator},
        "update_always_shuffles": {"ppo_update": update_always_shuffles},
        "update_returns_nothing": {"ppo_update": update_returns_nothing},
        "update_clips_after_the_step": {"ppo_update": update_clips_after_the_step},
        "update_normalises_data_in_place": {"ppo_update": update_normalises_data_in_place},
    }
)

FIRST_FAILURE = {
    "loss_is_the_objective": r"the objective L\^\{CLIP\+VF\+S\} itself",
    "loss_normalises_a_single_sample": r"a minibatch of one sample is normalised",
    "loss_adds_the_value_term_with_a_minus": r"value loss enters with the wrong sign",
    "loss_forgets_the_entropy": r"entropy bonus c2 S is missing",
    "gradient_of_the_objective": r"sign is flipped everywhere",
    "loss_epsilon_fixed": r"config\.clip_epsilon = 0\.1 is ignored",
    "loss_value_coef_fixed": r"config\.value_coef = .* is ignored",
    "loss_entropy_coef_fixed": r"entropy bonus c2 S is missing|config\.entropy_coef = .* is ignored",
    "loss_band_on_log_ratio": r"not on log r",
    "loss_sample_std": r"sample standard deviation",
    "update_normalises_the_whole_batch": r"minibatch 1 .*not the whole batch",
    "update_shuffles_once": r"every epoch used the same order",
    "update_global_random": r"not as rng\.permutation\(n\) of the rng passed in",
    "update_fresh_generator": r"not as rng\.permutation\(n\) of the rng passed in",
    "update_always_shuffles": r"shuffle_minibatches = False",
    "update_never_shuffles": r"rng\.permutation\(n\), not 0 … n−1",
    "update_returns_nothing": r"number of optimizer steps.*not None",
    "update_clips_after_the_step": r"max_grad_norm",
    "update_normalises_data_in_place": r"changed its input",
}


def loss_normalises_without_epsilon(agent, minibatch, config):
    """(Â − mean Â) / std Â without the 1e-8: equal advantages give 0/0."""
    n = len(minibatch["advantages"])
    if config.normalize_advantages and n > 1:
        a = minibatch["advantages"]
        with np.errstate(invalid="ignore", divide="ignore"):
            minibatch = dict(minibatch, advantages=(a - a.mean()) / a.std())
    return _assemble(agent, minibatch, config, normalize=False)


def update_counts_the_keys(agent, optimizer, data, config, rng):
    """n = len(data), the number of keys in the dict, instead of the number of rows."""
    n, steps = len(data), 0
    for _ in range(config.epochs):
        order = rng.permutation(n) if config.shuffle_minibatches else np.arange(n)
        for start in range(0, n, config.minibatch_size):
            index = order[start : start + config.minibatch_size]
            loss_and_grad(agent, {key: value[index] for key, value in data.items()}, config)
            if config.grad_norm_clipping:
                clip_grad_norm(agent.grads, config.max_grad_norm)
            optimizer.step(agent.grads)
            steps += 1
    return steps


def loss_epsilon_inside_the_root(agent, minibatch, config):
    """(Â − mean Â) / √(var Â + 1e-8): the 1e-8 inside the square root, which matters only for a tiny spread."""
    n = len(minibatch["advantages"])
    if config.normalize_advantages and n > 1:
        a = minibatch["advantages"]
        minibatch = dict(minibatch, advantages=(a - a.mean()) / np.sqrt(a.var() + 1e-8))
    return _assemble(agent, minibatch, config, normalize=False)


def loss_value_of_the_old_values(agent, minibatch, config):
    """L^VF from minibatch["values"], the rollout's values, instead of the network's V_θ(s_t): the value network gets
    no gradient."""
    return _assemble(agent, minibatch, config, old_values=True)


def loss_clips_the_value_loss(agent, minibatch, config):
    """The value loss clipped around minibatch["values"] (the "37 details" value clipping), which this exercise's
    contract leaves out."""
    out, values, cache = agent.forward(minibatch["obs"])
    dist = agent.distribution(out)
    logp = dist.log_prob(minibatch["actions"])
    n = len(logp)
    advantages = minibatch["advantages"]
    if config.normalize_advantages and n > 1:
        advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
    clip_value, grad_logp = losses.clip_objective(logp, minibatch["logp"], advantages, config.clip_epsilon)
    value_loss, grad_values = losses.value_loss(values, minibatch["returns"], minibatch["values"], config.clip_epsilon)
    loss = -clip_value + config.value_coef * value_loss
    grads = list(dist.log_prob_backward(minibatch["actions"], -grad_logp))
    if config.entropy_coef:
        loss -= config.entropy_coef * float(np.mean(dist.entropy()))
        grads = [g + e for g, e in zip(grads, dist.entropy_backward(np.full(n, -config.entropy_coef / n)))]
    agent.backward(cache, grads[0], config.value_coef * grad_values, grads[1] if len(grads) > 1 else None)
    return float(loss)


def update_always_clips(agent, optimizer, data, config, rng):
    """Clips the gradient's norm whether or not config.grad_norm_clipping asks for it."""
    n, steps = len(data["logp"]), 0
    for _ in range(config.epochs):
        order = rng.permutation(n) if config.shuffle_minibatches else np.arange(n)
        for start in range(0, n, config.minibatch_size):
            index = order[start : start + config.minibatch_size]
            loss_and_grad(agent, {key: value[index] for key, value in data.items()}, config)
            clip_grad_norm(agent.grads, config.max_grad_norm)
            optimizer.step(agent.grads)
            steps += 1
    return steps


VARIANTS.update(
    {
        "loss_epsilon_inside_the_root": {"loss_and_grad": loss_epsilon_inside_the_root},
        "loss_value_of_the_old_values": {"loss_and_grad": loss_value_of_the_old_values},
        "update_always_clips": {"ppo_update": update_always_clips},
        "loss_clips_the_value_loss": {"loss_and_grad": loss_clips_the_value_loss},
        "loss_normalises_without_epsilon": {"loss_and_grad": loss_normalises_without_epsilon},
        "update_counts_the_keys": {"ppo_update": update_counts_the_keys},
    }
)
FIRST_FAILURE.update(
    {
        "loss_normalises_without_epsilon": r"all equal \(std Â = 0\)|NaN",
        "update_counts_the_keys": r"optimizer steps|rows",
        "loss_epsilon_inside_the_root": r"tiny spread.*the 1e-8 inside the square root",
        "loss_value_of_the_old_values": r"minibatch\['values'\] \(the rollout's old values\)",
        "loss_clips_the_value_loss": r"the value loss is clipped around minibatch\['values'\]",
        "update_always_clips": r"grad_norm_clipping = False.*is config\.grad_norm_clipping ignored",
    }
)


# the rollout: collect


def _collect(policy, envs, obs_normalizer, raw_obs, horizon, action_bounds=None, *, at_truncation="final",
             at_termination="zero", logp_of="sampled", update="end", last_value="next", both_truncated=False,
             reset_when="ended", store="normalised", update_rows="acted", actions_kept="sampled", act_on="normalised",
             last_raw="next"):  # fmt: skip
    """collect with switches for its usual mistakes (each default is the contract's)."""
    T, N = horizon, len(envs)
    raw = [np.array(raw_obs, dtype=np.float64)]
    obs, actions, sent_actions = [], [], []
    rewards = np.zeros((T, N))
    terminated = np.zeros((T, N), dtype=bool)
    truncated = np.zeros((T, N), dtype=bool)
    finals = {}  # (t, i) -> the raw observation the step that ended an episode returned
    for t in range(T):
        o = obs_normalizer(raw[t])
        a = policy.sample(o if act_on == "normalised" else raw[t])
        obs.append(o)
        sent = a if action_bounds is None else np.clip(a, action_bounds[0], action_bounds[1])
        actions.append(a if actions_kept == "sampled" else sent)
        sent_actions.append(sent)
        following = np.empty_like(raw[t])
        for i, env in enumerate(envs):
            observation, reward, term, trunc, _ = env.step(sent[i])
            rewards[t, i] = reward
            terminated[t, i] = term
            truncated[t, i] = trunc if both_truncated else trunc and not term
            if term or trunc:
                finals[(t, i)] = np.asarray(observation, dtype=np.float64)
            if term or (trunc and reset_when == "ended"):
                observation, _ = env.reset()
            following[i] = observation
        raw.append(following)
        if update == "every step":
            obs_normalizer.update(raw[t])
    if update == "before the bootstrap values":
        obs_normalizer.update(np.array(raw[:T]).reshape(T * N, -1))
    obs, actions = np.array(obs), np.array(actions)
    flat = obs.reshape(T * N, -1)
    chosen = actions if logp_of == "sampled" else np.array(sent_actions)
    logp = policy.log_prob(flat, chosen.reshape(T * N, *actions.shape[2:])).reshape(T, N)
    values = policy.value(flat).reshape(T, N)
    next_values = np.empty((T, N))
    next_values[:-1] = values[1:]
    next_values[-1] = policy.value(obs_normalizer(raw[T])) if last_value == "next" else values[-1]
    if last_value == "unshifted":
        next_values = values.copy()
    for (t, i), final in finals.items():
        how = at_termination if terminated[t, i] else at_truncation
        if how == "final":
            next_values[t, i] = policy.value(obs_normalizer(final))
        elif how == "zero":
            next_values[t, i] = 0.0
        # "reset": keep V of the next stored observation, the one env.reset() returned
    if update == "end":
        rows = {"acted": raw[:T], "next": raw[1:], "normalised": obs}[update_rows]
        obs_normalizer.update(np.array(rows).reshape(T * N, -1))
    return {
        "obs": obs if store == "normalised" else np.array(raw[:T]),
        "actions": actions,
        "logp": logp,
        "values": values,
        "next_values": next_values,
        "rewards": rewards,
        "terminated": terminated,
        "truncated": truncated,
        "raw_obs": (raw[T] if last_raw == "next" else raw[T - 1]).copy(),
    }


def _variant(**switches):
    def collect(policy, envs, obs_normalizer, raw_obs, horizon, action_bounds=None):
        return _collect(policy, envs, obs_normalizer, raw_obs, horizon, action_bounds, **switches)

    return collect


ROLLOUT_MISTAKES = {
    # (the switches, the words its first failure must hold)
    "rollout_no_bootstrap_at_truncation": (dict(at_truncation="zero"), r"no bootstrap at a truncation"),
    "rollout_bootstraps_at_termination": (dict(at_termination="final"), r"a bootstrap at a termination"),
    "rollout_logp_of_the_clipped_action": (dict(logp_of="clipped"), r"log π_θold of the clipped action"),
    "rollout_updates_statistics_every_step": (
        dict(update="every step"),
        r"after obs_normalizer\.update|update was called \d+ times",
    ),
    "rollout_updates_before_the_bootstrap_values": (
        dict(update="before the bootstrap values"),
        r"after obs_normalizer\.update: .*s_T, or a truncated episode's final observation",
    ),
    "rollout_last_next_value_off_by_one": (
        dict(last_value="own"),
        r"the value of the step's own observation \(off by one\)",
    ),
    "rollout_next_values_unshifted": (dict(last_value="unshifted"), r"off by one"),
    "rollout_post_reset_value_at_truncation": (
        dict(at_truncation="reset"),
        r"V of the observation env\.reset\(\) returned",
    ),
    "rollout_post_reset_value_at_every_episode_end": (
        dict(at_truncation="reset", at_termination="reset"),
        r"V of the observation env\.reset\(\) returned \(the next episode's first\) where the episode terminated",
    ),
    "rollout_keeps_truncated_with_terminated": (dict(both_truncated=True), r"counts as terminated"),
    "rollout_resets_only_on_termination": (
        dict(reset_when="terminated"),
        r"stepped again at step \d+ without env\.reset",
    ),
    "rollout_stores_raw_observations": (dict(store="raw"), r"the raw observation s_t; store o_t"),
    "rollout_policy_acts_on_raw_observations": (dict(act_on="raw"), r"the raw observation s_t; the policy acts on o_t"),
    "rollout_updates_with_the_next_observations": (dict(update_rows="next"), r"s_1 … s_T"),
    "rollout_updates_with_normalised_observations": (dict(update_rows="normalised"), r"the normalised observations"),
    "rollout_stores_clipped_actions": (dict(actions_kept="clipped"), r"the clipped action; store a_t"),
    "rollout_returns_the_last_acted_observation": (
        dict(last_raw="acted"),
        r"s_\{T−1\}, the observation of the last step",
    ),
}
VARIANTS.update({name: {"collect": _variant(**switches)} for name, (switches, _) in ROLLOUT_MISTAKES.items()})
FIRST_FAILURE.update({name: words for name, (_, words) in ROLLOUT_MISTAKES.items()})


# the transfer task


def _trunk_parts(features, policy_weights, value_weights, actions, logp_old, advantages, returns, epsilon):
    n = len(actions)
    logits = features @ policy_weights
    log_probs = logits - np.log(np.exp(logits).sum(axis=1, keepdims=True))
    clip_value, grad_logp = losses.clip_objective(log_probs[np.arange(n), actions], logp_old, advantages, epsilon)
    score = -np.exp(log_probs)
    score[np.arange(n), actions] += 1.0
    error = features @ value_weights - returns
    return clip_value, -score * grad_logp[:, None] @ policy_weights.T, error


def trunk_policy_path_only(features, policy_weights, value_weights, actions, logp_old, advantages, returns, epsilon,
                           value_coef):  # fmt: skip
    """Only the policy head's gradient carried into h; the value head's path forgotten."""
    clip_value, policy_grad, error = _trunk_parts(features, policy_weights, value_weights, actions, logp_old,
                                                  advantages, returns, epsilon)  # fmt: skip
    return -clip_value + value_coef * 0.5 * float(np.mean(error**2)), policy_grad


def trunk_value_sign(features, policy_weights, value_weights, actions, logp_old, advantages, returns, epsilon,
                     value_coef):  # fmt: skip
    """The value path entered with the objective's sign, −c1, in a loss that adds c1 L^VF."""
    clip_value, policy_grad, error = _trunk_parts(features, policy_weights, value_weights, actions, logp_old,
                                                  advantages, returns, epsilon)  # fmt: skip
    value_grad = -value_coef * error[:, None] * value_weights[None, :] / len(actions)
    return -clip_value + value_coef * 0.5 * float(np.mean(error**2)), policy_grad + value_grad


def trunk_value_without_half(features, policy_weights, value_weights, actions, logp_old, advantages, returns, epsilon,
                             value_coef):  # fmt: skip
    """The value path as the gradient of c1 Ê[(V − V^targ)²], without chapter 8's ½."""
    clip_value, policy_grad, error = _trunk_parts(features, policy_weights, value_weights, actions, logp_old,
                                                  advantages, returns, epsilon)  # fmt: skip
    value_grad = 2 * value_coef * error[:, None] * value_weights[None, :] / len(actions)
    return -clip_value + value_coef * 0.5 * float(np.mean(error**2)), policy_grad + value_grad


VARIANTS.update(
    {
        "trunk_policy_path_only": {"shared_trunk_gradient": trunk_policy_path_only},
        "trunk_value_sign": {"shared_trunk_gradient": trunk_value_sign},
        "trunk_value_without_half": {"shared_trunk_gradient": trunk_value_without_half},
    }
)
FIRST_FAILURE.update(
    {
        "trunk_policy_path_only": r"value head's gradient missing",
        "trunk_value_sign": r"value term's sign flipped",
        "trunk_value_without_half": r"without its ½",
    }
)
