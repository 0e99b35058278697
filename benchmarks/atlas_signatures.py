"""The atlas's analysis: what each recorded run's debug variables show, the healthy ranges, and a signature rule per
(mode, task), read from ``results/atlas_runs.csv`` (``python -m benchmarks.atlas summarize`` writes them as CSV tables).
"""

from __future__ import annotations

import numpy as np

from benchmarks import common
from benchmarks.atlas_faults import FAULTS, RUNS_CSV, TASKS, task_config
from minippo.records import read_rows

RANGES_CSV = common.RESULTS / "atlas_healthy_ranges.csv"
SIGNATURES_CSV = common.RESULTS / "atlas_signatures.csv"

VARIABLES = ["return_mean", "length_mean", "approx_kl", "clip_fraction", "entropy", "policy_objective", "value_loss",
             "explained_variance", "lr"]  # fmt: skip
SETTLED = 5  # the healthy ranges leave out the first updates, while the critic and the statistics settle


FEATURE_LEGEND = {
    "completed": "updates made / updates planned (below 1: the run stopped on a non-finite loss)",
    "kl_first5": "mean approx_kl over updates 1-5",
    "kl_median": "median approx_kl over all updates",
    "kl_max": "largest approx_kl of any update",
    "clip_first5": "mean clip_fraction over updates 1-5",
    "clip_median": "median clip_fraction over all updates",
    "clip_max_first_half": "largest clip_fraction in the first half of the run (annealed ε sends it to 1 late)",
    "entropy_change_first10": "entropy at update 10 minus entropy at update 1 (nats)",
    "entropy_change": "entropy at the last update minus entropy at update 1 (nats)",
    "ev_last_quarter": "mean explained_variance over the last quarter of the updates",
    "ev_median": "median explained_variance over all updates",
    "ev_max": "largest explained_variance of any update",
    "value_loss_growth": "log10(mean value_loss over the last quarter / mean value_loss over updates 1-5)",
    "return_gain": "mean return_mean over the last quarter / mean of the first 5 finite return_mean",
    "lr_start": "lr at update 1 (what config.json says; not a behaviour)",
    "return_vs_healthy": "mean return_mean over the last quarter / the same for the median healthy seed of the task",
}


def runs_of(rows) -> dict:
    """{(mode, task, seed): {variable: array over the updates}} from the rows of atlas_runs.csv."""
    grouped = {}
    for row in rows:
        grouped.setdefault((row["mode"], row["task"], int(row["seed"])), []).append(row)
    return {key: {k: np.array([float(r[k]) for r in group]) for k in VARIABLES} for key, group in grouped.items()}


def _mean(x) -> float:
    x = x[np.isfinite(x)]
    return float(np.mean(x)) if len(x) else float("nan")


def features(run: dict, planned: int) -> dict:
    """One run's numbers that a rule may read; each says its window of updates."""
    kl, clip, entropy, ev, vl, ret = (run[k] for k in ("approx_kl", "clip_fraction", "entropy", "explained_variance",
                                                        "value_loss", "return_mean"))  # fmt: skip
    n = len(kl)
    last = slice(n - max(1, n // 4), n)  # the last quarter of the run
    start = ret[np.isfinite(ret)][:5]
    return {
        "completed": n / planned,  # the fraction of the planned updates made before it stopped (non-finite)
        "kl_first5": _mean(kl[:5]),
        "kl_median": float(np.nanmedian(kl)),
        "kl_max": float(np.nanmax(kl)),
        "clip_first5": _mean(clip[:5]),
        "clip_median": float(np.nanmedian(clip)),
        "clip_max_first_half": float(np.nanmax(clip[: max(1, n // 2)])),
        "entropy_change_first10": float(entropy[min(9, n - 1)] - entropy[0]),
        "entropy_change": float(entropy[-1] - entropy[0]),
        "ev_last_quarter": _mean(ev[last]),
        "ev_median": float(np.nanmedian(ev)) if np.isfinite(ev).any() else float("nan"),
        "ev_max": float(np.nanmax(ev)) if np.isfinite(ev).any() else float("nan"),
        "value_loss_growth": float(np.log10(_mean(vl[last]) / _mean(vl[:5]))),  # log10 of last quarter / first 5
        "return_gain": _mean(ret[last]) / np.mean(start) if len(start) else float("nan"),  # last quarter / first 5
        "lr_start": float(run["lr"][0]),  # config-visible: the step size at update 1
    }


def all_features(runs: dict) -> dict:
    """{(mode, task, seed): features}, with return_vs_healthy: the last quarter's mean return over the median of the
    healthy seeds' on the same task (the one feature that needs a task's healthy runs to read)."""
    planned = {task: updates for task, (_, updates) in TASKS.items()}
    feats = {key: features(run, planned[key[1]]) for key, run in runs.items()}
    for task in TASKS:
        finals = [_mean(run["return_mean"][-max(1, len(run["return_mean"]) // 4) :])
                  for (mode, t, _), run in runs.items() if mode == "healthy" and t == task]  # fmt: skip
        reference = float(np.median(finals)) if finals else float("nan")
        for (mode, t, seed), run in runs.items():
            if t == task:
                final = _mean(run["return_mean"][-max(1, len(run["return_mean"]) // 4) :])
                feats[mode, t, seed]["return_vs_healthy"] = final / reference
    return feats


def healthy_ranges(runs: dict) -> list[dict]:
    table = []
    for task in TASKS:
        mine = [run for (mode, t, _), run in runs.items() if mode == "healthy" and t == task]
        for name in VARIABLES:
            values = np.concatenate([run[name][SETTLED:] for run in mine]) if mine else np.array([])
            values = values[np.isfinite(values)]
            if len(values):
                low, mid, high = np.min(values), np.median(values), np.max(values)
                table.append({"task": task, "variable": name, "seeds": len(mine), "updates": f">{SETTLED}",
                              "min": f"{low:.4g}", "median": f"{mid:.4g}", "max": f"{high:.4g}"})  # fmt: skip
    return table


def _holds(value: float, direction: str, threshold: float) -> bool:
    return bool(np.isfinite(value) and (value > threshold if direction == ">" else value < threshold))


RULE_FEATURES = [name for name in FEATURE_LEGEND if name != "lr_start"]  # behaviour only: config.json shows the lr
# ratios and non-negative quantities that span decades are compared on a log10 scale (0 counts as 1e-6)
LOG_FEATURES = {"kl_first5", "kl_median", "kl_max", "clip_first5", "clip_median", "clip_max_first_half",
                "return_gain", "return_vs_healthy"}  # fmt: skip
ROBUST = 0.1  # a rule is robust when its threshold lies at least this fraction of the healthy spread from both sides


def _all_hold(conditions, values) -> bool:
    return all(all(_holds(v[name], direction, threshold) for name, direction, threshold in conditions) for v in values)


def _confusions(conditions, groups, mode) -> list[str]:
    return [f"{m} ({t})" for (m, t), vs in groups.items() if m not in (mode, "healthy") and _all_hold(conditions, vs)]


def _single_rules(values, healthy, groups, mode) -> list[tuple]:
    """Every (feature, direction) as a rule with its threshold between the mode's seeds and the healthy runs."""
    rules = []
    for name in RULE_FEATURES:
        h = np.array([v[name] for v in healthy if np.isfinite(v[name])])
        f = np.array([v[name] for v in values])
        spread = h.max() - h.min() + 1e-12
        for direction in (">", "<"):
            edge = h.max() if direction == ">" else h.min()
            held = int(np.sum(f > edge if direction == ">" else f < edge))
            if held == len(f):
                inner = f.min() if direction == ">" else f.max()
                threshold = float((inner + edge) / 2)
                margin = min(abs(inner - threshold), abs(threshold - edge)) / spread
            else:
                threshold, margin = float(edge), -1.0
            conditions = [(name, direction, threshold)]
            confused = _confusions(conditions, groups, mode)
            false_alarms = sum(_all_hold(conditions, [v]) for v in healthy)
            rules.append((held, -false_alarms, margin >= ROBUST, -len(confused), margin, conditions, confused))
    return rules


def _pair_rules(values, healthy, groups, mode) -> list[tuple]:
    """Two conditions that hold together on every seed of the mode and on no healthy run, each alone pointing away
    from the healthy runs (false on at least half of them), each threshold ROBUST of the healthy spread beyond the
    mode's least extreme seed."""
    conditions = []
    for name in RULE_FEATURES:
        h = np.array([v[name] for v in healthy if np.isfinite(v[name])])
        f = np.array([v[name] for v in values])
        if not np.isfinite(f).all():
            continue
        spread = h.max() - h.min() + 1e-12
        for condition in [(name, ">", float(f.min() - ROBUST * spread)), (name, "<", float(f.max() + ROBUST * spread))]:
            excluded = sum(not _all_hold([condition], [v]) for v in healthy) / len(healthy)
            if excluded >= 0.5:
                conditions.append((excluded, condition))
    rules = []
    for i, (first_excluded, first) in enumerate(conditions):
        for second_excluded, second in conditions[i + 1 :]:
            if first[0] == second[0] or any(_all_hold([first, second], [v]) for v in healthy):
                continue
            confused = _confusions([first, second], groups, mode)
            rules.append((len(values), 0, True, -len(confused), first_excluded + second_excluded, [first, second],
                          confused))  # fmt: skip
    return rules


def signature_rules(runs: dict) -> list[dict]:
    """Per (mode, task): a rule on the features that holds on all the mode's seeds and on no healthy run of any task.

    First one feature with one threshold, placed between the mode's seeds and the healthy runs (the geometric mean of
    the two edges; LOG_FEATURES on a log scale): robust ones first (the threshold at least ROBUST of the
    healthy spread from both), then the fewest other modes on which it also holds on every seed, then the widest
    margin. When that one is not robust or also holds on another mode, two features together are tried. A mode with
    no rule gets the feature that holds on the most seeds, with the healthy extreme as its threshold."""
    groups = {}
    for (mode, task, _), value in all_features(runs).items():
        scaled = {k: float(np.log10(max(v, 1e-6))) if k in LOG_FEATURES else v for k, v in value.items()}
        groups.setdefault((mode, task), []).append(scaled)
    healthy = [value for (mode, _), values in groups.items() if mode == "healthy" for value in values]
    table = []
    for (mode, task), values in groups.items():
        if mode == "healthy":
            continue
        best = max(_single_rules(values, healthy, groups, mode), key=lambda rule: rule[:5])
        if best[0] == len(values) and best[1] == 0 and not (best[2] and best[3] == 0):
            pairs = _pair_rules(values, healthy, groups, mode)
            if pairs and (pair := max(pairs, key=lambda rule: rule[:5]))[3] > best[3] - (not best[2]):
                best = pair
        held, minus_alarms, robust, _, margin, conditions, confused = best
        found = held == len(values) and minus_alarms == 0
        also = f"; also holds on {len(confused)} other (mode, task)" if confused else ""
        verdict = "not separated from healthy" if not found else "separated" + also
        verdict = "not robustly separated from healthy" if found and not robust else verdict
        config_fields = sorted(FAULTS[mode].changes(task_config(task, 1)))
        rule = " and ".join(f"{name} {direction} {10**threshold if name in LOG_FEATURES else threshold:.3g}"
                            for name, direction, threshold in conditions)  # fmt: skip
        table.append({"mode": mode, "task": task, "rule": rule, "seeds_holding": f"{held}/{len(values)}",
                      "healthy_false_alarms": f"{-minus_alarms}/{len(healthy)}",
                      "margin": f"{margin:.3g}" if len(conditions) == 1 else "", "verdict": verdict,
                      "also_holds_on": "; ".join(confused), "in_config_json": " ".join(config_fields)})  # fmt: skip
    return table


def summarize() -> int:
    runs = runs_of(read_rows(RUNS_CSV))
    feats = all_features(runs)
    per_run = [{"mode": m, "task": t, "seed": s, **{k: f"{v:.4g}" for k, v in feats[m, t, s].items()}}
               for (m, t, s) in sorted(runs)]  # fmt: skip
    common.write_rows(common.RESULTS / "atlas_features.csv", per_run)
    common.write_rows(RANGES_CSV, healthy_ranges(runs))
    legend = [{"feature": name, "meaning": text} for name, text in FEATURE_LEGEND.items()]
    common.write_rows(common.RESULTS / "atlas_feature_legend.csv", legend)
    rules = signature_rules(runs)
    common.write_rows(SIGNATURES_CSV, rules)
    for row in rules:
        print(
            f"{row['mode']:28} {row['task']:12} {row['rule']:44} {row['seeds_holding']} seeds, healthy "
            f"{row['healthy_false_alarms']}, margin {row['margin']:>6} {row['verdict']}; {row['also_holds_on']}"
        )
    return 0
