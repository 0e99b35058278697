"""minippo: Proximal Policy Optimization in NumPy, with every gradient derived by hand."""

from minippo.config import Config
from minippo.ppo import train

__all__ = ["Config", "train"]
__version__ = "0.1.0"
