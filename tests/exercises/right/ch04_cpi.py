"""Other correct ways to write chapter 4."""

import numpy as np


def cpi_objective_dot(logp, logp_old, advantages):
    """r Â summed with a dot product."""
    ratio = np.exp(logp - logp_old)
    n = len(ratio)
    return float(ratio @ advantages / n), ratio * advantages / n


VARIANTS = {"cpi_objective_dot": {"cpi_objective": cpi_objective_dot}}


def weighted_by_quotient_rule(logp, logp_old, advantages):
    """The quotient rule written out term by term, without rescaling the ratios."""
    ratio = np.exp(logp - logp_old)
    total, weighted = ratio.sum(), np.sum(ratio * advantages)
    return float(weighted / total), ratio * advantages / total - weighted * ratio / total**2


VARIANTS["weighted_by_quotient_rule"] = {"weighted_cpi_objective": weighted_by_quotient_rule}
