"""Named settings of ``Config``: the paper's MuJoCo settings, and the course's two CartPole settings.

Each is a dict of Config fields: ``Config(**CARTPOLE_PPO, seed=3)``.
"""

# The paper's Table 3 (MuJoCo), with ε = 0.2 from its Table 1 and N = 1 actor: Config's defaults are these.
MUJOCO = dict(num_envs=1, horizon=2048, lr=3e-4, epochs=10, minibatch_size=64, gamma=0.99, gae_lambda=0.95)
MUJOCO.update(clip_epsilon=0.2)

# CartPole needs none of observation normalisation, reward scaling and value clipping, which later chapters teach.
# The vanilla setting (chapters 3, 5, 6): Â = discounted return − V (no GAE), no entropy bonus, and a step size large
# enough for forty steps on one batch to show what they do.
CARTPOLE_VANILLA = dict(
    env_id="CartPole-v1",
    use_gae=False,
    horizon=512,
    lr=2.5e-3,
    entropy_coef=0.0,
    normalize_observations=False,
    scale_rewards=False,
    clip_value_loss=False,
)
# The PPO setting (chapters 8 to 10 and the learning tests): GAE, K = 4 epochs of minibatches of 128, an entropy
# bonus c2 = 0.01 and the gentler step size 2.5e-4.
CARTPOLE_PPO = dict(
    env_id="CartPole-v1",
    horizon=512,
    minibatch_size=128,
    epochs=4,
    entropy_coef=0.01,
    normalize_observations=False,
    scale_rewards=False,
    clip_value_loss=False,
    lr=2.5e-4,
)
