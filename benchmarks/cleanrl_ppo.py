"""CleanRL's PPO in PyTorch, for runs of the doctor's campaign (benchmarks/doctor_runs.py) that a CleanRL user would
have made: the algorithm, defaults, TensorBoard tags and global_step of ``cleanrl/ppo.py`` (discrete actions) and
``cleanrl/ppo_continuous_action.py`` (continuous), vwxyzjn/cleanrl at commit
fe8d8a03c41a7ef5b523e2e354bd01c363e786bb, written anew from reading them (this is not their code).

Two things differ from those files, both forced by gymnasium 1.x, which they predate: the vector environment resets an
environment in the step that ends it (``AutoresetMode.SAME_STEP``, gymnasium 0.29's behaviour, which their rollout
assumes), and a finished episode's statistics are read from the dict of arrays gymnasium 1.x puts in
``infos["final_info"]``. Weights & Biases, videos and saving the model are left out.
"""

from __future__ import annotations

import math
import random
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

# the Args defaults of each script (the run-time fields batch_size, minibatch_size and num_iterations are filled in
# by ``train``, as the scripts fill them before logging their hyperparameters)
PPO = dict(exp_name="ppo", seed=1, torch_deterministic=True, env_id="CartPole-v1", total_timesteps=500_000,
           learning_rate=2.5e-4, num_envs=4, num_steps=128, anneal_lr=True, gamma=0.99, gae_lambda=0.95,
           num_minibatches=4, update_epochs=4, norm_adv=True, clip_coef=0.2, clip_vloss=True, ent_coef=0.01,
           vf_coef=0.5, max_grad_norm=0.5, target_kl=None)  # fmt: skip
PPO_CONTINUOUS_ACTION = dict(PPO, exp_name="ppo_continuous_action", env_id="HalfCheetah-v4", total_timesteps=1_000_000,
                             learning_rate=3e-4, num_envs=1, num_steps=2048, num_minibatches=32, update_epochs=10,
                             ent_coef=0.0)  # fmt: skip
DEFAULTS = {"ppo": PPO, "ppo_continuous_action": PPO_CONTINUOUS_ACTION}


def wrapped(make_env, continuous: bool, gamma: float) -> gym.Env:
    """The task from ``make_env()`` with the script's wrappers, in its order."""
    if not continuous:
        return gym.wrappers.RecordEpisodeStatistics(make_env())
    env = gym.wrappers.RecordEpisodeStatistics(gym.wrappers.FlattenObservation(make_env()))
    env = gym.wrappers.NormalizeObservation(gym.wrappers.ClipAction(env))
    env = gym.wrappers.TransformObservation(env, lambda obs: np.clip(obs, -10, 10), env.observation_space)
    return gym.wrappers.TransformReward(gym.wrappers.NormalizeReward(env, gamma=gamma), lambda r: np.clip(r, -10, 10))


def networks(obs_size: int, outputs: int):
    """The critic and the actor: two separate tanh MLPs of 64 × 64, orthogonal weights with gains √2, then 1 (critic)
    or 0.01 (actor), zero biases; and the continuous policy's state-independent log σ, starting at 0."""
    import torch
    from torch import nn

    def layer(n_in, n_out, gain):
        linear = nn.Linear(n_in, n_out)
        nn.init.orthogonal_(linear.weight, gain)
        nn.init.zeros_(linear.bias)
        return linear

    def mlp(n_out, gain):
        hidden = math.sqrt(2)
        layers = [layer(obs_size, 64, hidden), nn.Tanh(), layer(64, 64, hidden), nn.Tanh(), layer(64, n_out, gain)]
        return nn.Sequential(*layers)

    return mlp(1, 1.0), mlp(outputs, 0.01), nn.Parameter(torch.zeros(1, outputs))


def train(args: dict, continuous: bool, make_env, folder) -> tuple[int, int]:
    """PPO with ``args`` (a dict of DEFAULTS' fields) on ``num_envs`` copies of ``make_env()``, logging to a
    TensorBoard events file in ``folder``. Returns (global_step, iterations)."""
    import torch
    from torch import nn
    from torch.utils.tensorboard import SummaryWriter

    batch = args["num_envs"] * args["num_steps"]
    a = dict(args, batch_size=batch, minibatch_size=batch // args["num_minibatches"])
    a["num_iterations"] = a["total_timesteps"] // batch
    writer = SummaryWriter(str(Path(folder)))
    writer.add_text("hyperparameters", "|param|value|\n|-|-|\n" + "\n".join(f"|{k}|{v}|" for k, v in a.items()))
    random.seed(a["seed"])
    np.random.seed(a["seed"])
    torch.manual_seed(a["seed"])
    torch.backends.cudnn.deterministic = a["torch_deterministic"]
    n, horizon, batch, iterations = a["num_envs"], a["num_steps"], a["batch_size"], a["num_iterations"]
    envs = gym.vector.SyncVectorEnv([lambda: wrapped(make_env, continuous, a["gamma"])] * n,
                                    autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)  # fmt: skip
    obs_size, space = int(np.prod(envs.single_observation_space.shape)), envs.single_action_space
    critic, actor, log_std = networks(obs_size, int(np.prod(space.shape)) if continuous else int(space.n))
    params = [*critic.parameters(), *actor.parameters()] + ([log_std] if continuous else [])
    optimizer = torch.optim.Adam(params, lr=a["learning_rate"], eps=1e-5)

    def policy(obs):
        """π(·|obs): (log π(a|obs), entropy, a sampler); a Gaussian's log-density and entropy sum over the action."""
        out = actor(obs)
        if continuous:
            gauss = torch.distributions.Normal(out, log_std.expand_as(out).exp())
            return lambda act: gauss.log_prob(act).sum(1), lambda: gauss.entropy().sum(1), gauss.sample
        cat = torch.distributions.Categorical(logits=out)
        return lambda act: cat.log_prob(act.long()), cat.entropy, cat.sample

    shape = (horizon, n)
    obs, actions = torch.zeros(shape + (obs_size,)), torch.zeros(shape + space.shape)
    logps, rewards, dones, values = (torch.zeros(shape) for _ in range(4))
    global_step, start, order = 0, time.time(), np.arange(batch)
    next_obs, next_done = torch.tensor(envs.reset(seed=a["seed"])[0], dtype=torch.float32), torch.zeros(n)
    for iteration in range(1, iterations + 1):
        if a["anneal_lr"]:
            optimizer.param_groups[0]["lr"] = (1.0 - (iteration - 1.0) / iterations) * a["learning_rate"]
        for t in range(horizon):
            global_step += n
            obs[t], dones[t] = next_obs, next_done
            with torch.no_grad():
                log_prob, _, sample = policy(next_obs)
                actions[t] = sample()
                logps[t], values[t] = log_prob(actions[t]), critic(next_obs).flatten()
            step = envs.step(actions[t].numpy() if continuous else actions[t].long().numpy())
            next_obs, reward, terminated, truncated, infos = step
            next_obs, rewards[t] = torch.tensor(next_obs, dtype=torch.float32), torch.tensor(reward).view(-1)
            next_done = torch.tensor(np.logical_or(terminated, truncated), dtype=torch.float32)
            ended = infos.get("final_info", {})
            for i in np.flatnonzero(ended.get("_episode", [])):
                writer.add_scalar("charts/episodic_return", ended["episode"]["r"][i], global_step)
                writer.add_scalar("charts/episodic_length", ended["episode"]["l"][i], global_step)
        with torch.no_grad():  # GAE (eq. 11 of the PPO paper); a time limit ends the episode as a termination does
            advantages, last, next_value = torch.zeros(shape), 0.0, critic(next_obs).flatten()
            for t in reversed(range(horizon)):
                nonterminal = 1.0 - (next_done if t == horizon - 1 else dones[t + 1])
                following = next_value if t == horizon - 1 else values[t + 1]
                delta = rewards[t] + a["gamma"] * following * nonterminal - values[t]
                advantages[t] = last = delta + a["gamma"] * a["gae_lambda"] * nonterminal * last
            returns = advantages + values
        b_obs, b_actions = obs.reshape(batch, obs_size), actions.reshape((batch,) + space.shape)
        b_logps, b_adv, b_returns, b_values = (x.reshape(-1) for x in (logps, advantages, returns, values))
        clipfracs = []
        for _ in range(a["update_epochs"]):
            np.random.shuffle(order)  # in place: each epoch shuffles the order the one before left
            for first in range(0, batch, a["minibatch_size"]):
                idx = order[first : first + a["minibatch_size"]]
                log_prob, entropy, _ = policy(b_obs[idx])
                logratio = log_prob(b_actions[idx]) - b_logps[idx]
                ratio = logratio.exp()
                # the k1 and k3 estimators of KL[π_old ‖ π] (http://joschu.net/blog/kl-approx.html)
                with torch.no_grad():
                    old_approx_kl, approx_kl = (-logratio).mean(), ((ratio - 1) - logratio).mean()
                    clipfracs.append(((ratio - 1.0).abs() > a["clip_coef"]).float().mean().item())
                adv = b_adv[idx]
                if a["norm_adv"]:
                    adv = (adv - adv.mean()) / (adv.std() + 1e-8)
                clipped = torch.clamp(ratio, 1 - a["clip_coef"], 1 + a["clip_coef"])
                pg_loss = torch.max(-adv * ratio, -adv * clipped).mean()
                value = critic(b_obs[idx]).view(-1)
                v_loss = (value - b_returns[idx]) ** 2
                if a["clip_vloss"]:
                    v_clip = b_values[idx] + torch.clamp(value - b_values[idx], -a["clip_coef"], a["clip_coef"])
                    v_loss = torch.max(v_loss, (v_clip - b_returns[idx]) ** 2)
                v_loss, entropy_loss = 0.5 * v_loss.mean(), entropy().mean()
                loss = pg_loss - a["ent_coef"] * entropy_loss + a["vf_coef"] * v_loss
                optimizer.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(params, a["max_grad_norm"])
                optimizer.step()
            if a["target_kl"] is not None and approx_kl > a["target_kl"]:
                break
        y_pred, y_true = b_values.numpy(), b_returns.numpy()
        var_y = np.var(y_true)
        explained_var = np.nan if var_y == 0 else 1 - np.var(y_true - y_pred) / var_y
        logged = {"charts/learning_rate": optimizer.param_groups[0]["lr"], "losses/value_loss": v_loss.item(),
                  "losses/policy_loss": pg_loss.item(), "losses/entropy": entropy_loss.item(),
                  "losses/old_approx_kl": old_approx_kl.item(), "losses/approx_kl": approx_kl.item(),
                  "losses/clipfrac": np.mean(clipfracs), "losses/explained_variance": explained_var,
                  "charts/SPS": int(global_step / (time.time() - start))}  # fmt: skip
        for tag, value in logged.items():
            writer.add_scalar(tag, value, global_step)
    envs.close()
    writer.close()
    return global_step, iterations
