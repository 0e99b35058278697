"""minippo's hand-derived update against the same update written with PyTorch autograd (book/_torch_bridge.py):
on random float64 minibatches, for every objective, both action kinds and both network layouts, the loss, the
gradient and the parameters after four Adam steps agree to rounding. Skipped where PyTorch is not installed."""

import csv
import dataclasses

import pytest

torch = pytest.importorskip("torch", reason="PyTorch is not installed; the bridge to autograd needs it")

from book import _torch_bridge as torch_bridge  # noqa: E402

TOLERANCE = 1e-10  # rounding of float64 sums over a minibatch is about 1e-16; a wrong term shows as 1e-3 or more


@pytest.mark.parametrize("kind, shared, objective", torch_bridge.CASES)
def test_pytorch_computes_minippos_loss_gradient_and_adam_update(kind, shared, objective):
    row = torch_bridge.compare(kind, shared, objective, seed=3)
    assert row["max_gradient"] > 1e-3  # a gradient to compare, not zeros against zeros
    assert row["clip_fraction"] > 0.05  # some ratios lie outside the band, where L^CLIP's gradient is cut
    assert row["loss_difference"] < TOLERANCE
    assert row["max_gradient_difference"] < TOLERANCE
    assert row["max_parameter_difference"] < TOLERANCE


def test_a_wrong_term_is_caught():
    """The comparison can fail: PyTorch without the entropy bonus differs from minippo far above the tolerance."""
    agent, mb, config = torch_bridge.random_case("discrete", False, "clip", seed=3)
    theta = torch.tensor(agent.params, requires_grad=True)
    torch_bridge.loss_and_grad(theta, agent, mb, config)
    with_bonus = theta.grad.clone()
    config = dataclasses.replace(config, entropy_coef=0.0)
    torch_bridge.loss_and_grad(theta, agent, mb, config)
    assert float((with_bonus - theta.grad).abs().max()) > 1e3 * TOLERANCE


def test_the_record_the_book_shows_covers_every_case_within_the_tolerance():
    with open(torch_bridge.CSV_PATH, newline="") as handle:
        rows = list(csv.DictReader(handle))
    cases = {(row["kind"], row["layout"] == "shared", row["objective"]) for row in rows}
    assert cases == set(torch_bridge.CASES)
    for row in rows:
        differences = ("loss_difference", "max_gradient_difference", "max_parameter_difference")
        worst = max(float(row[key]) for key in differences)
        assert worst < TOLERANCE, row
