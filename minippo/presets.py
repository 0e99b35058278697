"""Named settings of ``Config``: the paper's MuJoCo and Atari settings, A2C, and the course's two CartPole settings.

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

# The paper's Table 5 (Atari): N = 8 actors, T = 128, K = 3 epochs, minibatches of 32 × 8 = 256, step size 2.5e-4 × α
# and ε = 0.1 × α with α falling linearly from 1 to 0, c1 = 1, c2 = 0.01, γ = 0.99, λ = 0.95; one network with a policy
# and a value head (eq. 9). minippo's value loss carries a ½ the paper's does not, so value_coef = 1.0 weighs the
# squared error by 0.5, half of Table 5's c1 = 1 (which would be value_coef = 2.0); the MinAtar records were made with
# 1.0. Advantage normalisation and value
# clipping are Config's defaults (OpenAI Baselines' ppo2 does both; Table 5 does not list them). The network is
# MinAtar's (conv 16 3×3, dense 128), not the paper's: the paper used Mnih et al. 2016's for all three algorithms (conv
# 16 8×8 stride 4, conv 32 4×4 stride 2, dense 256, on 84 × 84 × 4 frames); Baselines' code uses the Nature DQN network
# instead (conv 32 8×8/4, conv 64 4×4/2, conv 64 3×3/1, dense 512). A 10 × 10 grid of booleans needs no observation
# normalisation, and MinAtar's rewards are small counts, so neither is scaled (Atari runs usually clip each reward to
# its sign, as the DQN preprocessing and Baselines' Atari wrappers do; the PPO paper does not say).
ATARI = dict(
    num_envs=8,
    horizon=128,
    epochs=3,
    minibatch_size=256,
    lr=2.5e-4,
    anneal_lr=True,
    clip_epsilon=0.1,
    anneal_clip=True,
    gamma=0.99,
    gae_lambda=0.95,
    value_coef=1.0,
    entropy_coef=0.01,
    network="minatar_cnn",
    shared_network=True,
    normalize_observations=False,
    scale_rewards=False,
)

# A2C (Mnih et al. 2016, synchronous), the paper's Atari baseline, from minippo's pieces: the L^PG objective (eq. 2)
# with one gradient step on each batch of N = 16 actors × T = 5 steps, n-step advantages (GAE with λ = 1 is the
# bootstrapped n-step return minus V), c1 = value_coef = 0.5, c2 = 0.01, step size 7e-4 falling to 0, gradient norm
# clipped at 0.5, no advantage normalisation, no value clipping, on the same network and observations as ATARI. These
# are the defaults of OpenAI Baselines' A2C (a2c.learn) as released in August 2017 (commit 3f676f7), whose vf_coef =
# 0.5 weighed a halved squared error as minippo's value_coef does (its a2c since August 2018 drops the ½, which would
# be value_coef = 1.0 here), with Adam (ε = 1e-5) in place of its RMSProp, since minippo has only Adam. They
# are not the paper's: its A2C used settings "tuned to maximize performance" (section 6.4) that it does not list.
A2C = dict(
    ATARI,
    objective="pg",
    num_envs=16,
    horizon=5,
    epochs=1,
    minibatch_size=80,
    lr=7e-4,
    anneal_clip=False,
    gae_lambda=1.0,
    value_coef=0.5,
    shuffle_minibatches=False,
    normalize_advantages=False,
    clip_value_loss=False,
)

# the names ``minippo train --preset`` and ``minippo sweep --preset`` know
PRESETS = {"atari": ATARI, "a2c": A2C, "mujoco": MUJOCO}

