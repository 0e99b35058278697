"""``minippo doctor RUN``: read a run's log and name the failure signatures its debug variables show.

Reads minippo's progress.csv, Stable-Baselines3's CSV or TensorBoard log, CleanRL's TensorBoard log, or W&B's CSV
export of either; minippo/doctor_logs.py reads them, and its SOURCES table maps each one's columns to minippo's names
and units. A rule whose variable the log lacks (or has on too few updates) is reported as not checked, not as clean.

Exit status: 0 when every rule was checked and none holds, 1 when one holds, 2 on bad input, 3 when none holds but some
rules could not be checked.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass

import numpy as np

from minippo.doctor_logs import NAMES, UNITS, Log, read_log
from minippo.errors import MinippoError
from minippo.run_folder import PROGRESS_FIELDS  # noqa: F401 (the book reads the atlas's columns by this name)

CHAPTER = "book/when-ppo-fails.md"  # the appendix "When PPO does not learn"
ANCHORS = {  # the sections of the atlas chapter that a finding sends the reader to
    "atlas-step-size": "a step size too large, too many epochs",
    "atlas-minibatch": "minibatches far too large or far too small",
    "atlas-advantages": "advantages not normalised",
    "atlas-value-loss": "the value loss: its sign, stale targets",
    "atlas-entropy": "the entropy bonus: its sign and its size",
    "atlas-bootstrapping": "bootstrapping at termination, none at truncation",
    "atlas-normalization": "observations not normalised, rewards not scaled",
    "atlas-ratio": "the ratio against the current policy",
    "atlas-log-prob": "the Gaussian log-density over the wrong axis",
    "atlas-discount": "no discount: γ = 1",
    "atlas-healthy": "the healthy ranges",
}
MIN_UPDATES = 10  # the shortest window of a rule
WINDOWS = {  # a window's name: the (first, last + 1) indices of the rows it reads, for a run of n updates
    "all updates": lambda n: (0, n),
    "updates 1-10": lambda n: (0, MIN_UPDATES),
    "the last quarter": lambda n: (n - max(1, n // 4), n),
}


def _statistic(name: str, values: np.ndarray, level: float | None) -> float:
    if name == "fraction above":  # the fraction of the window's updates with the variable above ``level``
        return float(np.mean(values > level))
    if name == "last minus first":
        return float(values[-1] - values[0])
    if name == "last over first":
        return float(values[-1] / values[0])
    return float({"median": np.median, "min": np.min, "max": np.max, "mean": np.mean}[name](values))


def _enough(values: np.ndarray, window: list) -> bool:
    """Whether a rule has data enough: a number on at least half of its window's updates, and on 2."""
    return len(values) >= max(2, len(window) / 2)


@dataclass(frozen=True)
class Rule:
    """One failure signature: ``statistic`` of ``variable`` over ``window`` compared with ``threshold``."""

    id: str
    variable: str
    window: str  # a key of WINDOWS
    statistic: str  # median, min, max, mean, last minus first, last over first, fraction above (``level``)
    comparison: str  # > or <
    threshold: float
    causes: tuple[str, ...]  # the likely causes, the likeliest first
    anchor: str  # a key of ANCHORS
    healthy: tuple[float, float]  # the statistic's range over healthy runs
    level: float | None = None  # for "fraction above"

    def values(self, rows: list[dict]) -> tuple[np.ndarray, list[dict]]:
        """The finite values of the variable over the window, and the window's rows."""
        start, stop = WINDOWS[self.window](len(rows))
        window = rows[start:stop]
        values = np.array([row.get(self.variable, math.nan) for row in window], dtype=float)
        return values[np.isfinite(values)], window

    def measure(self, rows: list[dict]) -> tuple[float, int, int]:
        """The statistic over the window's finite values (NaN when fewer than half of its updates, or than 2, have
        one: not enough data), and the window's first and last update."""
        values, window = self.values(rows)
        value = _statistic(self.statistic, values, self.level) if _enough(values, window) else math.nan
        return value, int(window[0]["update"]), int(window[-1]["update"])

    def missing(self, rows: list[dict], log: Log | None = None) -> str | None:
        """Why the rule cannot be measured on ``rows`` (its variable missing or too sparse), or None when it can."""
        values, window = self.values(rows)
        if _enough(values, window):
            return None
        column = log.column(self.variable) if log else self.variable
        if log and self.variable in log.absent:
            state = "is not in the log"
        elif len(values) == 0:
            state = "is empty"
        else:
            state = f"has a number on {len(values)} of the {len(window)} updates of {self.window}"
        return f"not enough data for rule {self.id}: column {column} {state}"

    def holds(self, value: float) -> bool:
        return math.isfinite(value) and (value > self.threshold if self.comparison == ">" else value < self.threshold)


# The rules, the most specific first. Thresholds and healthy ranges are measured on the atlas's record,
# benchmarks/results/atlas_runs.csv (python -m benchmarks.atlas run, code at commit cdc9815: 17 modes, CartPole-v1 for
# 150 updates and Hopper-v5 for 60, seeds 1-3, and healthy MinAtar Breakout for 200). "Healthy" below is the range of
# the statistic over the 9 healthy runs, whole and cut to their first 10, 15 and 40 updates; a threshold sits between
# the healthy extreme and the nearest run of the modes it names, and its comment gives both. No rule separates the
# entropy bonus's sign, advantages left unnormalised, bootstrapping at a termination, none at a truncation, raw
# observations or γ = 1 on Hopper from healthy runs in that record (the atlas chapter shows why).
RULES = (
    # the ratio fault logs approx_kl = 0 exactly at every update (CartPole and Hopper, 3 seeds each); the smallest
    # healthy largest-KL is 1.1e-3 (CartPole, 10 updates). A run whose policy collapsed after steps far too large has
    # a large KL first, so it is not taken for this
    Rule("policy-never-moves", "approx_kl", "all updates", "max", "<", 1e-10,
         ("the ratio r_t computed against the current policy, not θ_old: r_t = 1 and the clip never engages",),
         "atlas-ratio", (1.09e-3, 0.0203)),
    # the entropy's last minus its first: every healthy run loses entropy (at most -0.015 nats); an entropy bonus of
    # c2 = 0.5 on Hopper gains 2.3 nats in 10 updates, 8.2 in 60; the log-density over the wrong axis 0.73 and 2.7
    Rule("entropy-rises", "entropy", "all updates", "last minus first", ">", 0.5,
         ("an entropy bonus c2 far too large, outweighing the advantages",
          "the Gaussian log-density summed over the wrong axis (the policy's own σ gets no gradient to shrink)"),
         "atlas-entropy", (-0.961, -0.0148)),
    # the largest approx KL: healthy at most 0.0203 (Hopper); α × 10 on Hopper 0.038 in 10 updates, α × 100 with K = 40
    # on CartPole 0.078 in 10 (0.94 to 6.5 over 150), α × 10 on CartPole 0.033 to 0.070 over 150
    Rule("kl-spike", "approx_kl", "all updates", "max", ">", 0.03,
         ("a step size α too large", "too many epochs K over one batch", "minibatches far too small"),
         "atlas-step-size", (1.09e-3, 0.0203)),
    # the median approx KL: healthy at most 0.0114 (Hopper); K = 50 on Hopper 0.0155 in 10 updates, 0.0157 over 60;
    # α × 10 on Hopper 0.030, M = 4 on Hopper 0.0143 in 10 updates (0.0119 over 60: missed)
    Rule("kl-high", "approx_kl", "all updates", "median", ">", 0.013,
         ("too many epochs K over one batch", "a step size α too large", "minibatches far too small"),
         "atlas-step-size", (1.48e-4, 0.0114)),
    # the median clip fraction: healthy at most 0.169 (Hopper, 10 updates); K = 50 on Hopper 0.228
    Rule("clip-high", "clip_fraction", "all updates", "median", ">", 0.2,
         ("too many epochs K over one batch", "a step size α too large", "minibatches far too small"),
         "atlas-step-size", (0.0, 0.169)),
    # the largest approx KL again, at the other end: the whole batch as one minibatch on CartPole (one Adam step an
    # epoch) moves the policy by at most 9.7e-5; the smallest healthy largest-KL is 1.09e-3
    Rule("policy-barely-moves", "approx_kl", "all updates", "max", "<", 3e-4,
         ("minibatches far too large: a handful of Adam steps per batch", "a step size α far too small"),
         "atlas-minibatch", (1.09e-3, 0.0203)),
    # the median explained variance: healthy at least -0.031 (CartPole, 10 updates: its critic learns slowly in the
    # book's setting); the value loss's sign flipped on Hopper -4.5 and below, stale value targets on Hopper -1.35 (one
    # seed of 3 over 60 updates). Set at -1, a whole unit below every healthy run
    Rule("critic-worse-than-constant", "explained_variance", "all updates", "median", "<", -1.0,
         ("the value loss added with the wrong sign: the critic ascends its squared error",
          "value targets computed once and never refreshed (stale)"),
         "atlas-value-loss", (-0.031, 0.99)),
    # the last update's value loss over the first's: healthy at most 2.23 (CartPole, 10 updates); the value loss's
    # sign flipped on CartPole 3.2 at 40 updates, Hopper without reward scaling from 10 updates on, γ = 1 on CartPole
    # (2 seeds of 3)
    Rule("value-loss-grows", "value_loss", "all updates", "last over first", ">", 2.7,
         ("the value loss added with the wrong sign: the critic ascends its squared error",
          "returns growing faster than the critic follows (rewards not scaled, γ = 1)"),
         "atlas-value-loss", (0.0031, 2.23)),
)  # fmt: skip


@dataclass(frozen=True)
class Finding:
    rule: Rule
    value: float
    first_update: int
    last_update: int

    def lines(self) -> list[str]:
        rule, low_high = self.rule, "–".join(f"{x:.4g}" for x in self.rule.healthy)
        level = f" {rule.level:g}" if rule.level is not None else ""
        return [
            f"{rule.variable}: {rule.statistic}{level} over updates {self.first_update}-{self.last_update} is "
            f"{self.value:.4g} ({rule.comparison} {rule.threshold:g}; healthy runs: {low_high})  [{rule.id}]",
            "  likely causes, likeliest first: " + "; ".join(rule.causes),
            f"  read: {CHAPTER}#{rule.anchor} ({ANCHORS[rule.anchor]})",
        ]


def read_run(path) -> tuple[str, list[dict]]:
    """(the source: "minippo", "sb3" or "cleanrl", the rows of updates in minippo's names and units) of the log at
    ``path`` (minippo/doctor_logs.py reads it)."""
    log = read_log(path)
    return log.source, log.rows


def diagnose(rows: list[dict], rules=RULES) -> list[Finding]:
    """The rules that hold on ``rows`` (one dict per update, minippo's names), in the order of ``rules``."""
    if len(rows) < MIN_UPDATES:
        raise MinippoError(f"{len(rows)} updates are too few to judge: the doctor needs at least {MIN_UPDATES}")
    findings = []
    for rule in rules:
        value, first, last = rule.measure(rows)
        if rule.holds(value):
            findings.append(Finding(rule, value, first, last))
    return findings


def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None  # strict JSON has no NaN


def report(path, as_json: bool = False) -> tuple[str, int]:
    """The doctor's report of the run at ``path`` and its exit status: 0 when every rule was checked and none holds, 1
    when one holds, 3 when none holds but some rules could not be checked (their data is missing)."""
    log = read_log(path)
    rows = log.rows
    findings = diagnose(rows)
    missing = {rule.id: rule.missing(rows, log) for rule in RULES}
    if all(missing.values()):
        reasons = dict.fromkeys(reason.split(": ", 1)[1] for reason in missing.values())
        raise MinippoError(f"{path}: not enough data for any rule: " + "; ".join(reasons))
    measured = [(rule, *rule.measure(rows)) for rule in RULES]
    status = 1 if findings else 3 if any(missing.values()) else 0
    if as_json:

        def described(rule, value, first, last):
            return {**asdict(rule), "value": _finite(value), "updates": [first, last], "found": rule.holds(value),
                    "missing": missing[rule.id], "read": f"{CHAPTER}#{rule.anchor}"}  # fmt: skip

        text = json.dumps({"run": str(path), "format": log.source, "file": log.file, "updates": len(rows),
                           "notes": log.notes,
                           "findings": [described(f.rule, f.value, f.first_update, f.last_update) for f in findings],
                           "checked": [described(*m) for m in measured],
                           "not_checked": [rule.id for rule in RULES if missing[rule.id]]},
                          indent=1, allow_nan=False)  # fmt: skip
        return text, status
    head = f"{path}: {NAMES[log.source]} {log.file}, {len(rows)} updates"
    if log.source in UNITS:
        head += f" ({UNITS[log.source]})"
    lines = [head, *(f"  note: {note}" for note in log.notes)]
    checked = [m for m in measured if not missing[m[0].id]]
    if findings:
        lines += [f"{len(findings)} failure signature{'s' * (len(findings) > 1)} found:"]
        for number, finding in enumerate(findings, 1):
            first, *rest = finding.lines()
            lines += [f"{number}. {first}", *rest]
    else:
        by = f"by the {len(checked)} rules of {len(RULES)} that could be checked " if len(checked) < len(RULES) else ""
        lines += [f"no failure signature found {by}in {len(rows)} updates; what was checked, against the healthy "
                  f"ranges ({CHAPTER}#atlas-healthy):"]  # fmt: skip
        for rule, value, first, last in checked:
            low, high = rule.healthy
            lines += [f"  {rule.variable}: {rule.statistic} over updates {first}-{last} = {value:.4g} (flagged "
                      f"{rule.comparison} {rule.threshold:g}; healthy runs: {low:.4g}–{high:.4g})"]  # fmt: skip
    lines += [reason for reason in missing.values() if reason]
    return "\n".join(lines), status
