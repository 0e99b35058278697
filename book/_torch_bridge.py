"""minippo's minibatch update written with PyTorch autograd, and a check that it computes minippo's numbers.

``loss_and_grad`` is ``minippo.ppo.loss_and_grad`` with every hand-derived backward replaced by ``loss.backward()``.
``compare`` builds a random float64 minibatch (a policy π_θold, actions sampled from it, a policy π_θ moved away from
it so that ratios leave the clip band) and returns how far the two losses, the two gradients and the parameters after
a few Adam steps (minippo's ``Adam`` against ``torch.optim.Adam``) lie apart. Run as a script, it checks every
objective, both action kinds and both network layouts and writes the record the book's appendix (pytorch-bridge.md)
shows, from the repository's root:

    python -m book._torch_bridge
"""

from __future__ import annotations

import argparse
import csv
import itertools
import sys
from pathlib import Path

import numpy as np
import torch
from torch.distributions import Categorical, Normal, kl_divergence

from minippo import losses
from minippo.agent import ActorCritic, AgentSpec
from minippo.optimizer import Adam
from minippo.ppo import OBJECTIVES, Config, update_minibatch
from minippo.ppo import loss_and_grad as minippo_loss_and_grad
from minippo.records import commit_of_code

ROOT = Path(__file__).resolve().parent.parent
CSV_PATH = ROOT / "benchmarks" / "results" / "torch_bridge.csv"
FIELDS = ["kind", "layout", "objective", "clip_fraction", "loss", "loss_difference", "max_gradient"]
FIELDS += ["max_gradient_difference", "adam_steps", "max_parameter_difference", "commit", "torch", "command"]


def layers(theta, agent):
    """The (W, b) of every network of ``agent`` as views into the flat tensor θ, in minippo's order, and log σ."""
    nets, offset = {}, 0
    for name, net in agent.nets.items():
        nets[name] = []
        for fan_in, fan_out in zip(net.sizes[:-1], net.sizes[1:]):
            W = theta[offset : offset + fan_in * fan_out].view(fan_in, fan_out)
            b = theta[offset + fan_in * fan_out : offset + fan_in * fan_out + fan_out]
            nets[name].append((W, b))
            offset += fan_in * fan_out + fan_out
    return nets, theta[offset:]


def mlp(weights, x, activate_output=False):
    """tanh between the linear layers, as minippo's MLP."""
    for i, (W, b) in enumerate(weights):
        x = x @ W + b
        if i < len(weights) - 1 or activate_output:
            x = torch.tanh(x)
    return x


def loss_and_grad(theta, agent, mb, config, kl_beta=1.0):
    """−(L^surrogate − c1 L^VF + c2 S) (eq. 9) on one minibatch, its gradient left in ``theta.grad`` by autograd."""
    data = {key: torch.as_tensor(value) for key, value in mb.items()}
    nets, log_std = layers(theta, agent)
    features = mlp(nets["trunk"], data["obs"], activate_output=True) if agent.shared else data["obs"]
    out, values = mlp(nets["policy"], features), mlp(nets["value"], features)[:, 0]
    if agent.kind == "discrete":
        dist, old = Categorical(logits=out), Categorical(logits=data["policy_out"])
        logp, kl, entropy = dist.log_prob(data["actions"]), kl_divergence(old, dist), dist.entropy()
    else:
        dist, old = Normal(out, log_std.exp()), Normal(data["policy_out"], data["policy_log_std"].exp())
        logp = dist.log_prob(data["actions"]).sum(-1)
        kl, entropy = kl_divergence(old, dist).sum(-1), dist.entropy().sum(-1)
    advantages = data["advantages"]
    if config.normalize_advantages and len(advantages) > 1:
        advantages = (advantages - advantages.mean()) / (advantages.std(correction=0) + 1e-8)

    ratio = torch.exp(logp - data["logp"])
    if config.objective == "clip":
        clipped = ratio.clamp(1 - config.clip_epsilon, 1 + config.clip_epsilon)
        objective = torch.min(ratio * advantages, clipped * advantages).mean()
    elif config.objective == "cpi":
        objective = (ratio * advantages).mean()
    elif config.objective == "pg":
        objective = (logp * advantages).mean()
    else:
        objective = (ratio * advantages).mean() - kl_beta * kl.mean()
    squared = (values - data["returns"]) ** 2
    if config.clip_value_loss:
        moved = (values - data["values"]).clamp(-config.clip_epsilon, config.clip_epsilon)
        squared = torch.max(squared, (data["values"] + moved - data["returns"]) ** 2)
    loss = -objective + config.value_coef * 0.5 * squared.mean() - config.entropy_coef * entropy.mean()

    theta.grad = None
    loss.backward()
    return loss.item(), theta.grad.numpy().copy()


def random_case(kind, shared, objective, seed=0, n=64, obs_dim=5, act_dim=3):
    """A float64 agent (π_θ), a minibatch collected by a nearby π_θold, and a Config that switches every term on."""
    rng = np.random.default_rng(seed)
    config = Config(objective=objective, entropy_coef=0.01, shared_network=shared, hidden_sizes=(16, 16))
    agent = ActorCritic(AgentSpec(obs_dim, kind, act_dim, config.hidden_sizes, shared, dtype="float64"), rng)
    agent.params += 0.3 * rng.standard_normal(agent.params.size)  # a policy far from uniform
    obs = rng.standard_normal((n, obs_dim))
    policy_out, values, _ = agent.forward(obs)
    old = agent.distribution(policy_out.copy(), agent.log_std.copy())
    old_log_std = agent.log_std.copy()
    actions = old.sample(rng)
    agent.params += 0.05 * rng.standard_normal(agent.params.size)  # π_θ moved: some ratios leave the clip band
    mb = {
        "obs": obs,
        "actions": actions,
        "logp": old.log_prob(actions),
        "policy_out": policy_out,
        "policy_log_std": np.tile(old_log_std, (n, 1)) if kind == "continuous" else np.zeros((n, 0)),
        "values": values,
        "advantages": rng.standard_normal(n),
        "returns": values + rng.standard_normal(n),
    }
    return agent, mb, config


def compare(kind, shared, objective, seed=0, adam_steps=4) -> dict:
    """How far minippo's and PyTorch's loss, gradient, and parameters after ``adam_steps`` updates lie apart."""
    agent, mb, config = random_case(kind, shared, objective, seed)
    theta = torch.tensor(agent.params, requires_grad=True)
    logp = agent.distribution(agent.policy_output(mb["obs"])).log_prob(mb["actions"])
    clip_fraction = losses.clip_fraction(logp, mb["logp"], config.clip_epsilon)
    loss, _ = minippo_loss_and_grad(agent, mb, config, kl_beta=0.7)
    torch_loss, torch_grad = loss_and_grad(theta, agent, mb, config, kl_beta=0.7)
    row = {"kind": kind, "layout": "shared" if shared else "separate", "objective": objective}
    row |= {"clip_fraction": clip_fraction, "loss": loss, "loss_difference": abs(loss - torch_loss)}
    row["max_gradient"] = float(np.abs(agent.grads).max())
    row["max_gradient_difference"] = float(np.abs(agent.grads - torch_grad).max())
    # the same update with each library's Adam: the gradient-norm clip, then one Adam step per minibatch
    optimizer = Adam(agent.params, lr=config.lr, eps=config.adam_eps)
    torch_optimizer = torch.optim.Adam([theta], lr=config.lr, eps=config.adam_eps)
    for _ in range(adam_steps):
        update_minibatch(agent, optimizer, mb, config, kl_beta=0.7)
        loss_and_grad(theta, agent, mb, config, kl_beta=0.7)
        torch.nn.utils.clip_grad_norm_([theta], config.max_grad_norm)
        torch_optimizer.step()
    row["adam_steps"] = adam_steps
    row["max_parameter_difference"] = float(np.abs(agent.params - theta.detach().numpy()).max())
    return row


CASES = list(itertools.product(("discrete", "continuous"), (False, True), OBJECTIVES))  # kind, shared, objective


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--csv", default=str(CSV_PATH), help="the record to write (replaced)")
    args = parser.parse_args(argv)
    extra = {"commit": commit_of_code(("minippo", "book/_torch_bridge.py"), ROOT), "torch": torch.__version__}
    extra["command"] = "python -m book._torch_bridge"
    rows = [{**compare(*case), **extra} for case in CASES]
    with open(args.csv, "w", newline="") as handle:
        writer = csv.DictWriter(handle, FIELDS, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    worst = max(max(r["loss_difference"], r["max_gradient_difference"], r["max_parameter_difference"]) for r in rows)
    print(f"{len(rows)} cases, largest difference {worst:.1e}; wrote {args.csv}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
