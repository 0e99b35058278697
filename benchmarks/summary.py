"""Turn the benchmark records into benchmarks/results/summary.md and its figures.

    python benchmarks/summary.py                 # summary.md, mujoco_curves.png, table1.png, peers_curves.png
    python benchmarks/summary.py --table-only    # print only the seven-task table
    python benchmarks/summary.py --readme        # rewrite the README's generated blocks from the records

Reads only committed records: results/mujoco.csv and the run folders' progress.csv (learning curves),
results/table1.csv and results/random.csv, results/speed.csv, results/peers.csv (minippo beside Stable-Baselines3,
with Welch's interval for each difference, computed here without SciPy). Nothing in the output is typed in except the
paper's and CleanRL's reference numbers below, quoted with their sources.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import records  # noqa: E402
from seven_tasks import TASKS  # noqa: E402
from table1 import SETTINGS as TABLE1_SETTINGS  # noqa: E402
from table1 import complete_tasks, normalized_scores, random_returns  # noqa: E402

TABLE1_ROWS = len(TABLE1_SETTINGS)
TABLE1_PAPER = {name: score for name, _, score in TABLE1_SETTINGS}  # the paper's Table 1 score of each setting

# Figure 3 of Schulman et al. (2017), PPO (clip) at 1M steps, as read off the plot by third parties (approximate);
# (low, high) of the read-off range. "At or above the paper" compares a mean with the low end.
PAPER = {
    "HalfCheetah-v5": (1800, 1800),
    "Hopper-v5": (2200, 2300),
    "InvertedDoublePendulum-v5": (8000, 8000),
    "InvertedPendulum-v5": (1000, 1000),
    "Reacher-v5": (-8, -5),
    "Swimmer-v5": (110, 110),
    "Walker2d-v5": (3000, 3400),
}
# CleanRL ppo_continuous_action.py, MuJoCo v4, 1M steps, 3 seeds (mean ± std), from its published benchmark
CLEANRL = {
    "HalfCheetah-v5": "1442 ± 46",
    "Hopper-v5": "2383 ± 272",
    "Walker2d-v5": "2288 ± 572",
    "InvertedPendulum-v5": "963 ± 22",
}
SOURCES = (
    "Paper: Schulman et al. (2017), Figure 3, PPO (clip) at 1M steps on the v1 tasks of 2017, values read off the "
    "plot (approximate; a range where readings differ). CleanRL: `ppo_continuous_action.py`, MuJoCo v4, 1M steps, "
    "3 seeds, from CleanRL's published benchmark. Gymnasium's v5 tasks differ slightly from v4 (Hopper and Walker2d "
    "pay the healthy reward only while healthy); HalfCheetah and Swimmer are unchanged."
)
SPEED_NAMES = {
    "raw": "raw env stepping, random actions",
    "minippo": "minippo PPO (NumPy)",
    "sb3": "Stable-Baselines3 PPO (PyTorch)",
}


def paper_text(env_id: str) -> str:
    low, high = PAPER[env_id]
    return f"~{low}" if low == high else f"~{low} to {high}" if low >= 0 else f"~{low} ({low} to {high})"


def task_stats(rows: list[dict]) -> dict[str, dict]:
    """Per task: the seeds' final returns, their mean and sample standard deviation, mean steps/s and wall time."""
    grouped: dict[str, list[dict]] = {}
    for row in rows:
        grouped.setdefault(row["env"], []).append(row)
    stats = {}
    for env_id, runs in grouped.items():
        runs = sorted(runs, key=lambda row: int(row["seed"]))
        returns = [float(row["return_mean"]) for row in runs]
        stats[env_id] = {
            "seeds": [int(row["seed"]) for row in runs],
            "returns": returns,
            "mean": statistics.fmean(returns),
            "std": statistics.stdev(returns) if len(returns) > 1 else 0.0,
            "steps": sorted({int(row["steps"]) for row in runs}),
            "steps_per_s": statistics.fmean(float(row["steps_per_s"]) for row in runs),
            "wall_min": statistics.fmean(float(row["wall_s"]) for row in runs) / 60,
        }
    return stats


def at_or_above(env_id: str, mean: float) -> bool:
    return mean >= PAPER[env_id][0]


def mujoco_table(stats: dict[str, dict]) -> list[str]:
    lines = [
        "| Task (Gymnasium v5) | minippo, mean ± std over seeds | seeds | paper (Fig. 3) | CleanRL (v4) "
        "| at or above paper | steps/s | minutes per run |",
        "|---|---:|---|---:|---:|:---:|---:|---:|",
    ]
    for env_id in TASKS:
        if env_id not in stats:
            lines.append(f"| {env_id} | not run yet | | {paper_text(env_id)} | {CLEANRL.get(env_id, '—')} | | | |")
            continue
        s = stats[env_id]
        seeds = ", ".join(f"{value:.0f}" for value in s["returns"])
        mark = "yes" if at_or_above(env_id, s["mean"]) else "no"
        lines.append(
            f"| {env_id} | {s['mean']:.1f} ± {s['std']:.1f} (n = {len(s['returns'])}) | {seeds} | {paper_text(env_id)} "
            f"| {CLEANRL.get(env_id, '—')} | {mark} | {s['steps_per_s']:.0f} | {s['wall_min']:.1f} |"
        )
    return lines


def complete_and_above(stats: dict[str, dict]) -> tuple[list[str], list[str]]:
    """The tasks with 3 seeds recorded, and those of them whose mean is at or above the paper's value."""
    complete = [env_id for env_id in TASKS if env_id in stats and len(stats[env_id]["returns"]) >= 3]
    return complete, [env_id for env_id in complete if at_or_above(env_id, stats[env_id]["mean"])]


def mujoco_verdict(stats: dict[str, dict]) -> str:
    complete, above = complete_and_above(stats)
    steps = sorted({step for env_id in stats for step in stats[env_id]["steps"]})
    return (
        f"{len(complete)} of 7 tasks have 3 seeds recorded; minippo's mean is at or above the paper's value (the low "
        f"end of the read-off range) on {len(above)} of them"
        + (f" ({', '.join(above)})" if above else "")
        + f". Each run is {', '.join(f'{s:,} steps ({s // 2048} updates of 2048)' for s in steps)}; its return is "
        "the mean of its last 100 training episodes. The steps/s and minutes are the trainer's own clock while two "
        "trainings (and other people's jobs) shared the two cores, so they understate minippo's speed on a quiet "
        "machine; the speed race below measures that."
    )


def score_text(row: dict) -> str:
    """A Table 1 score with its seed-to-seed standard error when the record has one: '0.62 ± 0.11'. Takes a row of a
    table CSV (strings, "" for no error) or scores as ``normalized_scores`` gives them (floats, None for no error)."""
    se = row.get("score_se")
    return f"{float(row['score']):.2f}" + (f" ± {float(se):.2f}" if se not in (None, "") else "")


def scored_text(score: dict) -> str:
    """``score_text`` for a setting's scores as ``normalized_scores`` gives them."""
    return score_text({"score": score["score"], "score_se": score["se"]})


def stale_settings(runs_csv: str, table: list[dict], results=records.RESULTS) -> list[str]:
    """Settings whose runs in ``runs_csv`` were made by code later found wrong (kept under results/stale/) and that the
    table does not score yet: they are being rerun."""
    scored = {row["setting"] for row in table}
    stale = {row["setting"] for row in records.read_rows(Path(results) / "stale" / runs_csv)}
    return [name for name, _, _ in TABLE1_SETTINGS if name in stale and name not in scored]


def noise_text(row: dict, best: dict) -> str:
    """How a setting's gap to the best compares with the seeds' noise: twice the standard error of the difference of
    the two scores (the scores' errors combined as independent), or nothing when a score has no error."""
    if not row.get("score_se") or not best.get("score_se"):
        return ""
    gap = float(best["score"]) - float(row["score"])
    error = math.hypot(float(row["score_se"]), float(best["score_se"]))
    if gap <= 2 * error:
        return f", a gap of {gap:.2f}, within twice its standard error ({error:.2f}): level within the seeds' noise"
    return f", a gap of {gap:.2f}, more than twice its standard error ({error:.2f})"


def table1_verdict(table: list[dict], pending: list[str] = ()) -> str:
    """Where the paper's two landmarks rank here: clipping at ε = 0.2 (the paper's best) and no clipping (its worst).
    ``pending``: settings being rerun, named so that nobody reads the table as complete."""
    ranked = sorted(table, key=lambda row: -float(row["score"]))
    names = [row["setting"] for row in ranked]
    best, worst = ranked[0], ranked[-1]
    text = (
        f"Best here: {best['setting']} ({score_text(best)}); worst: {worst['setting']} ({score_text(worst)}). "
        "In the paper: Clipping, ε = 0.2 best (0.82), no clipping worst (−0.39)."
    )
    clip, none = "Clipping, ε = 0.2", "No clipping or penalty"
    if clip in names and none in names:
        clip_rank, none_rank = names.index(clip) + 1, names.index(none) + 1
        if len(names) < TABLE1_ROWS:
            verdict = f"is not settled: only {len(names)} of the {TABLE1_ROWS} settings are recorded."
        elif clip_rank == 1 and none_rank == len(names):
            verdict = "is reproduced."
        elif none_rank == len(names):
            verdict = (
                f"is half reproduced: no clipping is last, as in the paper, but ε = 0.2 is not first "
                f"({score_text(ranked[clip_rank - 1])} against {score_text(best)})"
                f"{noise_text(ranked[clip_rank - 1], best)}."
            )
        else:
            verdict = "is not reproduced at this scale."
        text += (
            f" Here Clipping, ε = 0.2 ranks {clip_rank} of {len(names)} and no clipping {none_rank} of {len(names)}: "
            f"the paper's ordering {verdict}"
        )
    if pending:
        text += " " + pending_text(pending)
    return text


def pending_text(pending: list[str]) -> str:
    """The sentence that names the settings being rerun (``stale_settings``), so that nobody reads a table as
    complete."""
    return (
        f"Not shown: {len(pending)} KL-penalty setting{'' if len(pending) == 1 else 's'} ({', '.join(pending)}), "
        "being rerun after a fix to the penalty, which had compared the new policy with the old policy's means but "
        "the current σ; the earlier runs are kept in `benchmarks/results/stale/` and not scored."
    )


def table1_lines(table: list[dict], randoms: list[dict], pending: list[str] = ()) -> list[str]:
    if not table:
        return ["No Table 1 runs are recorded yet."]
    lines = [
        f"Scale: {table[0]['scale']}. Score: per task the random policy's mean return is 0 and the best final "
        "return of any setting is 1; a setting's score is the mean over its runs, ± its standard error from seed to "
        "seed (the seeds' variance within each task, pooled over the tasks).",
        "",
        "| Setting | minippo score | runs | paper (Table 1) |",
        "|---|---:|---:|---:|",
    ]
    for row in table:
        lines.append(f"| {row['setting']} | {score_text(row)} | {row['runs']} | {float(row['paper_score']):.2f} |")
    lines += ["", table1_verdict(table, pending)]
    if randoms:
        lines += [
            "",
            "Random policy (the zero of the score):",
            "",
            "| Task | episodes | mean return | std |",
            "|---|---:|---:|---:|",
        ]
        for row in randoms:
            lines.append(
                f"| {row['env']} | {row['episodes']} | {float(row['return_mean']):.2f} | "
                f"{float(row['return_std']):.2f} |"
            )
    return lines


def speed_lines(rows: list[dict]) -> list[str]:
    if not rows:
        return ["The speed race has not been run yet."]
    first = rows[0]
    lines = [
        f"{first['env']}, one process, {first['date']}, commit {first['commit']}, {first['machine']}; 1-minute load "
        f"average {first['load_before']} before and {first['load_after']} after. Median over interleaved rounds.",
        "",
        "| Contender | steps/s (median) | rounds | × raw stepping | × SB3 | version |",
        "|---|---:|---|---:|---:|---|",
    ]
    for row in rows:
        speed = f"{float(row['steps_per_s']):,.0f}" if row["steps_per_s"] else "—"
        lines.append(
            f"| {SPEED_NAMES.get(row['contender'], row['contender'])} | {speed} | {row['rounds'].replace(';', ', ')} "
            f"| {row['vs_raw'] or '—'} | {row['vs_sb3'] or '—'} | {row['version']} |"
        )
    lines += ["", f"Command: `{first['command']}`"]
    return lines


def speed_sentence(rows: list[dict]) -> str:
    """The README's paragraph on the speed race, from speed.csv."""
    by_name = {row["contender"]: row for row in rows}
    if "minippo" not in by_name or not by_name["minippo"]["steps_per_s"]:
        return "The speed race has not been run yet (`python benchmarks/speed.py`)."
    mine, raw, sb3 = by_name["minippo"], by_name.get("raw"), by_name.get("sb3")
    rounds = len(mine["rounds"].split(";"))
    text = (
        f"Speed on {mine['env']} with the paper's settings, measured in one process by `{mine['command']}` "
        f"(`benchmarks/results/speed.csv`, median of {rounds} interleaved rounds, {mine['machine']}, {mine['date']}, "
        f"commit {mine['commit']}): minippo trains at {float(mine['steps_per_s']):.0f} steps/s"
    )
    if sb3 and sb3["steps_per_s"]:
        text += (
            f", {float(mine['vs_sb3']):.2f}× Stable-Baselines3 PPO with the same settings and one torch thread "
            f"({float(sb3['steps_per_s']):.0f} steps/s)"
        )
    else:
        text += " (Stable-Baselines3 was not measured: " + (sb3["version"] if sb3 else "no row") + ")"
    if raw and raw["steps_per_s"]:
        text += (
            f", and {float(mine['vs_raw']):.2f}× raw environment stepping with random actions "
            f"({float(raw['steps_per_s']):.0f} steps/s)"
        )
    return text + "."


# minippo beside Stable-Baselines3 (peers.csv): Welch's interval for the difference of two means


def regularized_beta(x: float, a: float, b: float) -> float:
    """I_x(a, b), the regularised incomplete beta function, by its continued fraction (modified Lentz), on the side
    of x where the fraction converges fast."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    if x > (a + 1.0) / (a + b + 2.0):
        return 1.0 - regularized_beta(1.0 - x, b, a)
    log_front = math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x)
    tiny = 1e-300

    def guarded(value: float) -> float:
        return value if abs(value) > tiny else tiny

    c, d = 1.0, 1.0 / guarded(1.0 - (a + b) * x / (a + 1.0))
    fraction = d
    for m in range(1, 500):
        for term in (
            m * (b - m) * x / ((a + 2 * m - 1) * (a + 2 * m)),  # the even step of the fraction
            -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 2 * m + 1)),  # the odd step
        ):
            d = 1.0 / guarded(1.0 + term * d)
            c = guarded(1.0 + term / c)
            fraction *= c * d
        if abs(c * d - 1.0) < 1e-15:
            break
    return math.exp(log_front) * fraction / a


def t_cdf(t: float, df: float) -> float:
    """P(T ≤ t) for Student's t with ``df`` degrees of freedom (any df > 0, not only whole numbers):
    P(|T| > |t|) = I_{df/(df + t²)}(df/2, 1/2)."""
    tail = 0.5 * regularized_beta(df / (df + t * t), df / 2.0, 0.5)
    return 1.0 - tail if t >= 0 else tail


def t_quantile(p: float, df: float) -> float:
    """The t with P(T ≤ t) = p, by bisection on ``t_cdf`` (to about 1e-12)."""
    if not 0.0 < p < 1.0:
        raise ValueError(f"p must lie in (0, 1), not {p}")
    if p < 0.5:
        return -t_quantile(1.0 - p, df)
    low, high = 0.0, 1.0
    while t_cdf(high, df) < p:
        low, high = high, 2.0 * high
    for _ in range(200):
        middle = 0.5 * (low + high)
        if t_cdf(middle, df) < p:
            low = middle
        else:
            high = middle
        if high - low < 1e-12 * max(1.0, high):
            break
    return 0.5 * (low + high)


def welch_interval(first: list[float], second: list[float], level: float = 0.95) -> dict:
    """Welch's t interval for mean(first) − mean(second), the variances not assumed equal: the difference ± t·se,
    se² = s₁²/n₁ + s₂²/n₂, t the (1 + level)/2 quantile at the Welch–Satterthwaite degrees of freedom
    df = se⁴ / ((s₁²/n₁)²/(n₁ − 1) + (s₂²/n₂)²/(n₂ − 1)). Each sample needs two values at least."""
    if len(first) < 2 or len(second) < 2:
        raise ValueError("Welch's interval needs at least two values in each sample")
    diff = statistics.fmean(first) - statistics.fmean(second)
    part1 = statistics.variance(first) / len(first)
    part2 = statistics.variance(second) / len(second)
    se = math.sqrt(part1 + part2)
    if se == 0.0:  # both samples constant: no spread to speak of
        return {"diff": diff, "low": diff, "high": diff, "se": 0.0, "df": math.inf}
    df = (part1 + part2) ** 2 / (part1**2 / (len(first) - 1) + part2**2 / (len(second) - 1))
    half = t_quantile(0.5 + level / 2.0, df) * se
    return {"diff": diff, "low": diff - half, "high": diff + half, "se": se, "df": df}


def standing(interval: dict) -> str:
    """ahead / behind when the interval excludes 0 (on its side), level when it includes 0."""
    if interval["low"] > 0:
        return "ahead"
    if interval["high"] < 0:
        return "behind"
    return "level"


PEER_LIBRARIES = {"minippo": "minippo", "sb3": "SB3"}
PEER_SCORES = {
    "return_mean": ("train", "training score (last 100 episodes)"),
    "eval_mean": ("eval", "deterministic evaluation (10 episodes)"),
}


def peers_stats(rows: list[dict]) -> dict[tuple, dict]:
    """Per (task, steps), in the runner's task order: each library's seeds, its train and eval scores (mean, standard
    error over seeds, n) and minutes per run, and for each score the Welch interval of minippo − SB3 with its
    standing (None while a library has fewer than 2 seeds: incomplete)."""
    from peers import TASKS as PEER_TASKS

    groups: dict[tuple, dict[str, list[dict]]] = {}
    for row in rows:
        groups.setdefault((row["task"], int(row["steps"])), {}).setdefault(row["library"], []).append(row)
    order = {task: i for i, task in enumerate(PEER_TASKS)}
    stats = {}
    for key in sorted(groups, key=lambda key: (order.get(key[0], len(order)), key[0], key[1])):
        entry: dict = {"libraries": {}, "compared": {}}
        for library in PEER_LIBRARIES:
            runs = sorted(groups[key].get(library, []), key=lambda row: int(row["seed"]))
            scores = {}
            for column in PEER_SCORES:
                values = [float(row[column]) for row in runs]
                se = statistics.stdev(values) / math.sqrt(len(values)) if len(values) > 1 else None
                scores[column] = {"values": values, "mean": statistics.fmean(values) if values else None, "se": se}
            entry["libraries"][library] = {
                "seeds": [int(row["seed"]) for row in runs],
                "scores": scores,
                "minutes": statistics.fmean(float(row["wall_s"]) for row in runs) / 60 if runs else None,
                "versions": sorted({row["version"] for row in runs}),
                "commits": sorted({row["commit"] for row in runs}),
            }
        complete = all(len(entry["libraries"][library]["seeds"]) >= 2 for library in PEER_LIBRARIES)
        for column in PEER_SCORES:
            if complete:
                mine, theirs = (entry["libraries"][library]["scores"][column]["values"] for library in PEER_LIBRARIES)
                interval = welch_interval(mine, theirs)
                entry["compared"][column] = {**interval, "standing": standing(interval)}
            else:
                entry["compared"][column] = None
        stats[key] = entry
    return stats


def number(value: float, digits: int, sign: bool = False) -> str:
    """A figure with thousands separators, its sign written as + or the minus sign − (U+2212) when ``sign``."""
    text = f"{value:+,.{digits}f}" if sign else f"{value:,.{digits}f}"
    return text.replace("-", "\u2212")


def peers_lines(rows: list[dict]) -> list[str]:
    """The side-by-side table (per task, each library's mean ± standard error of both scores, minippo − SB3 with
    its 95% Welch interval, minutes per run) and one sentence per task: ahead, level or behind at equal steps."""
    if not rows:
        return ["No side-by-side runs are recorded yet (`python benchmarks/peers.py`)."]
    stats = peers_stats(rows)
    lines = [
        "minippo's PPO and Stable-Baselines3's PPO with the paper's settings in both (how each setting was matched, "
        "and where the two cannot match: `benchmarks/README.md`), the same tasks and seeds, each run a Ray task of one "
        "CPU and one math thread on the same machine (`benchmarks/results/peers.csv`, made by "
        "`python benchmarks/peers.py`). Train: the mean return of the run's last 100 training episodes; eval: the "
        "final policy's mean action over 10 episodes (reset seeds 0–9). Each cell is the mean over seeds ± its "
        "standard error (n seeds); the difference minippo − SB3 has Welch's 95% t interval, and a library is ahead "
        "or behind when the interval excludes 0, level when it includes 0.",
        "",
        "| Task | steps | score | minippo | SB3 | minippo − SB3 [95% interval] | standing | minutes per run, "
        "minippo / SB3 |",
        "|---|---:|---|---:|---:|---:|:---:|---:|",
    ]
    sentences = []
    for (task, steps), entry in stats.items():
        libraries = entry["libraries"]
        means = [s["mean"] for lib in libraries.values() for s in lib["scores"].values() if s["mean"] is not None]
        digits = 0 if max(abs(value) for value in means) >= 100 else 1
        minutes = " / ".join("—" if lib["minutes"] is None else f"{lib['minutes']:.1f}" for lib in libraries.values())
        for column, (short, _) in PEER_SCORES.items():
            cells = []
            for library in PEER_LIBRARIES:
                score, n = libraries[library]["scores"][column], len(libraries[library]["seeds"])
                if score["mean"] is None:
                    cells.append("—")
                elif score["se"] is None:
                    cells.append(f"{number(score['mean'], digits)} (n = {n})")
                else:
                    cells.append(f"{number(score['mean'], digits)} ± {number(score['se'], digits)} (n = {n})")
            compared = entry["compared"][column]
            if compared is None:
                difference, verdict = "—", "incomplete"
            else:
                difference = (
                    f"{number(compared['diff'], digits, True)} [{number(compared['low'], digits, True)}, "
                    f"{number(compared['high'], digits, True)}]"
                )
                verdict = compared["standing"]
            lines.append(
                f"| {task} | {steps:,} | {short} | {cells[0]} | {cells[1]} | {difference} | {verdict} "
                f"| {minutes if column == 'return_mean' else ''} |"
            )
        sentences.append("- " + peers_sentence(task, steps, entry, digits))
    versions = sorted(
        {version for entry in stats.values() for lib in entry["libraries"].values() for version in lib["versions"]}
    )
    commits = sorted(
        {commit for entry in stats.values() for lib in entry["libraries"].values() for commit in lib["commits"]}
    )
    lines += ["", *sentences, "", f"Versions: {'; '.join(versions)}. Commit(s): {', '.join(commits)}."]
    return lines


def peers_sentence(task: str, steps: int, entry: dict, digits: int) -> str:
    """One task in a sentence: the standing on the training score, with the evaluation's beside it."""
    counts = {library: len(lib["seeds"]) for library, lib in entry["libraries"].items()}
    seeds = ", ".join(f"{PEER_LIBRARIES[library]} {n} seed{'s' if n != 1 else ''}" for library, n in counts.items())
    train, evaluation = entry["compared"]["return_mean"], entry["compared"]["eval_mean"]
    if train is None:
        return f"{task}, {steps:,} steps: incomplete ({seeds}; each library needs 2 seeds at least), no standing yet."

    def difference(compared: dict) -> str:
        return (
            f"{number(compared['diff'], digits, True)} (95% interval {number(compared['low'], digits, True)} to "
            f"{number(compared['high'], digits, True)})"
        )

    wording = {"ahead": "ahead of", "level": "level with", "behind": "behind"}
    text = (
        f"{task}, {steps:,} steps ({seeds}): minippo is {wording[train['standing']]} SB3 at equal steps; minippo − "
        f"SB3 is {difference(train)} on the training score"
    )
    there = evaluation["standing"] + (" too" if evaluation["standing"] == train["standing"] else "")
    return text + f", and {difference(evaluation)} on the deterministic evaluation, where it is {there}."


def recheck_lines(rows: list[dict], record: str = "hopper_recheck.csv", how: str = "trained again") -> list[str]:
    """One sentence per task run again (``how``: at a later commit, or with another setting), with its seeds."""
    lines = []
    for env_id, stat in task_stats(rows).items():
        commits = ", ".join(sorted({row["commit"] for row in rows if row["env"] == env_id}))
        returns = ", ".join(f"{value:.0f}" for value in stat["returns"])
        lines.append(
            f"{env_id} {how} at commit {commits} (`benchmarks/results/{record}`, seeds "
            f"{', '.join(map(str, stat['seeds']))}): {returns}, mean {stat['mean']:.1f} ± {stat['std']:.1f}."
        )
    return lines


def table1_by_task(table: list[dict], runs: list[dict], randoms: list[dict]) -> dict[str, dict[str, float]]:
    """{setting: {task: mean normalised return}} for the runs a Table 1 table scored (its tasks, seeds and steps),
    by the table's own scoring, in the table's row order."""
    if not table:
        return {}
    tasks, steps = table[0]["task_ids"].split(), table[0]["steps"]
    scored = [run for run in runs if run["env"] in tasks and run["steps"] == steps]
    scores = normalized_scores(scored, random_returns(randoms))
    return {row["setting"]: scores[row["setting"]]["per_task"] for row in table if row["setting"] in scores}


def table1_task_lines(by_task: dict[str, dict[str, float]]) -> list[str]:
    """Table 1's scores task by task (a Markdown table), and how the best setting fares against ε = 0.2 on each."""
    if not by_task:
        return []
    tasks = list(next(iter(by_task.values())))
    lines = [
        "| Setting | " + " | ".join(task.removesuffix("-v5") for task in tasks) + " |",
        "|---|" + "---:|" * len(tasks),
    ]
    for setting, per_task in by_task.items():
        lines.append(f"| {setting} | " + " | ".join(f"{per_task[task]:.2f}" for task in tasks) + " |")
    leader = leader_sentence(by_task)
    return lines + (["", leader] if leader else [])


def leader_sentence(by_task: dict[str, dict[str, float]]) -> str | None:
    """When the best setting is not the paper's ε = 0.2: how the two compare task by task (None otherwise)."""
    clip = "Clipping, ε = 0.2"
    if clip not in by_task:
        return None
    best = max(by_task, key=lambda setting: sum(by_task[setting].values()) / len(by_task[setting]))
    return None if best == clip else versus_sentence(by_task, best, clip)


def versus_sentence(by_task: dict[str, dict[str, float]], first: str, second: str) -> str:
    """Where ``first`` scores higher than ``second``, the same to two decimals, and lower, task by task."""
    groups = {"higher": [], "the same to two decimals": [], "lower": []}
    for task in by_task[first]:
        a, b = round(by_task[first][task], 2), round(by_task[second][task], 2)
        groups["higher" if a > b else "lower" if a < b else "the same to two decimals"].append(task)
    parts = [f"{how} on {len(tasks)}" + (f" ({', '.join(tasks)})" if tasks else "") for how, tasks in groups.items()]
    return f"Task by task, against {second}, {first} scores " + ", ".join(parts[:-1]) + f" and {parts[-1]}."


OTHER_TAG = " (as the paper describes it)"


def rerun_pool(default_runs: list[dict], other_runs: list[dict], seeds) -> tuple[list[str], list[dict]]:
    """The tasks on which ``other_runs`` has every one of its settings at each of ``seeds``, and the runs of
    ``default_runs`` on those tasks at the steps of ``other_runs``: what a rerun is scored with, on one scale."""
    steps = {run["steps"] for run in other_runs}
    tasks = complete_tasks(other_runs, TASKS, seeds)
    return tasks, [run for run in default_runs if run["env"] in tasks and run["steps"] in steps]


def implementation_scores(default_runs: list[dict], other_runs: list[dict], randoms: list[dict]) -> dict:
    """Table 1's settings that ran both with minippo's defaults and with other ``--config`` overrides, on one scale.

    Only the tasks on which the other record has every one of its settings at each of the defaults' seeds are
    scored. Per task the random policy is 0 and the best run of either record (all of the defaults' settings
    included) is 1, so while no run of the other record beats the defaults' best, the default column equals the full
    table's scores.
    Returns {setting: (default scores, other scores)}, each as ``normalized_scores`` gives them, in the order of
    Table 1; {} while no task is complete."""
    if not other_runs:
        return {}
    seeds = sorted({int(run["seed"]) for run in default_runs})  # a task counts once it has the defaults' seeds
    tasks, pool = rerun_pool(default_runs, other_runs, seeds)
    if not tasks:
        return {}
    pool += [{**run, "setting": run["setting"] + OTHER_TAG} for run in other_runs if run["env"] in tasks]
    scores = normalized_scores(pool, random_returns(randoms))
    return {
        setting: (scores[setting], scores[setting + OTHER_TAG])
        for setting in TABLE1_PAPER
        if setting in scores and setting + OTHER_TAG in scores
    }


def implementation_lines(compared: dict) -> list[str]:
    """The comparison as a Markdown table, and where ε = 0.2 ranks among the compared settings in each column."""
    if not compared:
        return []

    first = next(iter(compared.values()))[1]
    how_many = "All" if len(compared) == len(TABLE1_PAPER) else str(len(compared))
    lines = [
        f"{how_many} of Table 1's {len(TABLE1_PAPER)} settings, {first['tasks']} tasks, {first['runs']} runs each way. "
        "Score: per task the random policy 0 and the best run of either record 1.",
        "",
        "| Setting | minippo's defaults | as the paper describes it | paper (Table 1) |",
        "|---|---:|---:|---:|",
    ]
    for setting, (ours, other) in compared.items():
        lines.append(f"| {setting} | {scored_text(ours)} | {scored_text(other)} | {TABLE1_PAPER[setting]:.2f} |")
    clip = "Clipping, ε = 0.2"
    if clip in compared and len(compared) > 1:
        ranks = []
        for column, label in ((0, "with minippo's defaults"), (1, "as the paper describes it")):
            ranked = sorted(compared, key=lambda setting: -compared[setting][column]["score"])
            rank = ranked.index(clip)
            ahead = [f"{setting} ({compared[setting][column]['score']:.2f})" for setting in ranked[:rank]]
            if len(ahead) > 1:
                ahead = [", ".join(ahead[:-1]), ahead[-1]]
            leader = f", behind {' and '.join(ahead)}" if ahead else ""
            ranks.append(f"{rank + 1} of {len(compared)} {label}{leader}")
        lines += ["", f"Among these settings {clip} ranks " + "; ".join(ranks) + "."]
        leader = leader_sentence({setting: other["per_task"] for setting, (_, other) in compared.items()})
        lines += ["", f"As the paper describes it: {leader[0].lower()}{leader[1:]}"] if leader else []
    return lines


def common_overrides(rows: list[dict]) -> list[str]:
    """The ``--config`` KEY=VALUE pairs that every row's command carries (a setting's own pairs differ by row)."""

    def pairs(command):
        words = command.split("&&")[-1].split()
        return words[words.index("--config") + 1 :] if "--config" in words else []

    shared = [pair for pair in pairs(rows[0]["command"]) if "=" in pair] if rows else []
    return [pair for pair in shared if all(pair in pairs(row["command"]) for row in rows)]


def implementation_block(results, default_runs: list[dict], randoms: list[dict]) -> list[str]:
    """Table 1's contenders rerun as the paper describes its implementation: a heading that names the overrides, as
    read from the record's commands, and the comparison ([] while no task is complete)."""
    other = records.read_rows(results / "table1_1m_paperimpl_runs.csv")
    compared = implementation_scores(default_runs, other, randoms)
    if not compared:
        return []
    pending = stale_settings("table1_1m_paperimpl_runs.csv", [{"setting": name} for name in compared], results)
    which = "All of these settings" if len(compared) == len(TABLE1_PAPER) else "Some of these settings"
    return [
        f"{which} again, as the paper describes them: `--config "
        + " ".join(common_overrides(other))
        + "` (no gradient-norm clip, no value clip, no reward scaling: three details that minippo's defaults "
        "include and the paper does not describe), the same tasks, seeds and steps "
        "(`benchmarks/results/table1_1m_paperimpl_runs.csv`):",
        "",
        *implementation_lines(compared),
        *(["", pending_text(pending)] if pending else []),
    ]


MORE_SEEDS_CSV = "table1_1m_more_seeds_runs.csv"


def rerun_blocks(results, default_runs: list[dict], randoms: list[dict]) -> list[str]:
    """The 1M-step table's reruns, each followed by a blank line: as the paper describes its implementation, and
    with more seeds ([] while neither has a complete task)."""
    blocks = [implementation_block(results, default_runs, randoms), more_seeds_block(results, default_runs, randoms)]
    return [line for block in blocks if block for line in (*block, "")]


def more_seeds_scores(default_runs: list[dict], more_runs: list[dict], randoms: list[dict]) -> dict:
    """Settings of the 1M-step table run again with new seeds (same code, same steps), on one scale with the table.

    Only the tasks on which ``more_runs`` has every one of its settings at each of its seeds are scored. Per task the
    random policy is 0 and the best run of either record (every setting of the table included) is 1. Returns
    {setting: {"table": scores at the table's seeds, "new": at the new seeds, "all": at both}}, each as
    ``normalized_scores`` gives them, in the order of Table 1; {} while no task is complete."""
    if not more_runs:
        return {}
    settings = {run["setting"] for run in more_runs}
    tasks, table = rerun_pool(default_runs, more_runs, sorted({int(run["seed"]) for run in more_runs}))
    if not tasks:
        return {}
    new = [run for run in more_runs if run["env"] in tasks]
    randoms = random_returns(randoms)

    def tagged(runs, tag):
        return [{**run, "setting": run["setting"] + tag} if run["setting"] in settings else run for run in runs]

    apart = normalized_scores(tagged(table, " @table") + tagged(new, " @new"), randoms)
    together = normalized_scores(table + new, randoms)  # the same runs, so the same best run and scale
    return {
        setting: {"table": apart[setting + " @table"], "new": apart[setting + " @new"], "all": together[setting]}
        for setting in TABLE1_PAPER
        if setting in settings and setting + " @table" in apart
    }


def seed_range(runs: list[dict]) -> str:
    """'1–3' for seeds 1, 2, 3; '1, 5' for seeds that do not run on."""
    seeds = sorted({int(run["seed"]) for run in runs})
    if seeds == list(range(seeds[0], seeds[-1] + 1)) and len(seeds) > 2:
        return f"{seeds[0]}–{seeds[-1]}"
    return ", ".join(str(seed) for seed in seeds)


def more_seeds_block(results, default_runs: list[dict], randoms: list[dict]) -> list[str]:
    """The strongest settings of the 1M-step table with more seeds: a table of their scores at the table's seeds, at
    the new seeds and at both, and how far apart the first two settings are at both ([] while no task is complete)."""
    more = records.read_rows(Path(results) / MORE_SEEDS_CSV)
    scores = more_seeds_scores(default_runs, more, randoms)
    if not scores:
        return []
    tasks = set(next(iter(scores.values()))["all"]["per_task"])  # the tasks more_seeds_scores counted
    table_seeds = seed_range([run for run in default_runs if run["setting"] in scores and run["env"] in tasks])
    new_seeds = seed_range([run for run in more if run["env"] in tasks])
    names = " and ".join(scores)
    count = f"{len(tasks)} task" + ("" if len(tasks) == 1 else "s")
    lines = [
        f"{names} again with minippo's defaults and new seeds (`benchmarks/results/{MORE_SEEDS_CSV}`, seeds "
        f"{new_seeds}, the same code and steps), on the {count} where each has every new seed. Score: per "
        "task the random policy 0 and the best run of either record 1.",
        "",
        f"| Setting | seeds {table_seeds} | seeds {new_seeds} | all seeds | paper (Table 1) |",
        "|---|---:|---:|---:|---:|",
    ]
    for setting, score in scores.items():
        cells = " | ".join(scored_text(s) for s in score.values())
        lines.append(f"| {setting} | {cells} | {TABLE1_PAPER[setting]:.2f} |")
    if len(scores) == 2:
        (first, a), (second, b) = ((name, score["all"]) for name, score in scores.items())
        gap = a["score"] - b["score"]
        se = math.sqrt((a["se"] or 0.0) ** 2 + (b["se"] or 0.0) ** 2)
        ahead, behind = (first, second) if gap >= 0 else (second, first)
        size = f", {abs(gap) / se:.1f} standard errors of the difference" if se > 0 else ""
        lines += [
            "",
            f"Over all seeds {ahead} scores {abs(gap):.2f} above {behind} ({a['runs']} runs each{size}).",
        ]
    return lines


DETAILS = ["grad_norm_clipping", "clip_value_loss", "scale_rewards"]


def one_detail_lines(results) -> list[str]:
    """The unclipped objective with all three details on (the 1M table), with each one off alone
    (``cpi_without_<detail>_runs.csv``) and with all three off (the paper's description): mean return over seeds."""
    results = Path(results)
    none = "No clipping or penalty"
    columns = {"all on": records.read_rows(results / "table1_1m_runs.csv")}
    for detail in DETAILS:
        columns[f"{detail} off"] = records.read_rows(results / f"cpi_without_{detail}_runs.csv")
    columns["all off"] = records.read_rows(results / "table1_1m_paperimpl_runs.csv")
    tasks = sorted({row["env"] for detail in DETAILS for row in columns[f"{detail} off"]})
    if not tasks:
        return []
    lines = [
        "| Task | " + " | ".join(columns) + " |",
        "|---|" + "---:|" * len(columns),
    ]
    for task in tasks:
        cells = []
        for rows in columns.values():
            values = [float(row["return_mean"]) for row in rows if row["setting"] == none and row["env"] == task]
            cells.append(f"{statistics.mean(values):.0f} ({len(values)})" if values else "—")
        lines.append(f"| {task} | " + " | ".join(cells) + " |")
    return lines


def current_code_lines(table1_runs: list[dict]) -> list[str]:
    """The seven-task table again from Table 1's 1M-step "Clipping, ε = 0.2" runs: the paper's defaults, the same
    command as the seven-task runs, made at later commits."""
    rows = [row for row in table1_runs if row["setting"] == "Clipping, ε = 0.2"]
    if not rows:
        return []
    stats = task_stats(rows)
    complete, above = complete_and_above(stats)
    commits = ", ".join(sorted({row["commit"] for row in rows}))
    return [
        "",
        "The same defaults at later code: Table 1's 1M-step ε = 0.2 runs (`benchmarks/results/table1_1m_runs.csv`, "
        f"commits {commits}) are `minippo train ENV --steps 1000000 --seed S` with the default objective spelt out, so "
        "they measure the seven tasks again with the code as it is now:",
        "",
        *mujoco_table(stats),
        "",
        f"At the later code, {len(complete)} of 7 tasks have 3 seeds recorded; the mean is at or above the paper's "
        f"value on {len(above)} of them" + (f" ({', '.join(above)})." if above else "."),
    ]


def same_math_lines(rows: list[dict]) -> list[str]:
    """One sentence per comparison in same_math.csv: how far the current code's short run is from the earlier
    commit's at update 1, and at which update the two runs part (a difference above 1%)."""
    groups: dict[tuple, list[dict]] = {}
    for row in rows:
        groups.setdefault((row["env"], row["seed"], row["dtype"], row["earlier_commit"]), []).append(row)
    lines = []
    for (env_id, seed, dtype, earlier), group in groups.items():
        group.sort(key=lambda row: int(row["update"]))
        differences = [float(row["max_relative_difference"]) for row in group]
        parted = next((row["update"] for row, d in zip(group, differences) if d > 0.01), None)
        ending = (
            f"the runs part (above 1%) at update {parted}"
            if parted
            else f"they stay within {max(differences):.1g} for all {len(group)} updates"
        )
        lines.append(
            f"{env_id}, seed {seed}, {dtype}, commit {earlier} against {group[0]['commit']} "
            f"(`{group[0]['command']}`): largest relative difference {differences[0]:.1g} at update 1; {ending}."
        )
    return lines


def rechecks_lines(results) -> list[str]:
    """The seven tasks measured again: Hopper's recheck over more seeds, the same defaults at later code, the
    networks in float64, and the same-math comparisons of an earlier commit with a later one."""
    results = Path(results)
    recheck = recheck_lines(records.read_rows(results / "hopper_recheck.csv"))
    float64 = recheck_lines(
        records.read_rows(results / "float64_runs.csv"), "float64_runs.csv", "with the networks in float64"
    )
    same_math = same_math_lines(records.read_rows(results / "same_math.csv"))
    lines = ["## The seven tasks, measured again", ""]
    lines += [*recheck, ""] if recheck else []
    lines += [*current_code_lines(records.read_rows(results / "table1_1m_runs.csv"))[1:], ""]
    lines += [*float64, ""] if float64 else []
    if same_math:
        lines += [
            "Same training, other rounding: `benchmarks/same_math.py` trains a few updates at an earlier commit and at "
            "the current one, same task and seed, and compares them update by update "
            "(`benchmarks/results/same_math.csv`). Agreement to rounding at update 1 means the later code computes "
            "the same algorithm; after that, rounding differences grow until the two runs are different samples of it.",
            "",
            *same_math,
            "",
        ]
    return lines


def compact_mujoco_lines(stats: dict[str, dict], current: dict[str, dict]) -> list[str]:
    """The README's results table: per task, minippo's mean ± std over seeds from the seven-task record and from the
    same defaults at the current code (Table 1's ε = 0.2 runs), beside the paper and CleanRL."""
    lines = [
        "| Task (Gymnasium v5) | minippo (`mujoco.csv`) | same, current code | paper (Fig. 3) | CleanRL (v4) |",
        "|---|---:|---:|---:|---:|",
    ]

    def cell(table, env_id):
        s = table.get(env_id)
        digits = 1 if s and abs(s["mean"]) < 100 else 0
        return f"{s['mean']:.{digits}f} ± {s['std']:.{digits}f}" if s else "not run"

    for env_id in TASKS:
        lines.append(
            f"| {env_id} | {cell(stats, env_id)} | {cell(current, env_id)} | {paper_text(env_id)} "
            f"| {CLEANRL.get(env_id, '—')} |"
        )
    complete, above = complete_and_above(stats)
    now_complete, now_above = complete_and_above(current)
    lines += [
        "",
        f"Each cell: {', '.join(sorted({str(len(s['returns'])) for s in stats.values()}))} seeds, 1M steps, the mean "
        "return of the last 100 training episodes. At or above the paper's value (the low end of its read-off range) "
        f"on {len(above)} of {len(complete)} tasks in the seven-task record, {len(now_above)} of {len(now_complete)} "
        "at the current code.",
    ]
    return lines


def table1_sentence(table: list[dict], pending: list[str]) -> str:
    """Table 1 at 1M steps in one sentence: where the paper's best and worst settings stand, and what is missing."""
    if not table:
        return "Table 1 has no complete setting recorded yet."
    ranked = sorted(table, key=lambda row: -float(row["score"]))
    names = [row["setting"] for row in ranked]
    scores = {row["setting"]: score_text(row) for row in table}
    clip, none = "Clipping, ε = 0.2", "No clipping or penalty"
    text = f"Table 1 at the paper's scale (1M steps, {table[0]['tasks']} tasks, {table[0]['seeds']} seeds, scored as "
    text += f"in the paper): best here {ranked[0]['setting']} ({scores[names[0]]})"
    if clip in scores:
        text += f"; {clip} {scores[clip]}, {names.index(clip) + 1} of {len(names)} (paper: 0.82, first)"
    if none in scores:
        text += f"; no clipping {scores[none]}, {names.index(none) + 1} of {len(names)} (paper: −0.39, last)"
    text += "."
    if pending:
        text += (
            f" {len(pending)} KL-penalty setting{' is' if len(pending) == 1 else 's are'} being rerun after a fix"
            " to the penalty and not scored yet."
        )
    return text


def readme_blocks(results) -> dict[str, str]:
    """The README's generated blocks, by name: the results table, the speed sentence, Table 1 in one sentence.
    Everything else the records say is in summary.md."""
    results = Path(results)
    stats = task_stats(records.read_rows(results / "mujoco.csv"))
    full_runs = records.read_rows(results / "table1_1m_runs.csv")
    current = task_stats([row for row in full_runs if row["setting"] == "Clipping, ε = 0.2"])
    table1_1m = records.read_rows(results / "table1_1m.csv")
    return {
        "mujoco": "\n".join(compact_mujoco_lines(stats, current)),
        "speed": speed_sentence(records.read_rows(results / "speed.csv")),
        "table1": table1_sentence(table1_1m, stale_settings("table1_1m_runs.csv", table1_1m)),
    }


def fill_readme(text: str, blocks: dict[str, str]) -> str:
    """Replace what stands between ``<!-- summary:NAME -->`` and ``<!-- /summary:NAME -->`` with block NAME."""
    for name, block in blocks.items():
        start, end = f"<!-- summary:{name} -->", f"<!-- /summary:{name} -->"
        if start not in text or end not in text.split(start, 1)[1]:
            raise records.BenchmarkError(f"README.md has no generated block '{name}' ({start} … {end})")
        head, rest = text.split(start, 1)
        _, tail = rest.split(end, 1)
        text = f"{head}{start}\n{block}\n{end}{tail}"
    return text


def progress_curves(folder) -> tuple[list[float], list[float]] | None:
    rows = records.read_rows(Path(folder) / "progress.csv")
    points = [(float(r["step"]), float(r["return_mean"])) for r in rows if r["return_mean"] not in ("", "nan")]
    points = [(step, value) for step, value in points if math.isfinite(value)]
    if not points:
        return None
    return [p[0] for p in points], [p[1] for p in points]


def draw_seed_band(ax, curves, colour, label: str, alpha: float) -> None:
    """On ``ax``: the mean over seeds of (steps, returns) curves, on the steps all of them cover, and the band from the
    lowest to the highest seed."""
    import numpy as np

    grid = np.linspace(max(steps[0] for steps, _ in curves), min(steps[-1] for steps, _ in curves), 200)
    values = np.array([np.interp(grid, steps, returns) for steps, returns in curves])
    ax.fill_between(grid, values.min(axis=0), values.max(axis=0), color=colour, alpha=alpha, lw=0)
    ax.plot(grid, values.mean(axis=0), color=colour, lw=2, label=label)


def save_return_figure(fig, out) -> Path:
    """Label the shared axes of a figure of returns against steps, write it to ``out`` and close it."""
    import matplotlib.pyplot as plt

    fig.supxlabel("environment steps", fontsize=9)
    fig.supylabel("mean return, last 100 episodes", fontsize=9)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return Path(out)


def plot_mujoco(rows: list[dict], runs_root, out) -> Path | None:
    """Seven panels: the mean over seeds of the last-100-episode return, the min–max band over seeds, the paper."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from minippo.plotting import INK, ORANGE

    envs = [env_id for env_id in TASKS if any(row["env"] == env_id for row in rows)]
    if not envs:
        return None
    cols = 4
    fig, axes = plt.subplots(2, cols, figsize=(13, 5.6), dpi=100)
    axes = axes.ravel()
    for ax, env_id in zip(axes, envs):
        curves = []
        for row in rows:
            if row["env"] == env_id:
                curve = progress_curves(Path(runs_root) / f"{env_id}-seed{row['seed']}")
                if curve:
                    curves.append(curve)
        if not curves:
            continue
        draw_seed_band(ax, curves, ORANGE, f"minippo, {len(curves)} seeds", alpha=0.25)
        low, high = PAPER[env_id]
        if high > low:
            ax.axhspan(low, high, color=INK, alpha=0.15)
        ax.axhline(low, color=INK, ls="--", lw=1, label="paper, Fig. 3 (read off)")
        ax.set_title(env_id, fontsize=10)
        ax.grid(alpha=0.3)
        ax.ticklabel_format(axis="x", style="sci", scilimits=(0, 0))
    for ax in axes[len(envs) :]:
        ax.axis("off")
    axes[0].legend(frameon=False, fontsize=8)
    return save_return_figure(fig, out)


def plot_peers(rows: list[dict], runs_root, out) -> Path | None:
    """One panel per task of the side-by-side record: each library's mean over its seeds of the last-100-episode
    return against environment steps, and the band from the lowest to the highest seed (runs_root/<library>-<task>-
    seed<S>/progress.csv, which both libraries write with the same columns)."""
    from peers import TASKS as PEER_TASKS

    tasks = [task for task in PEER_TASKS if any(row["task"] == task for row in rows)]
    tasks += sorted({row["task"] for row in rows} - set(tasks))
    if not tasks:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from minippo.plotting import ORANGE, SAGE

    colours = {"minippo": ORANGE, "sb3": SAGE}
    fig, axes = plt.subplots(1, len(tasks), figsize=(4.2 * len(tasks), 3.4), dpi=100, squeeze=False)
    for ax, task in zip(axes[0], tasks):
        for library, name in PEER_LIBRARIES.items():
            seeds = sorted(int(row["seed"]) for row in rows if row["task"] == task and row["library"] == library)
            curves = [progress_curves(Path(runs_root) / f"{library}-{task}-seed{seed}") for seed in seeds]
            curves = [curve for curve in curves if curve]
            if not curves:
                continue
            label = f"{name}, {len(curves)} seed{'s' if len(curves) != 1 else ''}"
            draw_seed_band(ax, curves, colours[library], label, alpha=0.2)
        ax.set_title(task, fontsize=10)
        ax.grid(alpha=0.3)
        ax.ticklabel_format(axis="x", style="sci", scilimits=(0, 0))
        ax.legend(frameon=False, fontsize=8, loc="upper left")
    return save_return_figure(fig, out)


def plot_table1(table: list[dict], out, label: str = "minippo (reduced scale)") -> Path | None:
    if not table:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from minippo.plotting import INK, ORANGE

    names = [row["setting"] for row in table]
    y = np.arange(len(names))
    fig, ax = plt.subplots(figsize=(7.5, 4.5), dpi=100)
    ax.barh(y - 0.2, [float(row["score"]) for row in table], 0.4, color=ORANGE, label=label)
    ax.barh(y + 0.2, [float(row["paper_score"]) for row in table], 0.4, color=INK, alpha=0.6, label="paper, Table 1")
    ax.set_yticks(y, names, fontsize=8)
    ax.invert_yaxis()
    ax.axvline(0, color=INK, lw=0.8)
    ax.set_xlabel("normalised score (random = 0, best run = 1)")
    ax.legend(frameon=False, fontsize=8)
    ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return Path(out)


def build(results, runs_root) -> tuple[str, list[str]]:
    """The text of summary.md and the seven-task table's lines."""
    results = Path(results)
    mujoco_rows = records.read_rows(results / "mujoco.csv")
    stats = task_stats(mujoco_rows)
    table = mujoco_table(stats)
    table1 = records.read_rows(results / "table1.csv")
    randoms = records.read_rows(results / "random.csv")
    speed = records.read_rows(results / "speed.csv")
    commits = sorted({row["commit"] for row in mujoco_rows})
    parts = [
        "# Benchmark summary",
        "",
        "Generated by `python benchmarks/summary.py` from the records in `benchmarks/results/`; do not edit by hand.",
        "",
        "## Seven MuJoCo tasks, 1M steps, paper defaults",
        "",
        *table,
        "",
        mujoco_verdict(stats),
        "",
        SOURCES,
        "",
    ]
    if commits:
        parts += [f"Records made at commit(s) {', '.join(commits)}; each row of mujoco.csv holds its command.", ""]
    if mujoco_rows:
        parts += ["![Learning curves: mean over seeds, band from min to max](mujoco_curves.png)", ""]
    parts += rechecks_lines(results)
    table1_1m = records.read_rows(results / "table1_1m.csv")
    if table1_1m:
        parts += [
            "## Table 1: surrogate objectives, 1M steps a run",
            "",
            *table1_lines(table1_1m, randoms, stale_settings("table1_1m_runs.csv", table1_1m)),
            "",
        ]
        full_runs = records.read_rows(results / "table1_1m_runs.csv")
        by_task = table1_by_task(table1_1m, full_runs, randoms)
        parts += ["Each setting's score task by task (the mean of its seeds' normalised returns):", ""]
        parts += [*table1_task_lines(by_task), ""]
        parts += ["![Table 1 at 1M steps: minippo's scores beside the paper's](table1_1m.png)", ""]
        parts += rerun_blocks(results, full_runs, randoms)
        details = one_detail_lines(results)
        parts += (
            [
                "No clipping or penalty, 1M steps, with one of the three details off at a time "
                "(`cpi_without_<detail>_runs.csv`): mean return of the last 100 episodes over the seeds (seeds in "
                "brackets).",
                "",
                *details,
                "",
            ]
            if details
            else []
        )
    parts += [
        "## Table 1: surrogate objectives, reduced scale",
        "",
        *table1_lines(table1, randoms, stale_settings("table1_runs.csv", table1)),
        "",
    ]
    if table1:
        parts += ["![Table 1: minippo's scores beside the paper's](table1.png)", ""]
    peer_rows = records.read_rows(results / "peers.csv")
    parts += ["## Side by side with Stable-Baselines3", "", *peers_lines(peer_rows), ""]
    if peer_rows:
        parts += [
            "![minippo and SB3 learning curves: mean over seeds, band from the lowest to the highest seed]"
            "(peers_curves.png)",
            "",
        ]
    parts += ["## Speed race", "", *speed_lines(speed), ""]
    return "\n".join(parts), table


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--results", default=str(records.RESULTS), help="the folder of the CSV records")
    parser.add_argument("--runs", default=str(records.RUNS / "mujoco"), help="the seven-task run folders")
    parser.add_argument("--peer-runs", default=str(records.RUNS / "peers"), help="the side-by-side run folders")
    parser.add_argument("--table-only", action="store_true", help="print the seven-task table and stop")
    parser.add_argument("--readme", action="store_true", help="rewrite the README's generated blocks and stop")
    args = parser.parse_args(argv)
    results = Path(args.results)
    if not results.is_dir():
        records.fail(f"no results folder {args.results}")
    text, table = build(results, args.runs)
    if args.table_only:
        print("\n".join(table))
        return 0
    if args.readme:
        readme = records.ROOT / "README.md"
        try:
            readme.write_text(fill_readme(readme.read_text(), readme_blocks(results)))
        except records.BenchmarkError as error:
            records.fail(str(error))
        print(f"rewrote the generated blocks of {records.relative(readme)}")
        return 0
    (results / "summary.md").write_text(text)
    plot_mujoco(records.read_rows(results / "mujoco.csv"), args.runs, results / "mujoco_curves.png")
    plot_table1(records.read_rows(results / "table1.csv"), results / "table1.png")
    plot_table1(records.read_rows(results / "table1_1m.csv"), results / "table1_1m.png", "minippo (1M steps a run)")
    plot_peers(records.read_rows(results / "peers.csv"), args.peer_runs, results / "peers_curves.png")
    print(f"wrote {records.relative(results / 'summary.md')} and its figures")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
