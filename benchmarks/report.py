"""benchmarks/results/summary.md, its figures, and the README's result tables, from the scored tables.

    python -m benchmarks.report             # score the records, then write summary.md, the figures and the README block

Each section of summary.md is a paragraph written once (below, in SECTIONS) and a table computed by
benchmarks/scoring.py: the paragraphs say what a table holds and how it was made, never what its numbers are.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

from benchmarks import scoring
from benchmarks.common import RESULTS, ROOT, RUNS, fail
from minippo.plotting import INK, ORANGE, SAGE, draw_seed_band, read_progress, seed_curves
from minippo.records import read_rows

SEVEN = {
    "Task": "{task}",
    "record": "`{record}`",
    "minippo, mean ± sd": "{mean:,.1f} ± {sd:,.1f}",
    "seeds' returns": "{returns}",
    "paper (Fig. 3, ≈)": "{paper}",
    "CleanRL (v4)": "{cleanrl}",
    "≥ paper's low end": "{at_or_above_paper}",
    "min per run": "{minutes}",
    "commits": "{commits}",
}
PEERS = {
    "Task": "{task}",
    "score": "{score}",
    "minippo": "{minippo_mean:,.0f} ± {minippo_se:,.0f}",
    "SB3": "{sb3_mean:,.0f} ± {sb3_se:,.0f}",
    "seeds": "{seeds}",
    "minippo − SB3 [95%]": "{diff:+,.0f} [{low:+,.0f}, {high:+,.0f}]",
    "standing": "{standing}",
    "min per run (minippo / SB3)": "{minippo_minutes} / {sb3_minutes}",
}
TABLE1 = {"Setting": "{setting}", "score ± se": "{score:.2f} ± {score_se}", "paper": "{paper_score:.2f}"}
TABLE1 |= {"runs": "{runs}", "tasks": "{tasks}"}
SCALE = {"Setting": "{setting}", "record": "{record}", "score ± se": "{score:.2f} ± {score_se:.2f}"}
SCALE |= {"runs": "{runs}", "paper": "{paper_score:.2f}"}
SPEED = {"Contender": "{contender}", "steps/s (median)": "{steps_per_s}", "× raw stepping": "{vs_raw}"}
SPEED |= {"× SB3": "{vs_sb3}", "version": "{version}", "machine": "{machine}", "commit": "{commit}"}
SAME = {"Task": "{env}", "seed": "{seed}", "dtype": "{dtype}", "commits": "{earlier_commit} → {commit}"}
SAME |= {"rel. difference, update 1": "{difference_at_update_1}", "parted (> 1%) at update": "{parted_at_update}"}

SECTIONS = [
    (
        "Seven MuJoCo tasks, 1M steps, the paper's settings",
        "Each row is one task of one record: `mujoco.csv` (the seven-task campaign) and the ε = 0.2 runs of "
        "`table1_1m_runs.csv`, which are `minippo train ENV --steps 1000000 --seed S` with the default objective "
        "spelt out, made at later code. A run's return is the mean of its last 100 training episodes; the sd is over "
        "seeds. The paper's column is its Figure 3 at 1M steps as read off the plots (approximate, v1 tasks of "
        "2017); CleanRL's is its published `ppo_continuous_action.py` benchmark on the v4 tasks (mean ± sd of 3 "
        "seeds). The minutes are each run's own clock with a second training sharing the two cores.",
        "seven_tasks",
        SEVEN,
        "mujoco_curves.png",
    ),
    (
        "minippo beside Stable-Baselines3",
        "`python -m benchmarks.peers`: both libraries with the paper's settings on the same machine, 5 seeds, 1M "
        "steps. train is the mean of the last 100 training episodes, eval 10 deterministic episodes of the final "
        "policy; each cell is the mean ± standard error over seeds, and the interval is Welch's 95% interval for the "
        "difference (a standing other than level needs an interval that excludes zero).",
        "peers",
        PEERS,
        "peers_curves.png",
    ),
    (
        "Table 1 at 1M steps",
        "The paper's eleven surrogate settings on its seven tasks, 3 seeds each, scored as in the paper: per task the "
        "random policy is 0 and the best run of any setting is 1 (`table1_1m_runs.csv`, `random.csv`).",
        "table1_1m",
        TABLE1,
        "table1_1m.png",
    ),
    (
        "Table 1 with and without the three details",
        "The same settings run again with `--config grad_norm_clipping=false clip_value_loss=false "
        "scale_rewards=false` (`table1_1m_paperimpl_runs.csv`: the implementation as the paper describes it), scored "
        "with the defaults' runs on one scale (the best run of either record is 1).",
        "table1_1m_two_implementations",
        SCALE,
        None,
    ),
    (
        "Table 1 with three more seeds",
        "Settings of the 1M-step table run again with seeds 4–6 (`table1_1m_more_seeds_runs.csv`), on one scale with "
        "the table's seeds 1–3.",
        "table1_1m_more_seeds",
        SCALE,
        None,
    ),
    (
        "Same training, other code",
        "`python -m benchmarks.same_math EARLIER` trains a few updates at an earlier commit and at the current one, in "
        "one process each, and compares them update by update (`same_math.csv`). Agreement to rounding at update 1 "
        "means the same algorithm; afterwards rounding differences grow until the runs are two samples of it.",
        "same_math",
        SAME,
        None,
    ),
]


def figure_seven_tasks(rows: list[dict], out: Path, runs_root=RUNS / "mujoco") -> None:
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 4, figsize=(13, 5.6), dpi=100)
    for ax, task in zip(axes.flat, scoring.SEVEN_TASKS):
        runs = [read_progress(Path(runs_root) / f"{task}-seed{r['seed']}") for r in rows if r["env"] == task]
        curves = seed_curves(runs)
        if curves is not None:
            draw_seed_band(ax, *curves, ORANGE, f"minippo, {len(runs)} seeds", alpha=0.25)
        ax.axhline(scoring.PAPER_FIGURE3[task][0], color=INK, ls="--", lw=1, label="paper, Fig. 3 (read off)")
        ax.set_title(task, fontsize=10)
    axes.flat[-1].axis("off")
    axes.flat[0].legend(frameon=False, fontsize=8)
    save(fig, out)


def figure_peers(rows: list[dict], out: Path, runs_root=RUNS / "peers") -> None:
    import matplotlib.pyplot as plt

    tasks = list(dict.fromkeys(row["task"] for row in rows))
    fig, axes = plt.subplots(1, len(tasks), figsize=(4.2 * len(tasks), 3.4), dpi=100, squeeze=False)
    for ax, task in zip(axes[0], tasks):
        for library, colour in (("minippo", ORANGE), ("sb3", SAGE)):
            seeds = [r["seed"] for r in rows if r["task"] == task and r["library"] == library]
            runs = [read_progress(Path(runs_root) / f"{library}-{task}-seed{seed}") for seed in seeds]
            curves = seed_curves(runs)
            if curves is not None:
                draw_seed_band(ax, *curves, colour, f"{library}, {len(runs)} seeds")
        ax.set_title(task, fontsize=10)
        ax.legend(frameon=False, fontsize=8, loc="upper left")
    save(fig, out)


def figure_table1(table: list[dict], out: Path) -> None:
    import matplotlib.pyplot as plt
    import numpy as np

    y = np.arange(len(table))
    fig, ax = plt.subplots(figsize=(7.5, 4.5), dpi=100)
    ax.barh(y - 0.2, [float(row["score"]) for row in table], 0.4, color=ORANGE, label="minippo")
    ax.barh(y + 0.2, [float(row["paper_score"]) for row in table], 0.4, color=INK, alpha=0.6, label="paper, Table 1")
    ax.set_yticks(y, [row["setting"] for row in table], fontsize=8)
    ax.invert_yaxis()
    ax.axvline(0, color=INK, lw=0.8)
    ax.set_xlabel("normalised score (random = 0, best run = 1)")
    ax.legend(frameon=False, fontsize=8)
    save(fig, out)


def save(fig, out: Path) -> None:
    import matplotlib.pyplot as plt

    for ax in fig.axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)


def summary_text(tables: dict[str, list[dict]]) -> str:
    parts = ["# Benchmark summary", "", "Written by `python -m benchmarks.report` from the records in this folder."]
    for title, paragraph, name, columns, figure in SECTIONS:
        parts += ["", f"## {title}", "", paragraph, ""]
        parts.append(scoring.markdown(tables[name], columns) if tables.get(name) else "No complete record yet.")
        if figure:
            parts += ["", f"![{title}]({figure})"]
    return "\n".join(parts) + "\n"


def readme_blocks(tables: dict[str, list[dict]], speed: list[dict]) -> dict[str, str]:
    seven = [row for row in tables["seven_tasks"] if row["record"] == "mujoco.csv"]
    columns = {k: SEVEN[k] for k in ("Task", "minippo, mean ± sd", "paper (Fig. 3, ≈)", "CleanRL (v4)")}
    return {
        "mujoco": scoring.markdown(seven, columns),
        "speed": scoring.markdown(speed, {k: SPEED[k] for k in list(SPEED)[:4]}),
        "table1": scoring.markdown(tables["table1_1m"], {k: TABLE1[k] for k in ("Setting", "score ± se", "paper")}),
    }


def fill_readme(text: str, blocks: dict[str, str]) -> str:
    for name, block in blocks.items():
        pattern = re.compile(rf"(<!-- summary:{name} -->\n).*?(\n<!-- /summary:{name} -->)", re.S)
        if not pattern.search(text):
            raise ValueError(f"the README has no <!-- summary:{name} --> block")
        text = pattern.sub(lambda match, block=block: match.group(1) + block + match.group(2), text)
    return text


def main(argv=None) -> int:
    import matplotlib

    matplotlib.use("Agg")
    tables = scoring.score_all()
    (RESULTS / "summary.md").write_text(summary_text(tables))
    figure_seven_tasks(read_rows(RESULTS / "mujoco.csv"), RESULTS / "mujoco_curves.png")
    figure_peers(read_rows(RESULTS / "peers.csv"), RESULTS / "peers_curves.png")
    figure_table1(tables["table1_1m"], RESULTS / "table1_1m.png")
    readme = ROOT / "README.md"
    try:
        readme.write_text(fill_readme(readme.read_text(), readme_blocks(tables, read_rows(RESULTS / "speed.csv"))))
    except ValueError as error:
        fail(str(error))
    print("wrote benchmarks/results/summary.md, its figures and the README's result tables", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
