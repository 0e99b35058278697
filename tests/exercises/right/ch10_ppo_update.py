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


VARIANTS = {"ppo_update_shuffle_in_place": {"ppo_update": ppo_update_shuffle_in_place}}
