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


MINATAR = ROOT / "benchmarks" / "results" / "minatar_runs.csv"


def test_chapter_12s_campaign_is_whole_and_its_table_follows_from_the_episodes():
    with open(MINATAR, newline="") as handle:
        runs = list(csv.DictReader(handle))
    games = {row["env"] for row in runs}
    assert len(games) == 5 and len(runs) == 5 * 3 * 2
    assert {(row["algorithm"], row["env"], row["seed"]) for row in runs} == {
        (algorithm, game, seed) for algorithm in ("PPO", "A2C") for game in games for seed in ("1", "2", "3")
    }
    assert len({row["commit"] for row in runs}) == 1  # one code state
    assert len({(row["algorithm"], row["steps"]) for row in runs}) == 2  # one budget per algorithm
    root = ROOT / "benchmarks" / "runs" / "minatar"
    means = {}
    for row in runs:
        folder = root / f"{row['algorithm'].lower()}-{row['env'].replace('/', '-')}-seed{row['seed']}"
        with open(folder / "episodes.csv", newline="") as handle:
            returns = [float(episode["return"]) for episode in csv.DictReader(handle)]
        assert returns and (folder / "progress.csv").exists() and (folder / "config.json").exists()
        means.setdefault((row["algorithm"], row["env"]), []).append((sum(returns) / len(returns), returns[-100:]))
    with open(ROOT / "benchmarks" / "results" / "minatar.csv", newline="") as handle:
        for table_row in csv.DictReader(handle):
            for algorithm in ("PPO", "A2C"):
                seeds = means[(algorithm, table_row["env"])]
                everything = sum(mean for mean, _ in seeds) / 3
                last = sum(sum(tail) / len(tail) for _, tail in seeds) / 3
                assert abs(float(table_row[f"{algorithm}_all_training"]) - everything) < 1e-3
                assert abs(float(table_row[f"{algorithm}_last_100"]) - last) < 1e-3
