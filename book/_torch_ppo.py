"""PPO for discrete actions in PyTorch, in the shape of CleanRL's ppo.py: an ``nn.Module`` agent and one training
loop that reads top to bottom like the paper's Algorithm 1, in float32, with autograd in place of minippo's
hand-derived backward passes. The appendix "From minippo to PyTorch" (pytorch-bridge.md) shows and explains it;
tests/test_torch_ppo.py trains CartPole-v1 with it. From the repository's root:

    python -m book._torch_ppo --seeds 1 2 3 --total-steps 150000

trains three seeds and writes the record the appendix shows, benchmarks/results/torch_ppo.csv.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from torch import nn
from torch.distributions import Categorical

from minippo.records import commit_of_code

ROOT = Path(__file__).resolve().parent.parent
CSV_PATH = ROOT / "benchmarks" / "results" / "torch_ppo.csv"


@dataclass
class Args:
    env_id: str = "CartPole-v1"
    seed: int = 0
    total_steps: int = 150_000  # environment steps in all
    num_envs: int = 4  # N actors
    horizon: int = 128  # T
    epochs: int = 4  # K
    minibatch_size: int = 128  # M
    lr: float = 2.5e-4  # Adam's step size α, annealed linearly to 0
    gamma: float = 0.99  # γ
    gae_lambda: float = 0.95  # λ
    clip_epsilon: float = 0.2  # ε
    value_coef: float = 0.5  # c1, on ½ (V − V^targ)² as in minippo
    entropy_coef: float = 0.01  # c2
    max_grad_norm: float = 0.5


def layer(fan_in, fan_out, gain):
    """A linear layer with orthogonal weights of the given gain and zero biases (chapter 1)."""
    linear = nn.Linear(fan_in, fan_out)
    nn.init.orthogonal_(linear.weight, gain)
    nn.init.zeros_(linear.bias)
    return linear


class Agent(nn.Module):
    """Two 64-64 tanh MLPs: the actor's logits of π_θ(a|s) and the critic's V(s)."""

    def __init__(self, obs_dim, n_actions, hidden=64):
        super().__init__()

        def mlp(out, gain):
            trunk = [layer(obs_dim, hidden, np.sqrt(2)), nn.Tanh(), layer(hidden, hidden, np.sqrt(2)), nn.Tanh()]
            return nn.Sequential(*trunk, layer(hidden, out, gain))

        self.actor = mlp(n_actions, 0.01)  # logits near 0: π starts near uniform
        self.critic = mlp(1, 1.0)

    def value(self, obs):
        return self.critic(obs).squeeze(-1)  # shape (n,), not (n, 1): see the port bugs on the page

    def policy(self, obs):
        return Categorical(logits=self.actor(obs))


def ppo_loss(agent, mb, args):
    """−(L^CLIP − c1 L^VF + c2 S) (eq. 9) on one minibatch, and its approx KL and clip fraction before the step."""
    dist = agent.policy(mb["obs"])
    log_ratio = dist.log_prob(mb["actions"]) - mb["logp"]
    ratio = torch.exp(log_ratio)  # r_t(θ) = π_θ(a_t|s_t) / π_θold(a_t|s_t) (eq. 6)
    advantages = mb["advantages"]
    advantages = (advantages - advantages.mean()) / (advantages.std(correction=0) + 1e-8)  # minippo's n, not n − 1
    clipped = ratio.clamp(1 - args.clip_epsilon, 1 + args.clip_epsilon)
    clip_objective = torch.min(ratio * advantages, clipped * advantages).mean()  # eq. 7
    value_loss = 0.5 * ((agent.value(mb["obs"]) - mb["returns"]) ** 2).mean()  # L^VF, (V_θ(s_t) − V^targ_t)²
    loss = -clip_objective + args.value_coef * value_loss - args.entropy_coef * dist.entropy().mean()
    return loss, diagnostics(log_ratio.detach(), args.clip_epsilon)


def diagnostics(log_ratio, clip_epsilon):
    """approx KL, the mean of (r − 1) − log r (chapter 4), and the share of ratios outside [1 − ε, 1 + ε]."""
    ratio = log_ratio.exp()
    return ((ratio - 1) - log_ratio).mean().item(), ((ratio - 1).abs() > clip_epsilon).float().mean().item()


def gae(buffer, gamma, lam):
    """Â_t = δ_t + γλ Â_{t+1} (eq. 11), δ_t = r_t + γ V(s_{t+1}) − V(s_t), with no V(s_{t+1}) after a termination."""
    terminated, truncated = buffer["terminated"], buffer["truncated"]
    deltas = buffer["rewards"] + gamma * buffer["next_values"] * (1 - terminated) - buffer["values"]
    advantages = torch.zeros_like(deltas)
    following = torch.zeros_like(deltas[0])
    for t in reversed(range(len(deltas))):
        # an episode that ended at t (either way) passes nothing back to step t from the next one
        following = advantages[t] = deltas[t] + gamma * lam * (1 - terminated[t]) * (1 - truncated[t]) * following
    return advantages


def train(args: Args):
    """Run PPO for ``args.total_steps``; return the completed episodes' returns and one row of statistics per update."""
    torch.manual_seed(args.seed)
    envs = [gym.make(args.env_id) for _ in range(args.num_envs)]
    obs = np.stack([env.reset(seed=args.seed + i)[0] for i, env in enumerate(envs)])
    agent = Agent(envs[0].observation_space.shape[0], envs[0].action_space.n)
    optimizer = torch.optim.Adam(agent.parameters(), lr=args.lr, eps=1e-5)
    T, N = args.horizon, args.num_envs
    buffer = {key: torch.zeros(T, N) for key in ("logp", "values", "next_values", "rewards", "terminated", "truncated")}
    buffer["obs"], buffer["actions"] = torch.zeros(T, N, len(obs[0])), torch.zeros(T, N, dtype=torch.long)
    episode_returns, running_return, stats = [], np.zeros(N), []
    updates = args.total_steps // (T * N)
    for update in range(updates):
        optimizer.param_groups[0]["lr"] = args.lr * (1 - update / updates)  # α falls linearly to 0

        with torch.no_grad():  # the rollout: π_θold acts, nothing here needs a gradient
            for t in range(T):
                buffer["obs"][t] = observation = torch.as_tensor(obs, dtype=torch.float32)
                dist = agent.policy(observation)
                buffer["actions"][t] = actions = dist.sample()
                buffer["logp"][t], buffer["values"][t] = dist.log_prob(actions), agent.value(observation)
                for i, env in enumerate(envs):
                    obs[i], reward, terminated, truncated, _ = env.step(int(actions[i]))
                    buffer["rewards"][t, i], running_return[i] = reward, running_return[i] + reward
                    buffer["terminated"][t, i], buffer["truncated"][t, i] = terminated, truncated and not terminated
                    if terminated or truncated:
                        if truncated and not terminated:  # a time limit, not a terminal state: V of where it stopped
                            final = torch.as_tensor(obs[i], dtype=torch.float32)
                            buffer["next_values"][t, i] = agent.value(final[None])[0]
                        episode_returns.append(running_return[i])
                        running_return[i] = 0.0
                        obs[i], _ = env.reset()
            # V(s_{t+1}) is the next row's V(s_t) inside an episode, and V(s_T) after the batch
            inside = 1 - buffer["terminated"] - buffer["truncated"]
            following = torch.cat([buffer["values"][1:], agent.value(torch.as_tensor(obs, dtype=torch.float32))[None]])
            buffer["next_values"] = inside * following + buffer["truncated"] * buffer["next_values"]
            advantages = gae(buffer, args.gamma, args.gae_lambda)
            batch = {key: buffer[key].flatten(0, 1) for key in ("obs", "actions", "logp")}
            batch["advantages"] = advantages.flatten()
            batch["returns"] = (advantages + buffer["values"]).flatten()  # V^targ_t = Â_t + V(s_t)

        during = []  # (approx KL, clip fraction) of each minibatch before its step: CleanRL's and SB3's measure
        for _ in range(args.epochs):  # K epochs of shuffled minibatches of M
            order = torch.randperm(T * N)
            for start in range(0, T * N, args.minibatch_size):
                mb = {key: value[order[start : start + args.minibatch_size]] for key, value in batch.items()}
                loss, measured = ppo_loss(agent, mb, args)
                optimizer.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(agent.parameters(), args.max_grad_norm)
                optimizer.step()
                during.append(measured)
        with torch.no_grad():  # minippo's measure: after the update, on the whole batch
            log_ratio = agent.policy(batch["obs"]).log_prob(batch["actions"]) - batch["logp"]
        approx_kl, clip_fraction = diagnostics(log_ratio, args.clip_epsilon)
        last_epoch = during[-(T * N // args.minibatch_size) :]
        stats.append({"steps": (update + 1) * T * N, "approx_kl": approx_kl, "clip_fraction": clip_fraction})
        # SB3 logs the KL's mean over the last epoch's minibatches, and both libraries the clip fraction's over all
        stats[-1]["minibatch_approx_kl"] = np.mean([kl for kl, _ in last_epoch])
        stats[-1]["minibatch_clip_fraction"] = np.mean([fraction for _, fraction in during])
    return episode_returns, stats


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--total-steps", type=int, default=Args.total_steps)
    parser.add_argument("--csv", default=str(CSV_PATH), help="the record to write (replaced)")
    cli = parser.parse_args(argv)
    torch.set_num_threads(1)
    extra = {"commit": commit_of_code(("book/_torch_ppo.py",), ROOT), "torch": torch.__version__}
    extra["command"] = "python -m book._torch_ppo " + " ".join(argv if argv is not None else sys.argv[1:])
    rows = []
    for seed in cli.seeds:
        start = time.perf_counter()
        returns, stats = train(Args(seed=seed, total_steps=cli.total_steps))
        row = {"seed": seed, "total_steps": cli.total_steps, "episodes": len(returns)}
        row |= {"last_20_return": np.mean(returns[-20:]), "seconds": time.perf_counter() - start}
        row |= {key: np.mean([update[key] for update in stats]) for key in stats[0] if key != "steps"}
        rows.append(row | extra)
        print(f"seed {seed}: mean return of the last 20 episodes {row['last_20_return']:.1f}, {row['seconds']:.0f} s")
    with open(cli.csv, "w", newline="") as handle:
        writer = csv.DictWriter(handle, list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)


if __name__ == "__main__":
    main()
