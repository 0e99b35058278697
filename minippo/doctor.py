"""``minippo doctor RUN``: read a run's progress.csv and name the failure signatures its debug variables show.

Reads minippo's progress.csv or Stable-Baselines3's (its CSV logger, ``configure(folder, ["csv"])``). CleanRL logs
to TensorBoard, not to a CSV file: export its scalars to a progress.csv with minippo's column names first.

Stable-Baselines3's columns, mapped to minippo's names (an SB3 row of iteration i carries the train/ values of update
i − 1, logged before update i trains; the doctor pairs them with that update's rollout, so update i − 1 reads the
rollout/ columns of row i − 1 and the train/ columns of row i):

=============================  ===================  =====================================================
Stable-Baselines3               minippo              what differs
=============================  ===================  =====================================================
time/iterations − 1             update
time/total_timesteps            step                 (of row i − 1: the steps of update i − 1's rollout)
rollout/ep_rew_mean             return_mean          the same: the mean of the last 100 episodes
rollout/ep_len_mean             length_mean          the same
train/approx_kl                 approx_kl            both Ê[(r − 1) − log r]; SB3's is the mean over the minibatches of
                                                     the last epoch, each before its step; minippo's is over the whole
                                                     batch after the update (so minippo's is usually larger)
train/clip_fraction             clip_fraction        SB3's: the mean over the minibatches of every epoch, during
                                                     training; minippo's: over the whole batch after the update
−train/entropy_loss             entropy              SB3 logs −entropy, averaged over the minibatches during training;
                                                     minippo's is over the whole batch after the update
−train/policy_gradient_loss     policy_objective     the same: L^CLIP averaged over the minibatches
train/value_loss / 2            value_loss           SB3's is the mean squared error; minippo's is ½(V − V^targ)²
train/explained_variance        explained_variance   the same: the rollout's values against its returns
train/learning_rate             lr                   the same
=============================  ===================  =====================================================
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from minippo.errors import MinippoError
from minippo.run_folder import PROGRESS_FIELDS

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
SB3 = {  # minippo's name: (SB3's column, the factor that turns SB3's value into minippo's)
    "return_mean": ("rollout/ep_rew_mean", 1.0),
    "length_mean": ("rollout/ep_len_mean", 1.0),
    "approx_kl": ("train/approx_kl", 1.0),
    "clip_fraction": ("train/clip_fraction", 1.0),
    "entropy": ("train/entropy_loss", -1.0),
    "policy_objective": ("train/policy_gradient_loss", -1.0),
    "value_loss": ("train/value_loss", 0.5),
    "explained_variance": ("train/explained_variance", 1.0),
    "lr": ("train/learning_rate", 1.0),
}
ROLLOUT_COLUMNS = ("return_mean", "length_mean")  # of an SB3 row's own rollout, not of the update before
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

    def measure(self, rows: list[dict]) -> tuple[float, int, int]:
        """The statistic over the window's finite values, and the window's first and last update."""
        start, stop = WINDOWS[self.window](len(rows))
        window = rows[start:stop]
        values = np.array([row[self.variable] for row in window], dtype=float)
        values = values[np.isfinite(values)]
        value = _statistic(self.statistic, values, self.level) if len(values) else math.nan
        return value, int(window[0]["update"]), int(window[-1]["update"])

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


def _number(text: str | None, where: str) -> float:
    if text is None or text.strip() == "":
        return math.nan
    try:
        return float(text)
    except ValueError:
        raise MinippoError(f"{where}: {text!r} is not a number") from None


def read_run(folder) -> tuple[str, list[dict]]:
    """("minippo" or "sb3", the rows of updates) from ``folder``'s progress.csv, in minippo's names and units."""
    folder = Path(folder)
    if not folder.is_dir():
        raise MinippoError(f"no run folder {folder}")
    path = folder / "progress.csv"
    if not path.is_file():
        raise MinippoError(
            f"{folder} has no progress.csv (minippo train and Stable-Baselines3's CSV logger write one; "
            "CleanRL logs to TensorBoard)"
        )
    try:
        with open(path, newline="", encoding="utf-8") as handle:
            reader = csv.DictReader(handle)
            table, header = list(reader), set(reader.fieldnames or ())
    except (csv.Error, UnicodeDecodeError) as error:
        raise MinippoError(f"cannot read {path} as CSV ({error})") from None
    if not header:
        raise MinippoError(f"{path} is empty")
    if set(PROGRESS_FIELDS) <= header:
        rows = [{key: _number(row[key], f"{path}, line {i + 2}, {key}") for key in PROGRESS_FIELDS}
                for i, row in enumerate(table)]  # fmt: skip
        return "minippo", rows
    if "time/iterations" in header and any(column.startswith("train/") for column in header):
        rows = []
        for i in range(1, len(table)):  # row i holds the train/ columns of update (its iteration − 1)
            iteration, before = (_number(table[j]["time/iterations"], f"{path}, line {j + 2}") for j in (i, i - 1))
            if math.isnan(iteration):
                raise MinippoError(f"{path}, line {i + 2}: no time/iterations")
            update = iteration - 1
            rollout = table[i - 1] if before == update else {}  # its rollout's row, when every iteration is logged
            row = {"update": update, "step": _number(rollout.get("time/total_timesteps"), f"{path}, line {i + 1}")}
            for name, (column, factor) in SB3.items():
                source = rollout if name in ROLLOUT_COLUMNS else table[i]
                row[name] = factor * _number(source.get(column), f"{path}, line {i + 2}, {column}")
            rows.append(row)
        return "sb3", rows
    raise MinippoError(
        f"{path} has none of the columns of minippo's progress.csv ({', '.join(PROGRESS_FIELDS[:4])}, ...) or of "
        "Stable-Baselines3's (time/iterations, train/approx_kl, ...)"
    )


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


def report(folder, as_json: bool = False) -> tuple[str, int]:
    """The doctor's report of the run in ``folder`` and its exit status: 0 when no signature is found, 1 when one is."""
    kind, rows = read_run(folder)
    findings = diagnose(rows)
    measured = [(rule, *rule.measure(rows)) for rule in RULES]
    if as_json:

        def described(rule, value, first, last):
            return {**asdict(rule), "value": value, "updates": [first, last], "found": rule.holds(value),
                    "read": f"{CHAPTER}#{rule.anchor}"}  # fmt: skip

        text = json.dumps({"run": str(folder), "format": kind, "updates": len(rows),
                           "findings": [described(f.rule, f.value, f.first_update, f.last_update) for f in findings],
                           "checked": [described(*m) for m in measured]}, indent=1)  # fmt: skip
        return text, int(bool(findings))
    head = f"{folder}: {'minippo' if kind == 'minippo' else 'Stable-Baselines3'} progress.csv, {len(rows)} updates"
    if kind == "sb3":
        head += " (SB3's approx_kl and clip_fraction are measured during training: usually smaller)"
    lines = [head]
    if findings:
        lines += [f"{len(findings)} failure signature{'s' * (len(findings) > 1)} found:"]
        for number, finding in enumerate(findings, 1):
            first, *rest = finding.lines()
            lines += [f"{number}. {first}", *rest]
    else:
        lines += [f"no failure signature found in {len(rows)} updates; what was checked, against the healthy ranges "
                  f"({CHAPTER}#atlas-healthy):"]  # fmt: skip
        for rule, value, first, last in measured:
            low, high = rule.healthy
            lines += [f"  {rule.variable}: {rule.statistic} over updates {first}-{last} = {value:.4g} (flagged "
                      f"{rule.comparison} {rule.threshold:g}; healthy runs: {low:.4g}–{high:.4g})"]  # fmt: skip
    return "\n".join(lines), int(bool(findings))
