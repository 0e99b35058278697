"""minippo: Proximal Policy Optimization in NumPy, with every gradient derived by hand."""

import os

# minippo's matrices are small (64 × 64): a second BLAS thread saves nothing on them and, when the cores are busy,
# spins waiting for the first, which can make training many times slower. One thread, whether NumPy is loaded
# after minippo (the environment variable) or before it (threadpoolctl).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from threadpoolctl import threadpool_limits  # noqa: E402

threadpool_limits(1, user_api="blas")

from minippo.ppo import Config, train  # noqa: E402

__all__ = ["Config", "train"]
__version__ = "0.1.0"
