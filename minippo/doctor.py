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

CHAPTER = "book/15-when-ppo-fails.md"
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


# The rules, the most specific first. Thresholds and healthy ranges are measured on the atlas's record
# benchmarks/results/atlas_runs.csv (python -m benchmarks.atlas run, code at commit cdc9815; read while the campaign
# ran, with 3 seeds of healthy, lr_10x, lr_100x_epochs_40, epochs_50, minibatch_whole, minibatch_4,
# no_advantage_normalization, value_loss_sign, stale_value_targets, entropy_wrong_sign, entropy_too_large on
# CartPole-v1 and Hopper-v5, and healthy MinAtar Breakout) and on 5 seeds of the book's CartPole setting for 20,480
# steps (minippo train CartPole-v1 --steps 20480 --horizon 512 --minibatch-size 128 --epochs 4 --entropy-coef 0.01
# --no-normalize-observations --no-scale-rewards --no-clip-value-loss --lr 2.5e-4, and with --lr 0.025 --epochs 40).
# A healthy range is the statistic over every healthy run, whole and cut to its first 10, 15, 20 and 40 updates; a
# threshold is the geometric mean of the healthy extreme and the nearest run of the modes it names (every seed, whole
# or cut to 40 updates) unless its comment says otherwise. No rule separates the entropy bonus's sign or size, or
# advantages left unnormalised, from healthy runs in that record; the bootstrapping, normalisation, log-density and
# γ = 1 modes were not yet recorded.
RULES = (
    # the ratio fault logs approx_kl = 0 exactly (the atlas's tests/test_atlas.py, commit aadcb29; its runs were not yet
    # recorded); α × 100, K = 40 on CartPole seed 1 collapsed to a deterministic policy: median 1.6e-13 over 40
    # updates. Healthy medians 3.9e-5 at the least (minibatch_whole on CartPole 4.8e-6): 1e-8 is far below them all
    Rule("policy-frozen", "approx_kl", "all updates", "median", "<", 1e-8,
         ("the ratio r_t computed against the current policy, not θ_old: r_t = 1 and the clip never engages",
          "a policy collapsed to a deterministic one after steps far too large (look at its entropy)"),
         "atlas-ratio", (3.85e-5, 0.0114)),
    # healthy up to 0.0114 (Hopper, its first 10 updates); epochs_50 on Hopper 0.0157, lr_10x on Hopper 0.031,
    # α × 100 with K = 40 on CartPole 0.059 (two seeds; the third collapsed), the short CartPole run 0.0245
    Rule("kl-high", "approx_kl", "all updates", "median", ">", 0.013,
         ("a step size α too large", "too many epochs K over one batch", "minibatches far too small"),
         "atlas-step-size", (3.85e-5, 0.0114)),
    # healthy up to 0.169 (Hopper, first 10 updates); epochs_50 on Hopper 0.228, the short CartPole run 0.227
    Rule("clip-high", "clip_fraction", "all updates", "median", ">", 0.2,
         ("a step size α too large", "too many epochs K over one batch", "minibatches far too small"),
         "atlas-step-size", (0.0, 0.169)),
    # the last update's value loss over the first's: healthy up to 2.23 (CartPole, 10 updates); value_loss_sign 3.23
    # on CartPole at 40 updates (6.1 at 150), 280 on Hopper
    Rule("value-loss-grows", "value_loss", "all updates", "last over first", ">", 2.7,
         ("the value loss added with the wrong sign: the critic ascends its squared error",
          "returns growing faster than the critic follows (rewards not scaled, γ = 1)"),
         "atlas-value-loss", (0.0031, 2.23)),
    # healthy at least 0.0027 (CartPole: its critic learns slowly in the book's setting); value_loss_sign on Hopper
    # -4.8 or below, stale_value_targets on Hopper -0.87 and -1.1 (2 seeds of 3). Not the geometric mean: the
    # threshold is set at -1, below every healthy run by a whole unit. A run that solves CartPole (every return 500)
    # has returns of no variance, where explained variance means nothing
    Rule("critic-worse-than-constant", "explained_variance", "all updates", "median", "<", -1.0,
         ("the value loss added with the wrong sign", "value targets computed once and never refreshed (stale)"),
         "atlas-value-loss", (0.0027, 0.99)),
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
