"""Other correct ways to write chapter 4."""

import numpy as np


def cpi_objective_dot(logp, logp_old, advantages):
    """r Â summed with a dot product."""
    ratio = np.exp(logp - logp_old)
    n = len(ratio)
    return float(ratio @ advantages / n), ratio * advantages / n


VARIANTS = {"cpi_objective_dot": {"cpi_objective": cpi_objective_dot}}
