"""The PyTorch PPO of book/_torch_ppo.py: its minibatch loss is minippo's (checked with the harness of
book/_torch_bridge.py, in float64), and it learns CartPole-v1. Skipped where PyTorch is not installed."""

import csv
import dataclasses

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="PyTorch is not installed; the PyTorch PPO needs it")

from book import _torch_bridge as torch_bridge  # noqa: E402
from book import _torch_ppo as torch_ppo  # noqa: E402
from minippo.ppo import loss_and_grad as minippo_loss_and_grad  # noqa: E402

TOLERANCE = 1e-10
SEED, BUDGET, SOLVED = 1, 150_000, 195.0  # the record's first seed and step budget; CartPole-v0's "solved" line


def test_the_nn_module_loss_is_minippos_loss_with_the_same_gradient():
    agent, mb, config = torch_bridge.random_case("discrete", False, "clip", seed=3)
    config = dataclasses.replace(
        config, clip_value_loss=False
    )  # the PyTorch PPO, as CleanRL's with clip_vloss off, has no value clipping
    loss, _ = minippo_loss_and_grad(agent, mb, config)
    module = torch_ppo.Agent(mb["obs"].shape[1], agent.act_dim, hidden=config.hidden_sizes[0]).double()
    weights, _ = torch_bridge.layers(torch.tensor(agent.params), agent)
    gradients, _ = torch_bridge.layers(torch.tensor(agent.grads), agent)
    linears = {"policy": module.actor[::2], "value": module.critic[::2]}  # the Linear layers, between the Tanh
    with torch.no_grad():
        for name, layers in linears.items():
            for linear, (W, b) in zip(layers, weights[name]):
                linear.weight.copy_(W.T)  # minippo computes x W + b, nn.Linear x Wᵀ + b
                linear.bias.copy_(b)
    args = torch_ppo.Args(clip_epsilon=config.clip_epsilon, value_coef=config.value_coef)
    args.entropy_coef = config.entropy_coef
    batch = {key: torch.as_tensor(mb[key]) for key in ("obs", "actions", "logp", "advantages", "returns")}
    torch_loss, (approx_kl, clip_fraction) = torch_ppo.ppo_loss(module, batch, args)
    torch_loss.backward()
    assert clip_fraction > 0.05  # some ratios lie outside the band, where L^CLIP's gradient is cut
    assert abs(torch_loss.item() - loss) < TOLERANCE
    for name, layers in linears.items():
        for linear, (grad_W, grad_b) in zip(layers, gradients[name]):
            assert float((linear.weight.grad - grad_W.T).abs().max()) < TOLERANCE
            assert float((linear.bias.grad - grad_b).abs().max()) < TOLERANCE


def test_a_value_of_shape_n_by_1_makes_an_n_by_n_loss():
    """The port bug the appendix shows: (n, 1) − (n,) broadcasts to (n, n), and a perfect critic's loss is not 0."""
    returns = torch.arange(4.0)
    values = returns[:, None]  # V(s_t) = V^targ_t, but in a column as a Linear(64, 1) returns it
    assert ((values - returns) ** 2).shape == (4, 4)
    assert ((values - returns) ** 2).mean().item() > 1
    assert ((values[:, 0] - returns) ** 2).mean().item() == 0


@pytest.mark.slow
def test_the_pytorch_ppo_learns_cartpole():
    torch.set_num_threads(1)
    returns, stats = torch_ppo.train(torch_ppo.Args(seed=SEED, total_steps=BUDGET))
    assert stats[-1]["steps"] <= BUDGET
    assert np.mean(returns[-20:]) >= SOLVED


def test_the_record_the_book_shows_learns_on_every_seed():
    with open(torch_ppo.CSV_PATH, newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) >= 3 and {int(row["seed"]) for row in rows} >= {SEED}
    for row in rows:
        assert int(row["total_steps"]) == BUDGET
        assert float(row["last_20_return"]) >= SOLVED, row
