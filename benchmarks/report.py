"""benchmarks/results/summary.md, its figures, and the README's result tables, from the scored tables.

    python -m benchmarks.report             # score the records, then write summary.md, the figures and the README block

summary.md is benchmarks/summary_template.md (a person's paragraphs on what each table holds and how it was made)
with each ``<!-- table:NAME -->`` replaced by the table NAME that benchmarks/scoring.py computes.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from benchmarks import scoring
from benchmarks.common import RESULTS, ROOT, RUNS, BenchmarkError, one_line_errors
from minippo.plotting import INK, ORANGE, SAGE, draw_seed_band, read_progress, seed_curves
from minippo.records import read_rows

SEVEN = {"Task": "{task}", "record": "`{record}`", "minippo, mean ± sd": "{mean:,.1f} ± {sd:,.1f}"}
SEVEN |= {"seeds' returns": "{returns}", "paper (Fig. 3, ≈)": "{paper}", "CleanRL (v4)": "{cleanrl}"}
SEVEN |= {"≥ paper's low end": "{at_or_above_paper}", "min per run": "{minutes}", "commits": "{commits}"}
PEERS = {"Task": "{task}", "score": "{score}", "minippo": "{minippo_mean:,.0f} ± {minippo_se:,.0f}"}
PEERS |= {"SB3": "{sb3_mean:,.0f} ± {sb3_se:,.0f}", "seeds": "{seeds}"}
PEERS |= {"minippo − SB3 [95%]": "{diff:+,.0f} [{low:+,.0f}, {high:+,.0f}]", "standing": "{standing}"}
PEERS |= {"min per run (minippo / SB3)": "{minippo_minutes} / {sb3_minutes}"}
TABLE1 = {"Setting": "{setting}", "score ± se": "{score:.2f} ± {score_se}", "paper": "{paper_score:.2f}"}
TABLE1 |= {"runs": "{runs}", "tasks": "{tasks}"}
SCALE = {"Setting": "{setting}", "record": "{record}", "score ± se": "{score:.2f} ± {score_se:.2f}"}
SCALE |= {"runs": "{runs}", "paper": "{paper_score:.2f}"}
SPEED = {"Contender": "{contender}", "steps/s (median)": "{steps_per_s}", "× raw stepping": "{vs_raw}"}
SPEED |= {"× SB3": "{vs_sb3}", "version": "{version}", "machine": "{machine}", "commit": "{commit}"}
SAME = {"Task": "{env}", "seed": "{seed}", "dtype": "{dtype}", "commits": "{earlier_commit} → {commit}"}
SAME |= {"rel. difference, update 1": "{difference_at_update_1}", "parted (> 1%) at update": "{parted_at_update}"}

COLUMNS = {"seven_tasks": SEVEN, "peers": PEERS, "table1_1m": TABLE1, "table1_1m_two_implementations": SCALE}
COLUMNS |= {"table1_1m_more_seeds": SCALE, "same_math": SAME}
TEMPLATE = Path(__file__).with_name("summary_template.md")


def band(ax, folders, colour: str, library: str, **options) -> None:
    """The seed band of the runs in ``folders`` on ``ax``, labelled with the library and the number of seeds."""
    curves = seed_curves([read_progress(folder) for folder in folders])
    if curves is not None:
        draw_seed_band(ax, *curves, colour, f"{library}, {len(folders)} seeds", **options)


def figure_seven_tasks(rows: list[dict], out: Path, runs_root=RUNS / "seven_tasks") -> None:
    fig = Figure(figsize=(13, 5.6), dpi=100)  # no pyplot: nothing to show, nothing to close
    axes = fig.subplots(2, 4)
    for ax, task in zip(axes.flat, scoring.SEVEN_TASKS):
        folders = [Path(runs_root) / f"{task}-seed{r['seed']}" for r in rows if r["env"] == task]
        band(ax, folders, ORANGE, "minippo", alpha=0.25)
        ax.axhline(scoring.PAPER_FIGURE3[task][0], color=INK, ls="--", lw=1, label="paper, Fig. 3 (read off)")
        ax.set_title(task, fontsize=10)
    axes.flat[-1].axis("off")
    axes.flat[0].legend(frameon=False, fontsize=8)
    save(fig, out)


def figure_peers(rows: list[dict], out: Path, runs_root=RUNS / "peers", minippo_root=RUNS / "seven_tasks") -> None:
    """SB3's curves from the side-by-side runs, minippo's from the seven-task runs its side reads."""
    tasks = list(dict.fromkeys(row["task"] for row in rows))
    fig = Figure(figsize=(4.2 * len(tasks), 3.4), dpi=100)
    axes = fig.subplots(1, len(tasks), squeeze=False)
    for ax, task in zip(axes[0], tasks):
        for library, colour, prefix in (("minippo", ORANGE, f"{minippo_root}/"), ("sb3", SAGE, f"{runs_root}/sb3-")):
            seeds = [r["seed"] for r in rows if r["task"] == task and r["library"] == library]
            band(ax, [Path(f"{prefix}{task}-seed{seed}") for seed in seeds], colour, library)
        ax.set_title(task, fontsize=10)
        ax.legend(frameon=False, fontsize=8, loc="upper left")
    save(fig, out)


def figure_table1(table: list[dict], out: Path) -> None:
    y = np.arange(len(table))
    fig = Figure(figsize=(7.5, 4.5), dpi=100)
    ax = fig.subplots()
    ax.barh(y - 0.2, [float(row["score"]) for row in table], 0.4, color=ORANGE, label="minippo")
    ax.barh(y + 0.2, [float(row["paper_score"]) for row in table], 0.4, color=INK, alpha=0.6, label="paper, Table 1")
    ax.set_yticks(y, [row["setting"] for row in table], fontsize=8)
    ax.invert_yaxis()
    ax.axvline(0, color=INK, lw=0.8)
    ax.set_xlabel("normalised score (random = 0, best run = 1)")
    ax.legend(frameon=False, fontsize=8)
    save(fig, out)


def save(fig, out: Path) -> None:
    for ax in fig.axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out)


def summary_text(tables: dict[str, list[dict]]) -> str:
    def table(match):
        name = match.group(1)
        return scoring.markdown(tables[name], COLUMNS[name]) if tables.get(name) else "No complete record yet."

    return re.sub(r"<!-- table:(\w+) -->", table, TEMPLATE.read_text())


def readme_blocks(tables: dict[str, list[dict]], speed: list[dict]) -> dict[str, str]:
    seven = [row for row in tables["seven_tasks"] if row["record"] == "seven_tasks_runs.csv"]
    columns = {k: SEVEN[k] for k in ("Task", "minippo, mean ± sd", "paper (Fig. 3, ≈)", "CleanRL (v4)")}
    return {"mujoco": scoring.markdown(seven, columns), "speed": scoring.markdown(speed, dict(list(SPEED.items())[:4]))}


def fill_readme(text: str, blocks: dict[str, str]) -> str:
    for name, block in blocks.items():
        pattern = re.compile(rf"(<!-- summary:{name} -->\n).*?(\n<!-- /summary:{name} -->)", re.S)
        if not pattern.search(text):
            raise BenchmarkError(f"the README has no <!-- summary:{name} --> block")
        text = pattern.sub(lambda match, block=block: match.group(1) + block + match.group(2), text)
    return text


@one_line_errors
def main(argv=None) -> int:
    tables = scoring.score_all()
    (RESULTS / "summary.md").write_text(summary_text(tables))
    figure_seven_tasks(read_rows(RESULTS / "seven_tasks_runs.csv"), RESULTS / "mujoco_curves.png")
    peer_rows = [row for row in read_rows(RESULTS / "peers.csv") if row["library"] == "sb3"]
    figure_peers(peer_rows + read_rows(RESULTS / "peers_minippo.csv"), RESULTS / "peers_curves.png")
    figure_table1(tables["table1_1m"], RESULTS / "table1_1m.png")
    readme = ROOT / "README.md"
    readme.write_text(fill_readme(readme.read_text(), readme_blocks(tables, read_rows(RESULTS / "speed.csv"))))
    print("wrote benchmarks/results/summary.md, its figures and the README's result tables", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
