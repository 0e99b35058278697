"""The records the book reads: checks that belong to the repository, not to the page a reader sees."""

import csv
import shutil
import subprocess

import pytest
from conftest import ROOT

ABLATIONS = ROOT / "benchmarks" / "ablations" / "results.csv"


def minippo_tree(commit):
    """The git tree of minippo/ at ``commit`` (a recorded commit may carry a "+dirty" mark), or "" if unknown."""
    query = ["git", "rev-parse", f"{commit.split('+')[0]}:minippo"]
    return subprocess.run(query, cwd=ROOT, capture_output=True, text=True).stdout.strip()


def test_chapter_10s_ablation_records_all_ran_one_minippo_source():
    if not shutil.which("git") or not (ROOT / ".git").exists():
        pytest.skip("no git history to check the recorded commits against")
    with open(ABLATIONS, newline="") as handle:
        commits = {row["commit"] for row in csv.DictReader(handle)}
    assert commits and not any(commit.endswith("+dirty") for commit in commits)
    trees = {commit: minippo_tree(commit) for commit in commits}
    if not all(trees.values()):
        pytest.skip("this clone does not hold every recorded commit (a shallow clone?)")
    assert len(set(trees.values())) == 1, trees
