"""What the book's pages share, so that each page can stay about PPO: the draw of their seeds, the plot style,
central finite differences (minippo.gradcheck), the two CartPole settings (minippo.presets), one batch collected
from a fresh policy, K epochs of minibatch Adam on that one batch, Markdown tables, and whether a record's commit ran
the code at hand.

Every page imports it first (its cells run with ``book/`` as the working directory).
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

# the pages multiply small matrices, for which extra BLAS threads cost more in start-up than they save
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import matplotlib.pyplot as plt  # noqa: E402
from threadpoolctl import threadpool_limits  # noqa: E402

from minippo.gradcheck import central_differences  # noqa: E402
from minippo.minibatches import epochs_of  # noqa: E402
from minippo.plotting import INK, ORANGE, SAGE  # noqa: E402
from minippo.ppo import Trainer, compute_advantages, flatten, update_minibatch  # noqa: E402
from minippo.presets import CARTPOLE_PPO, CARTPOLE_VANILLA  # noqa: E402
from minippo.toys import corridor  # noqa: E402

threadpool_limits(1, user_api="blas")  # whether NumPy was loaded before this module or not


def _book_seed() -> int:
    text = os.environ.get("BOOK_SEED", "0").strip() or "0"
    if not text.isdigit():
        raise SystemExit(f"BOOK_SEED must be a whole number of 0 or more, not {text!r}")
    return int(text)


# Which draw of the book's experiments this build is: every seed a page uses is ``SEED + k`` for a small k of its
# own. The published book is draw 0 (SEED = 0); ``BOOK_SEED=3 jupyter-book build book/`` builds it under draw 3, whose
# seeds start at 3000 so that no two draws share one, and tools/check_claims.py runs every page under draws 0-7 to
# check that each sentence holds for the experiment, not for one draw of it.
SEED = 1000 * _book_seed()

SLATE = "#4f6d8f"
plt.rcParams.update(
    {
        "figure.dpi": 110,
        # one-column figures are about 5.8 inches wide: 11-point type stays legible when a phone shrinks them to 360 px
        "font.size": 11,
        "axes.grid": True,
        "grid.alpha": 0.3,
        "axes.spines.top": False,
        "axes.spines.right": False,
    }
)

__all__ = [
    "INK",
    "ORANGE",
    "SAGE",
    "SEED",
    "SLATE",
    "CARTPOLE_PPO",
    "CARTPOLE_VANILLA",
    "central_differences",
    "corridor_rounds",
    "epochs_on_one_batch",
    "markdown_table",
    "one_batch",
    "trains_as_now",
    "unchanged_since",
]


def one_batch(config):
    """A fresh ``Trainer`` for ``config`` and one batch its policy π_θold collected, flattened with its advantages."""
    trainer = Trainer(config)
    batch = trainer.rollout.collect()  # run π_θold for T steps
    advantages, returns = compute_advantages(batch, config)
    return trainer, flatten(batch, advantages, returns, trainer.agent.dtype)


def epochs_on_one_batch(trainer, data, epochs, measure):
    """``epochs`` passes of minibatch Adam over one batch (Algorithm 1's inner loop, without the early stop), and
    after each pass ``measure(policy)``, with π_θ on the whole batch; returns the list of what it measured."""
    agent, config = trainer.agent, trainer.config
    measured = []
    for epoch in epochs_of(data, epochs, config.minibatch_size, trainer.rng):
        for minibatch in epoch:
            update_minibatch(agent, trainer.optimizer, minibatch, config)
        out, _, _ = agent.forward(data["obs"])
        measured.append(measure(agent.distribution(out)))
    return measured


def corridor_rounds(settings, ticks, changes=None):
    """Plays the corridor explorer's math (``minippo.toys.corridor``, which the explorer on the page runs step for step)
    and sums the run up by round, so that a page can state what the reader will see when playing it.

    Returns ``{round: {"records", "max_kl", "broken_at", "end"}}``: the round's records, its largest KL, the first
    epoch at which the light read "broken" (None if it held) and its last record. ``settings`` and ``changes`` are as
    for ``corridor.run``.
    """
    rounds = {}
    for record in corridor.run(settings, ticks, changes):
        summary = rounds.setdefault(record["round"], {"records": [], "max_kl": 0.0, "broken_at": None})
        summary["records"].append(record)
        summary["max_kl"] = max(summary["max_kl"], record["kl"])
        if not record["held"] and summary["broken_at"] is None:
            summary["broken_at"] = record["epoch"]
        summary["end"] = record
    return rounds


def markdown_table(header, rows) -> str:
    """A Markdown table (for ``glue`` with ``Markdown`` and a ``{glue:md}`` directive): ``header`` a list of column
    titles, ``rows`` lists of cells, all strings. The theme renders it as an HTML table whose columns wrap their titles,
    so a table of a few short numbers fits a phone where a printed one would not."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join(lines + ["| " + " | ".join(row) + " |" for row in rows])


def unchanged_since(commit: str, paths) -> bool | None:
    """Whether a record made at ``commit`` ran the code at hand: ``commit`` is an ancestor of HEAD, and the files
    ``paths`` (relative to the repository) are the same there as in this working tree. False for a "+dirty" commit
    (its edits are unknown); None where git or the commit is not at hand (no git, or a shallow clone)."""
    if commit.endswith("+dirty"):
        return False
    try:
        if _git("cat-file", "-e", f"{commit}^{{commit}}") != 0:
            return None
    except OSError:
        return None
    if _git("merge-base", "--is-ancestor", commit, "HEAD") != 0:
        return False
    return _git("diff", "--quiet", commit, "--", *paths) == 0


def trains_as_now(commit: str, paths) -> bool | None:
    """Whether the code of a record made at ``commit`` trains bitwise as the code at hand does: ``paths`` are
    unchanged since (``unchanged_since``), or changed only in ways that a committed comparison found to compute the
    same numbers (``proven_same``). For a learning record, not for a speed record (the same numbers may take longer)."""
    unchanged = unchanged_since(commit, paths)
    return unchanged if unchanged is not False else (not commit.endswith("+dirty") and proven_same(commit, paths))


# The tasks on which a change of the training code must have been compared (python -m benchmarks.same_math) before a
# record made by the earlier code stands for the later: a discrete, a continuous and an image task, float32 and float64
SAME_MATH_TASKS = {(task, dtype) for task in ("CartPole-v1", "Hopper-v5", "MinAtar/Breakout-v1")
                   for dtype in ("float32", "float64")}  # fmt: skip


def proven_same(commit: str, paths) -> bool:
    """Whether ``benchmarks/results/same_math.csv`` holds a comparison, earlier commit E against later commit C, with
    no difference at all on every update of every task of ``SAME_MATH_TASKS``, such that ``paths`` are the same at
    ``commit`` as at E (E descends from ``commit``) and the same at C as in this working tree: the record's code and
    the code at hand then train bitwise the same, though their source differs."""
    from minippo.records import read_rows

    rows = read_rows(Path(__file__).resolve().parent.parent / "benchmarks" / "results" / "same_math.csv")
    pairs = {(row["earlier_commit"], row["commit"]) for row in rows}
    for earlier, later in pairs:
        compared = [row for row in rows if (row["earlier_commit"], row["commit"]) == (earlier, later)]
        if {(row["env"], row["dtype"]) for row in compared} < SAME_MATH_TASKS:
            continue
        if any(float(row["max_relative_difference"]) != 0 for row in compared) or later.endswith("+dirty"):
            continue
        before = _git("merge-base", "--is-ancestor", commit, earlier) == 0
        before = before and _git("diff", "--quiet", commit, earlier, "--", *paths) == 0
        after = _git("merge-base", "--is-ancestor", later, "HEAD") == 0
        after = after and _git("diff", "--quiet", later, "--", *paths) == 0
        if before and after:
            return True
    return False


def _git(*args: str) -> int:
    return subprocess.run(["git", *args], cwd=Path(__file__).resolve().parent.parent, capture_output=True).returncode
