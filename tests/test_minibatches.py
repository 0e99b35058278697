"""Algorithm 1's inner loop, written once: K epochs, each a new order of the batch cut into minibatches of M."""

import numpy as np

from minippo.minibatches import epochs_of


def test_k_epochs_each_a_new_permutation_cut_into_minibatches_of_m():
    rng, replay = np.random.default_rng(3), np.random.default_rng(3)
    epochs = [list(epoch) for epoch in epochs_of(10, 3, 4, rng)]
    assert len(epochs) == 3
    for epoch in epochs:
        assert [len(index) for index in epoch] == [4, 4, 2]  # the last one shorter: every sample once per epoch
        assert np.array_equal(np.concatenate(epoch), replay.permutation(10))  # one draw per epoch, in turn
    assert rng.random() == replay.random()  # and no other draw


def test_a_batch_of_arrays_is_cut_into_dicts_of_the_same_rows():
    data = {"obs": np.arange(12).reshape(6, 2), "actions": np.arange(6) * 10}
    for epoch in epochs_of(data, 2, 4, np.random.default_rng(0)):
        for minibatch in epoch:
            assert set(minibatch) == {"obs", "actions"}
            assert np.array_equal(minibatch["obs"][:, 0] // 2 * 10, minibatch["actions"])


def test_without_an_rng_every_epoch_takes_the_batch_in_order():
    for epoch in epochs_of(5, 2, 2, None):
        assert [list(index) for index in epoch] == [[0, 1], [2, 3], [4]]


def test_an_epoch_never_started_draws_nothing():
    """PPO's early stop (target_kl) breaks out before the next epoch: the rng it shares with the rollout is left
    where the last epoch run left it."""
    rng, replay = np.random.default_rng(5), np.random.default_rng(5)
    for epoch in epochs_of(8, 10, 4, rng):
        list(epoch)
        break
    replay.permutation(8)
    assert rng.random() == replay.random()
