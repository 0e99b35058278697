"""Records in, tables out: every number that summary.md, the README and chapter 11 show, computed from the records
in benchmarks/results/ and written under benchmarks/results/tables/ (by ``python -m benchmarks.report``). No sentences.
"""

from __future__ import annotations

import math
import statistics
from collections import defaultdict
from pathlib import Path

from benchmarks.common import RESULTS, BenchmarkError, write_rows
from minippo.records import read_rows

TABLES = RESULTS / "tables"
# Numbers typed in from their sources (benchmarks/README.md): per task in the paper's order, Figure 3 of the paper at
# 1M steps as read off its plots (low, high) and CleanRL's published v4 benchmark (mean, sd); the paper's Table 1.
PUBLISHED = {row["task"]: row for row in read_rows(RESULTS / "published_tasks.csv")}
SEVEN_TASKS = list(PUBLISHED)
PAPER_FIGURE3 = {task: (int(row["paper_low"]), int(row["paper_high"])) for task, row in PUBLISHED.items()}
CLEANRL = {task: (int(r["cleanrl_mean"]), int(r["cleanrl_sd"])) for task, r in PUBLISHED.items() if r["cleanrl_mean"]}
TABLE1_PAPER = {row["setting"]: float(row["paper_score"]) for row in read_rows(RESULTS / "published_table1.csv")}
RANDOM_EPISODES, RANDOM_SEED = 100, 0
STEPS_1M = 999_424  # 488 updates of 2048 steps
DETAILS = ["grad_norm_clipping", "clip_value_loss", "scale_rewards"]  # the three the paper does not describe


def welch_interval(first: list[float], second: list[float], level: float = 0.95) -> dict:
    """Welch's t interval for mean(first) − mean(second) (SciPy's Welch test: variances not assumed equal, the
    Welch–Satterthwaite degrees of freedom); ``standing`` is ahead / behind when the interval excludes 0, else level."""
    from scipy import stats

    if len(first) < 2 or len(second) < 2:
        raise ValueError("Welch's interval needs at least two values in each sample")
    low, high = map(float, stats.ttest_ind(first, second, equal_var=False).confidence_interval(level))
    standing = "ahead" if low > 0 else "behind" if high < 0 else "level"
    return {"diff": statistics.fmean(first) - statistics.fmean(second), "low": low, "high": high, "standing": standing}


def random_returns(rows: list[dict]) -> dict[str, float]:
    """{task: the random policy's mean return} from random.csv: the 0 of Table 1's scale."""
    chosen = [row for row in rows if row["episodes"] == str(RANDOM_EPISODES) and row["seed"] == str(RANDOM_SEED)]
    return {row["env"]: float(row["return_mean"]) for row in chosen}


def normalized_scores(runs: list[dict], random_return: dict[str, float]) -> dict[str, dict]:
    """Table 1's scoring: per task the random policy's return is 0 and the best run of any setting is 1; a setting's
    score is the mean of its runs' normalised returns, ``se`` √(Σ_k s_k²/n_k) / K over its K tasks (None when a task
    has one seed). Returns {setting: {"score", "se", "runs", "tasks", "per_task"}}."""
    best = {r["env"]: max(float(o["return_mean"]) for o in runs if o["env"] == r["env"]) for r in runs}
    per_task = defaultdict(lambda: defaultdict(list))
    for run in runs:
        env_id = run["env"]
        if env_id not in random_return:
            raise BenchmarkError(f"no random-policy return recorded for {env_id}")
        span = best[env_id] - random_return[env_id]
        if span <= 0:
            raise BenchmarkError(f"on {env_id} no run beats the random policy, so the score is undefined")
        per_task[run["setting"]][env_id].append((float(run["return_mean"]) - random_return[env_id]) / span)
    scores = {}
    for setting, tasks in per_task.items():
        values = [value for task in tasks.values() for value in task]
        se = None
        if all(len(task) > 1 for task in tasks.values()):
            se = math.sqrt(sum(statistics.variance(task) / len(task) for task in tasks.values())) / len(tasks)
        scores[setting] = {"score": statistics.fmean(values), "se": se, "runs": len(values), "tasks": len(tasks)}
        scores[setting]["per_task"] = {env_id: statistics.fmean(task) for env_id, task in tasks.items()}
    return scores


def complete(runs: list[dict], tasks, seeds, by: str) -> list[str]:
    """The settings (``by="setting"``) with a run for every task and seed, or the tasks (``by="env"``) where every
    setting has one for every seed: what can be scored while a campaign runs."""
    done = {(run["setting"], run["env"], int(run["seed"])) for run in runs}
    settings = list(dict.fromkeys(run["setting"] for run in runs))
    if by == "setting":
        return [s for s in settings if all((s, env_id, seed) in done for env_id in tasks for seed in seeds)]
    return [env_id for env_id in tasks if all((s, env_id, seed) in done for s in settings for seed in seeds)]


def table1(runs: list[dict], randoms: list[dict], tasks, seeds, steps: int) -> list[dict]:
    """Table 1 from a runs record: the settings with every run of ``tasks`` × ``seeds`` at ``steps`` (while none has,
    the complete tasks), scored, in the paper's order."""
    runs = [r for r in runs if r["env"] in tasks and int(r["seed"]) in seeds and int(r["steps"]) == steps]
    if settings := complete(runs, tasks, seeds, "setting"):
        runs = [run for run in runs if run["setting"] in settings]
    else:
        tasks = complete(runs, tasks, seeds, "env")
        runs = [run for run in runs if run["env"] in tasks]
    if not runs:
        raise BenchmarkError("no setting or task has all its runs recorded yet")
    scores = normalized_scores(runs, random_returns(randoms))
    table = []
    for name, paper in TABLE1_PAPER.items():
        if name in scores:
            score, se = scores[name]["score"], scores[name]["se"]
            row = {"setting": name, "score": round(score, 2), "score_se": "" if se is None else round(se, 2)}
            row |= {"paper_score": paper, "runs": scores[name]["runs"], "tasks": scores[name]["tasks"]}
            row["task_ids"] = " ".join(env_id for env_id in tasks if env_id in scores[name]["per_task"])
            table.append(row | {"seeds": len(seeds), "steps": steps})
    return table


def on_one_scale(records: dict[str, list[dict]], randoms: list[dict]) -> list[dict]:
    """Several runs records of Table 1's settings on one scale (per task the best run of any is 1), over the tasks
    each record covers completely. One row per setting and record ([] while a record is empty)."""
    if not all(records.values()):
        return []
    tasks = set(SEVEN_TASKS)
    for runs in records.values():
        tasks &= set(complete(runs, SEVEN_TASKS, sorted({int(r["seed"]) for r in runs}), "env"))
    pool = [{**r, "setting": (r["setting"], name)} for name, runs in records.items() for r in runs if r["env"] in tasks]
    if not pool:
        return []
    scores = normalized_scores(pool, random_returns(randoms))
    table = []
    for setting, paper in TABLE1_PAPER.items():
        for name in records:
            if (setting, name) in scores:
                score = scores[(setting, name)]
                row = {"setting": setting, "record": name, "score": round(score["score"], 3)}
                row |= {"score_se": round(score["se"] or 0.0, 3), "runs": score["runs"], "tasks": len(tasks)}
                table.append(row | {"paper_score": paper})
    return table


def seven_tasks(runs: list[dict], record: str) -> list[dict]:
    """Per task, in the paper's order: the seeds' final returns, their mean ± sd, the paper's Figure 3 range, CleanRL's
    mean ± sd, and a run's mean minutes."""
    table = []
    for env_id in SEVEN_TASKS:
        rows = sorted((r for r in runs if r["env"] == env_id), key=lambda r: int(r["seed"]))
        if not rows:
            continue
        returns = [float(r["return_mean"]) for r in rows]
        mean, sd = statistics.fmean(returns), statistics.stdev(returns) if len(returns) > 1 else 0.0
        low, high = PAPER_FIGURE3[env_id]
        row = {"record": record, "task": env_id, "seeds": len(rows), "returns": " ".join(f"{v:.1f}" for v in returns)}
        row |= {"mean": round(mean, 1), "sd": round(sd, 1), "paper_low": low, "paper_high": high}
        row["paper"] = f"{low}" if low == high else f"{low} to {high}"
        row["at_or_above_paper"] = "yes" if mean >= low else "no"
        row["cleanrl"] = "{} ± {}".format(*CLEANRL[env_id]) if env_id in CLEANRL else "—"
        table.append(row | {"minutes": minutes(rows), "commits": " ".join(sorted({r["commit"] for r in rows}))})
    return table


def minutes(runs: list[dict]) -> float:
    return round(statistics.fmean(float(run["wall_s"]) for run in runs) / 60, 1)


def peers(rows: list[dict]) -> list[dict]:
    """minippo against SB3 per task and score (train, eval): each library's mean ± standard error over seeds and
    Welch's 95% interval of minippo − SB3, on the tasks where both have two seeds at least."""
    table = []
    for task in dict.fromkeys(row["task"] for row in rows):
        mine = sorted((r for r in rows if r["task"] == task and r["library"] == "minippo"), key=lambda r: r["seed"])
        theirs = sorted((r for r in rows if r["task"] == task and r["library"] == "sb3"), key=lambda r: r["seed"])
        if len(mine) < 2 or len(theirs) < 2:
            continue
        for score, column in (("train", "return_mean"), ("eval", "eval_mean")):
            a, b = [float(r[column]) for r in mine], [float(r[column]) for r in theirs]
            interval = welch_interval(a, b)
            row = {"task": task, "score": score}
            for library, values in (("minippo", a), ("sb3", b)):
                row[f"{library}_mean"] = round(statistics.fmean(values), 1)
                row[f"{library}_se"] = round(statistics.stdev(values) / math.sqrt(len(values)), 1)
            row["seeds"] = f"{len(a)}/{len(b)}"
            row |= {key: round(interval[key], 1) for key in ("diff", "low", "high")}
            row["standing"] = interval["standing"]
            table.append(row | {"minippo_minutes": minutes(mine), "sb3_minutes": minutes(theirs)})
    return table


def one_detail(records: dict[str, list[dict]]) -> list[dict]:
    """No clipping (L^CPI) with the three details on, each one off, all three off, and every detail off: per task the
    mean final return of each record (``records``: {column: runs}), on the tasks the one-off records or the
    every-detail-off record ran (a column a task has no runs of is empty)."""
    none = "No clipping or penalty"
    partial = [f"{d} off" for d in DETAILS] + ["every detail off"]
    tasks = [t for t in SEVEN_TASKS if any(r["env"] == t for c in partial for r in records.get(c, []))]
    table = []
    for task in tasks:
        row = {"task": task}
        for column, runs in records.items():
            values = [float(r["return_mean"]) for r in runs if r["setting"] == none and r["env"] == task]
            row[column] = round(statistics.fmean(values), 1) if values else ""
            row[f"{column} seeds"] = len(values)
        table.append(row)
    return table


def same_math(rows: list[dict]) -> list[dict]:
    """Per comparison of two commits: the largest relative difference at update 1, and the first update where they
    part by more than 1% (empty if never)."""
    groups, names = defaultdict(list), ("env", "seed", "dtype", "earlier_commit", "commit")
    for row in rows:
        groups[tuple(row[k] for k in names)].append(row)
    table = []
    for key, runs in groups.items():
        runs.sort(key=lambda row: int(row["update"]))
        parted = [int(r["update"]) for r in runs if float(r["max_relative_difference"]) > 0.01]
        first = runs[0]["max_relative_difference"]
        row = dict(zip(names, key)) | {"updates": len(runs), "difference_at_update_1": first}
        table.append(row | {"parted_at_update": parted[0] if parted else "", "command": runs[0]["command"]})
    return table


def markdown(rows: list[dict], columns: dict[str, str]) -> str:
    """A Markdown table of ``rows`` with ``columns`` {header: format string over a row's fields}."""
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(fmt.format(**row) for fmt in columns.values()) + " |" for row in rows]
    return "\n".join(lines)


def score_all(results=RESULTS, folder=TABLES) -> dict[str, list[dict]]:
    """Every table, from the records in ``results``, written into ``folder``; returns them by name."""

    def record(name):
        return read_rows(Path(results) / name)

    randoms, default, paper = record("random.csv"), record("table1_1m_runs.csv"), record("table1_1m_paperimpl_runs.csv")
    # the book's seven tasks (5 seeds at one commit), then the older records, kept for benchmarks/README
    seven = {name: record(name) for name in ("seven_tasks_runs.csv", "mujoco.csv")}
    seven["table1_1m_runs.csv"] = [r for r in default if r["setting"] == "Clipping, ε = 0.2"]
    details = {"all on": default, **{f"{d} off": record(f"cpi_without_{d}_runs.csv") for d in DETAILS}}
    two = {"defaults": default, "without the three details": paper}
    # L^CPI with none of the details: the three above, and observation and advantage normalisation, orthogonal
    # initialisation, the step size's annealing and Adam's ε = 1e-5 (1e-8 instead)
    no_details = record("cpi_no_details_runs.csv") if (Path(results) / "cpi_no_details_runs.csv").exists() else []
    more_seeds = {"seeds 1-3": default, "seeds 4-6": record("table1_1m_more_seeds_runs.csv")}
    tables = {
        "seven_tasks": [row for name, runs in seven.items() for row in seven_tasks(runs, name)],
        # SB3's runs beside minippo's side from the same seven-task runs (peers.py --evaluate)
        "peers": peers([row for row in record("peers.csv") if row["library"] == "sb3"] + record("peers_minippo.csv")),
        "table1_1m": table1(default, randoms, SEVEN_TASKS, [1, 2, 3], STEPS_1M),
        "table1_1m_two_implementations": on_one_scale(two, randoms),
        "table1_1m_more_seeds": on_one_scale(more_seeds, randoms),
        "cpi_one_detail": one_detail(details | {"all off": paper, "every detail off": no_details}),
        "same_math": same_math(record("same_math.csv")),
    }
    for name, rows in tables.items():
        if rows:
            write_rows(Path(folder) / f"{name}.csv", rows)
    return tables
