"""tools/check_claims.py: every assert of a page becomes a recorded claim, so one execution per draw gives the verdict
of each claim on it (held, failed, or not reached after an error), and the exit status says whether all held."""

import csv
import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.book  # small books' pages executed under several draws

ROOT = Path(__file__).resolve().parent.parent
spec = importlib.util.spec_from_file_location("check_claims", ROOT / "tools" / "check_claims.py")
check_claims = importlib.util.module_from_spec(spec)
sys.modules["check_claims"] = check_claims
spec.loader.exec_module(check_claims)

FRONT_MATTER = """\
---
kernelspec:
  name: python3
  display_name: Python 3
jupytext:
  text_representation:
    format_name: myst
---
"""

PAGE = (
    FRONT_MATTER
    + """\
# A page

```{code-cell} ipython3
import os

draw = int(os.environ["BOOK_SEED"])
assert draw < 1  # holds in draw 0 only
for k in range(3):
    assert k < 3  # holds every time it is evaluated
```

Some prose.

```{code-cell} ipython3
if draw == 1:
    raise RuntimeError("this draw stops here")
assert draw >= 0, "a message"
```
"""
)


@pytest.mark.timeout(180)
def test_claims_are_recorded_per_draw_with_failures_and_unreached_ones(tmp_path):
    book = tmp_path / "book"
    book.mkdir()
    (book / "page.md").write_text(PAGE)
    (book / "prose.md").write_text("# No code here\n")
    out = tmp_path / "claims.csv"
    status = check_claims.main(["--book", str(book), "--seeds", "0-1", "--jobs", "2", "--out", str(out)])
    assert status == 1
    with open(out, newline="") as handle:
        rows = list(csv.DictReader(handle))
    verdicts = {(row["line"], row["seed"]): row["verdict"] for row in rows}
    assert {row["page"] for row in rows} == {"page"}  # a page without code is not executed
    assert verdicts == {
        ("15", "0"): "held",
        ("15", "1"): "failed",
        ("17", "0"): "held",
        ("17", "1"): "held",
        ("25", "0"): "held",
        ("25", "1"): "not reached",
    }
    assert {row["claim"] for row in rows if row["line"] == "15"} == {"assert draw < 1"}


@pytest.mark.timeout(180)
def test_a_book_whose_claims_all_hold_exits_zero(tmp_path):
    book = tmp_path / "book"
    book.mkdir()
    (book / "page.md").write_text(
        PAGE.replace("draw < 1", "draw < 2").replace('raise RuntimeError("this draw stops here")', "pass")
    )
    status = check_claims.main(["--book", str(book), "--seeds", "0,1", "--jobs", "1", "--out", str(tmp_path / "c.csv")])
    assert status == 0


def test_bad_seeds_are_one_line_errors(capsys):
    with pytest.raises(SystemExit) as stop:
        check_claims.main(["--seeds", "zero", "--out", "/dev/null"])
    assert stop.value.code == 2
    assert "--seeds takes integers" in capsys.readouterr().err


@pytest.mark.timeout(180)
def test_update_replaces_only_the_draws_it_runs(tmp_path):
    book = tmp_path / "book"
    book.mkdir()
    (book / "page.md").write_text(PAGE)
    out = tmp_path / "claims.csv"
    assert check_claims.main(["--book", str(book), "--seeds", "0", "--jobs", "1", "--out", str(out)]) == 0
    (book / "page.md").write_text(PAGE.replace("draw < 1", "draw < 5"))  # the page changed: draw 1 now holds
    assert check_claims.main(["--book", str(book), "--seeds", "1", "--jobs", "1", "--out", str(out), "--update"]) == 1
    with open(out, newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert sorted({row["seed"] for row in rows}) == ["0", "1"]
    assert {row["claim"] for row in rows if row["seed"] == "1" and row["line"] == "15"} == {"assert draw < 5"}
    assert len(json.loads(out.with_suffix(".json").read_text())["runs"]) == 2


MARGIN_PAGE = (
    FRONT_MATTER
    + """\
# Slack

```{code-cell} ipython3
import os

import numpy as np

draw = int(os.environ["BOOK_SEED"])
values = np.array([1.0, 2.0, 3.0]) + draw
assert 0.5 < values.min() < 100 and np.all(values > 0.25) and values.size == 3
assert np.any(values > 2.5 + draw) and all(v < 50 for v in values)
assert "text" != "other"
```
"""
)


@pytest.mark.timeout(180)
def test_each_ordered_comparison_records_its_slack_in_the_compared_units(tmp_path):
    book = tmp_path / "book"
    book.mkdir()
    (book / "page.md").write_text(MARGIN_PAGE)
    out = tmp_path / "claims.csv"
    assert check_claims.main(["--book", str(book), "--seeds", "0,2", "--jobs", "1", "--out", str(out)]) == 0
    rows = {(row["line"], row["seed"]): row for row in csv.DictReader(open(out, newline=""))}
    # draw 2: values = 3, 4, 5. Atoms in source order: 0.5 < min, min < 100, all(values > 0.25); the == has none
    # each slack a pair: the difference, and log(larger / smaller) where both sides are positive
    slacks = json.loads(rows["18", "2"]["slacks"])
    assert slacks == {
        "0": [2.5, pytest.approx(np.log(6), rel=1e-5)],
        "1": [97.0, pytest.approx(np.log(100 / 3), rel=1e-5)],
        "2": [2.75, pytest.approx(np.log(12), rel=1e-5)],
    }
    assert float(rows["18", "2"]["margin"]) == pytest.approx(2.5 / 3)  # the tightest relative to its larger side
    # any: the largest element's slack (5 - 4.5); all over a generator: the smallest (50 - 5)
    slacks = json.loads(rows["19", "2"]["slacks"])
    assert slacks == {
        "0": [0.5, pytest.approx(np.log(5 / 4.5), rel=1e-5)],
        "1": [45.0, pytest.approx(np.log(10), rel=1e-5)],
    }
    assert rows["20", "0"]["slacks"] == "{}" and rows["20", "0"]["margin"] == ""


def _rows(slacks, verdicts=None):
    verdicts = verdicts or ["held"] * len(slacks)
    return [
        {
            "page": "p",
            "line": "1",
            "claim": "assert x > 0",
            "env": "",
            "seed": str(seed),
            "verdict": verdict,
            "margin": "",
            "slacks": json.dumps({"0": slack if isinstance(slack, list) else [slack, None]}),
        }
        for seed, (slack, verdict) in enumerate(zip(slacks, verdicts))
    ]


def test_a_claim_stands_only_when_its_slack_clears_the_prediction_bound():
    steady = [1.0 + 0.01 * k for k in range(16)]  # mean 1.075, sd 0.048: 22 spreads
    spread = [0.5 + (0.3 if k % 2 else -0.3) for k in range(16)]  # held on every draw, mean 0.5, sd 0.31: 1.6 spreads
    (judged,) = check_claims.judge(_rows(steady))
    assert judged["status"] == "stands" and judged["spreads"] > 20
    (judged,) = check_claims.judge(_rows(spread))
    assert judged["status"] == "thin" and 1.5 < judged["spreads"] < 1.7
    (judged,) = check_claims.judge(_rows(steady, ["held"] * 15 + ["failed"]))
    assert judged["status"] == "failed"
    (judged,) = check_claims.judge(_rows(spread[:4]))  # too few draws to judge a spread: only the verdicts
    assert judged["status"] == "held"
    (judged,) = check_claims.judge(_rows([0.0] * 16))  # an exact claim that never moves (x <= 0 with x = 0)
    assert judged["status"] == "stands" and judged["spreads"] is None
    assert 3.8 < check_claims.needed_spreads(16) < 3.9 and 5.0 < check_claims.needed_spreads(8) < 5.1


def test_a_draw_far_on_the_safe_side_is_not_counted_as_risk():
    """β ≤ 0.125 met by a factor of 2 on 15 draws (slack log 2 ≈ 0.69) and by a factor of 100 on one: the ordinary
    standard deviation would call the claim thin, the spread below the mean sees no risk at all."""
    pairs = [[0.0625, np.log(2)]] * 15 + [[0.12375, np.log(100)]]
    (judged,) = check_claims.judge(_rows(pairs))
    assert judged["status"] == "stands"
    assert check_claims.downside_spread([1.0, 2.0, 3.0]) == pytest.approx(1.0)  # √(2 · 1 / 2)


def test_two_sides_of_one_sign_are_judged_on_the_log_scale():
    """x > 10 with x = 10 e^u, u evenly over 2 … 3.4: the differences x − 10 have a long right tail (2.7 spreads,
    thin), but x is a factor of e² or more above its bound on every draw (6.1 spreads on the log scale)."""
    us = [2 + 1.4 * k / 15 for k in range(16)]
    pairs = [[10 * np.exp(u) - 10, u] for u in us]
    (judged,) = check_claims.judge(_rows(pairs))
    assert judged["status"] == "stands" and 6.0 < judged["spreads"] < 6.2
    (judged,) = check_claims.judge(_rows([[d, None] for d, _ in pairs]))  # the same on a difference scale only
    assert judged["status"] == "thin" and 2.6 < judged["spreads"] < 2.8


def test_an_errors_size_against_a_tolerance_is_judged_as_a_difference():
    """|e| < 5 σ with e ~ N(0, σ²), which fails about once in two million draws: on the log scale the slack
    log(5σ / |e|) has its risk stretched out (about 3 spreads, thin), as a difference 5σ − |e| it is about 6 spreads.
    The same slacks under a claim without abs stay on the log scale."""
    from scipy.stats import norm

    errors = np.abs(norm.ppf((np.arange(16) + 0.5) / 16))  # |e| at 16 evenly spaced quantiles, σ = 1
    pairs = [[5 - e, float(np.log(5 / e))] for e in errors]
    rows = _rows(pairs)
    for row in rows:
        row["claim"] = "assert abs(mc - exact) < 5 * stderr"
    (judged,) = check_claims.judge(rows)
    assert judged["status"] == "stands" and judged["spreads"] > 5
    (judged,) = check_claims.judge(_rows(pairs))  # "assert x > 0": the log scale
    assert judged["status"] == "thin" and judged["spreads"] < 3.85
    assert check_claims.distance_atoms("assert np.max(np.abs(h - exact)) < 0.1 and 0 < x < 3") == {0}
    assert check_claims.distance_atoms("assert all(abs(r - 1) < 0.2 for r in rs) and 0.5 > abs(y)") == {0, 1}
    assert check_claims.distance_atoms("assert abs(a - c) < abs(b - c)") == set()  # two sizes: a factor apart
    assert check_claims.distance_atoms("assert -0.005 < a - b < 0.05") == set()


def test_report_judges_the_record_without_running_anything(tmp_path, capsys):
    out = tmp_path / "claims.csv"
    with open(out, "w", newline="") as handle:
        writer = csv.DictWriter(handle, check_claims.FIELDS)
        writer.writeheader()
        writer.writerows(_rows([0.5 + (0.3 if k % 2 else -0.3) for k in range(16)]))
    assert check_claims.main(["--report", "--out", str(out)]) == 1
    printed = capsys.readouterr().out
    assert "| thin |" in printed and "rule: held on all 16 draws and median slack >= 3.85 sd" in printed


@pytest.mark.timeout(180)
def test_relocate_moves_rows_of_unchanged_code_and_names_pages_whose_code_changed(tmp_path, capsys):
    book = tmp_path / "book"
    book.mkdir()
    (book / "page.md").write_text(MARGIN_PAGE)
    out = tmp_path / "claims.csv"
    assert check_claims.main(["--book", str(book), "--seeds", "0", "--jobs", "1", "--out", str(out)]) == 0
    (book / "page.md").write_text(MARGIN_PAGE.replace("# Slack\n", "# Slack\n\nA new paragraph.\n\n"))
    assert check_claims.main(["--relocate", "--book", str(book), "--out", str(out)]) == 0
    assert sorted(int(row["line"]) for row in csv.DictReader(open(out, newline=""))) == [21, 22, 23]
    (book / "page.md").write_text(MARGIN_PAGE.replace("+ draw", "+ 2 * draw"))  # the code changed
    assert check_claims.main(["--relocate", "--book", str(book), "--out", str(out)]) == 1
    assert "code changed since their rows were made: page" in capsys.readouterr().out
