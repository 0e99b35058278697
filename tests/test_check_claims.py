"""tools/check_claims.py: every assert of a page becomes a recorded claim, so one execution per draw gives the verdict
of each claim on it (held, failed, or not reached after an error), and the exit status says whether all held."""

import csv
import importlib.util
import json
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.book  # small books' pages executed under several draws

ROOT = Path(__file__).resolve().parent.parent
spec = importlib.util.spec_from_file_location("check_claims", ROOT / "tools" / "check_claims.py")
check_claims = importlib.util.module_from_spec(spec)
sys.modules["check_claims"] = check_claims
spec.loader.exec_module(check_claims)

PAGE = """\
---
kernelspec:
  name: python3
  display_name: Python 3
jupytext:
  text_representation:
    format_name: myst
---
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
