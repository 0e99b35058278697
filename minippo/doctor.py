"""``minippo doctor RUN``: read a run's log and name the failure signatures its debug variables show.

Reads minippo's progress.csv, Stable-Baselines3's CSV or TensorBoard log, CleanRL's TensorBoard log, or W&B's CSV
export of either; minippo/doctor_logs.py reads them, and its SOURCES table maps each one's columns to minippo's names
and units. A rule whose variable the log lacks (or has on too few updates) is reported as not checked, not as clean.

Where the log carries the run's settings (minippo's config.json, a config.yml in rl-zoo's format beside an SB3 log,
CleanRL's hyperparameters table; or a file named with --settings), the doctor first checks them (CHECKS) against bounds
that PPO's objective sets by definition: an entropy coefficient below 0, a value coefficient of 0 or below, a clip
range of 1 or more. These bounds are not calibrated on runs: beyond them a term of eq. 9 does the opposite of what it
is there for, or nothing, whether or not the run still learns.

Each rule compares a statistic of a variable over a window with a threshold; a relative signature adds a second
condition on another variable. The thresholds and the healthy ranges shown beside them are not written here: they are
in minippo/doctor_thresholds.json, which ``python -m benchmarks.doctor_calibrate calibrate`` writes from calibration
runs only (runs of minippo, Stable-Baselines3 and CleanRL, healthy and broken, and the atlas's record).

Exit status: 0 when every rule was checked and none holds, 1 when a rule or a check of the settings holds, 2 on bad
input (a log under MIN_UPDATES updates among it, whatever its settings), 3 when none holds but some rules could not be
checked. A log without settings says so in a note; it does not change the status.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from minippo.doctor_logs import NAMES, SOURCES, UNITS, Log, read_log
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
    "atlas-clip": "the clip range far too large",
    "atlas-reward": "a reward that never changes: not PPO",
    "atlas-healthy": "the healthy ranges",
}
MIN_UPDATES = 10  # the shortest window of a rule, and the span of a rolling median
WINDOWS = {  # a window's name: the (first, last + 1) indices of the rows it reads, for a run of n updates
    "all updates": lambda n: (0, n),
    "updates 1-10": lambda n: (0, MIN_UPDATES),
    "the last quarter": lambda n: (n - max(1, n // 4), n),
}
THRESHOLDS_JSON = Path(__file__).with_name("doctor_thresholds.json")  # python -m benchmarks.doctor_calibrate calibrate
PROBES = 'Andy Jones, "Debugging RL", https://andyljones.com/posts/rl-debugging.html'


def _start_and_end(values: np.ndarray) -> tuple[float, float]:
    """The first value, where the run started, and the median of the last quarter, where it ended up."""
    return float(values[0]), float(np.median(values[-max(1, len(values) // 4) :]))


def _relative(difference: float, size: float) -> float:
    return difference / size if size > 0 else 0.0  # 0/0: a variable that is 0 throughout does not change


def _statistic(name: str, values: np.ndarray, level: float | None) -> float:
    if name == "fraction above":  # the fraction of the window's updates with the variable above ``level``
        return float(np.mean(values > level))
    if name == "last minus first":
        return float(values[-1] - values[0])
    if name == "last over first":
        return float(values[-1] / values[0])
    if name == "largest rolling median":  # the highest median of MIN_UPDATES consecutive updates: a sustained level
        span = min(MIN_UPDATES, len(values))
        return float(np.median(np.lib.stride_tricks.sliding_window_view(values, span), axis=1).max())
    if name == "last quarter over first":  # the last quarter's median over the first value
        start, end = _start_and_end(values)
        return end / start
    if name == "change from first":  # (end − start) / (|end| + |start|), in [−1, 1] whatever the variable's scale
        start, end = _start_and_end(values)
        return _relative(end - start, abs(end) + abs(start))
    if name == "relative spread":  # (max − min) / (|max| + |min|), in [0, 1]: 0 for a variable that never changes
        low, high = float(np.min(values)), float(np.max(values))
        return _relative(high - low, abs(high) + abs(low))
    return float({"median": np.median, "min": np.min, "max": np.max, "mean": np.mean}[name](values))


def _enough(values: np.ndarray, window: list) -> bool:
    """Whether a rule has data enough: a number on at least half of its window's updates, and on 2."""
    return len(values) >= max(2, len(window) / 2)


@dataclass(frozen=True)
class Condition:
    """``statistic`` of ``variable`` over ``window`` compared with ``threshold``: one test of a rule."""

    variable: str
    window: str  # a key of WINDOWS
    statistic: str  # a name _statistic knows
    comparison: str  # > or <
    threshold: float = math.nan  # set from minippo/doctor_thresholds.json
    level: float | None = None  # for "fraction above"
    healthy: tuple[float, float] = (math.nan, math.nan)  # the statistic's range over healthy runs

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
        with np.errstate(divide="ignore", invalid="ignore"):
            value = _statistic(self.statistic, values, self.level) if _enough(values, window) else math.nan
        return value, int(window[0]["update"]), int(window[-1]["update"])

    def missing(self, rows: list[dict], rule_id: str, log: Log | None = None) -> str | None:
        """Why the condition cannot be measured on ``rows`` (its variable missing or too sparse), or None."""
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
        return f"not enough data for rule {rule_id}: column {column} {state}"

    def holds(self, value: float) -> bool:
        return math.isfinite(value) and (value > self.threshold if self.comparison == ">" else value < self.threshold)

    def describe(self) -> str:
        level = f" {self.level:g}" if self.level is not None else ""
        return f"{self.variable}: {self.statistic}{level}"


@dataclass(frozen=True)
class Rule:
    """One failure signature: ``statistic`` of ``variable`` over ``window`` compared with ``threshold``, and, for a
    relative signature, a second condition ``also`` that must hold with it."""

    id: str
    variable: str
    window: str  # a key of WINDOWS
    statistic: str  # median, min, max, mean, last minus first, last over first, fraction above (``level``), largest
    # rolling median, last quarter over first, change from first, relative spread (_statistic)
    comparison: str  # > or <
    threshold: float
    causes: tuple[str, ...]  # the likely causes, the likeliest first
    anchor: str  # a key of ANCHORS
    healthy: tuple[float, float]  # the statistic's range over healthy runs
    level: float | None = None  # for "fraction above"
    also: Condition | None = None  # a second condition on another variable, which must hold too

    @property
    def condition(self) -> Condition:
        return Condition(self.variable, self.window, self.statistic, self.comparison, self.threshold, self.level,
                         self.healthy)  # fmt: skip

    @property
    def conditions(self) -> tuple[Condition, ...]:
        return (self.condition,) + ((self.also,) if self.also else ())

    def values(self, rows: list[dict]) -> tuple[np.ndarray, list[dict]]:
        return self.condition.values(rows)

    def measure(self, rows: list[dict]) -> tuple[float, int, int]:
        """The first condition's statistic, and its window's first and last update (Condition.measure)."""
        return self.condition.measure(rows)

    def measure_all(self, rows: list[dict]) -> list[float]:
        """Each condition's statistic, in order."""
        return [condition.measure(rows)[0] for condition in self.conditions]

    def missing(self, rows: list[dict], log: Log | None = None) -> str | None:
        """Why the rule cannot be measured on ``rows`` (a variable missing or too sparse), or None when it can."""
        return next(filter(None, (c.missing(rows, self.id, log) for c in self.conditions)), None)

    def holds(self, value: float, also_value: float = math.nan) -> bool:
        """Whether the rule holds on its statistic ``value`` and, when it has a second condition, ``also_value``."""
        return self.condition.holds(value) and (self.also is None or self.also.holds(also_value))


# The rules, the most specific first. Their thresholds and healthy ranges are not written here: they are set from the
# calibration runs by ``python -m benchmarks.doctor_calibrate calibrate`` (the doctor's campaign, benchmarks/
# doctor_runs.py, and the atlas's record), which writes minippo/doctor_thresholds.json with how each was set: between
# the healthy runs' extreme and the nearest run of the faults the rule names. A rule the file has no threshold for is
# left out of RULES (UNCALIBRATED names it).
SIGNATURES = (
    # the return (the mean of the last episodes) the same at every update, to the log's precision: the agent is paid
    # the same (0, say) whatever it does, so there is nothing for PPO to learn from
    Rule("not-ppo-reward", "return_mean", "all updates", "relative spread", "<", math.nan,
         ("not PPO: the environment pays 0 (or the same) at every step; check the reward and the environment, on "
          f"probe environments with known answers ({PROBES})",),
         "atlas-reward", (math.nan, math.nan)),
    # the ratio fault logs approx_kl = 0 exactly at every update. A run whose policy collapsed after steps far too
    # large has a large KL first, so it is not taken for this
    Rule("policy-never-moves", "approx_kl", "all updates", "max", "<", math.nan,
         ("the ratio r_t computed against the current policy, not θ_old: r_t = 1 and the clip never engages",),
         "atlas-ratio", (math.nan, math.nan)),
    # a KL far above healthy while the clip fraction stays near 0: the ratios leave [1 − ε, 1 + ε] for no sample, so
    # ε is too wide to bind (a clip dropped from the loss by a bug would still log a high clip fraction)
    Rule("no-clip", "approx_kl", "all updates", "median", ">", math.nan,
         ("the clip range ε far too large: no ratio reaches 1 ± ε, so nothing holds the update near θ_old",),
         "atlas-clip", (math.nan, math.nan),
         also=Condition("clip_fraction", "all updates", "median", "<")),
    # the entropy's last minus its first: an entropy bonus far too large, or σ left without a gradient to shrink
    Rule("entropy-rises", "entropy", "all updates", "last minus first", ">", math.nan,
         ("an entropy bonus c2 far too large, outweighing the advantages",
          "the Gaussian log-density summed over the wrong axis (the policy's own σ gets no gradient to shrink)"),
         "atlas-entropy", (math.nan, math.nan)),
    # the highest median KL over 10 consecutive updates: a sustained burst of large steps, which a run's length does
    # not raise as it raises a single largest KL
    Rule("kl-spike", "approx_kl", "all updates", "largest rolling median", ">", math.nan,
         ("a step size α too large", "too many epochs K over one batch", "minibatches far too small"),
         "atlas-step-size", (math.nan, math.nan)),
    Rule("kl-high", "approx_kl", "all updates", "median", ">", math.nan,
         ("too many epochs K over one batch", "a step size α too large", "minibatches far too small"),
         "atlas-step-size", (math.nan, math.nan)),
    Rule("clip-high", "clip_fraction", "all updates", "median", ">", math.nan,
         ("too many epochs K over one batch", "a step size α too large", "minibatches far too small"),
         "atlas-step-size", (math.nan, math.nan)),
    # the entropy falling to a small share of its start (a Gaussian's may cross 0: a negative share) while the return
    # does not rise: the policy turned certain without learning. A bonus of the wrong sign pushes it there; so can
    # steps so large that one update makes the policy all but deterministic (the atlas's collapsed CartPole seed)
    Rule("entropy-collapse", "entropy", "all updates", "last quarter over first", "<", math.nan,
         ("an entropy coefficient with the wrong sign (c2 < 0): the bonus pushes the policy towards certainty",
          "steps far too large (α, K): an update that made the policy all but deterministic, after which it learns "
          "nothing"),
         "atlas-entropy", (math.nan, math.nan),
         also=Condition("return_mean", "all updates", "change from first", "<")),
    # the largest approx KL at the other end: the whole batch as one minibatch (one Adam step an epoch)
    Rule("policy-barely-moves", "approx_kl", "all updates", "max", "<", math.nan,
         ("minibatches far too large: a handful of Adam steps per batch", "a step size α far too small"),
         "atlas-minibatch", (math.nan, math.nan)),
    Rule("critic-worse-than-constant", "explained_variance", "all updates", "median", "<", math.nan,
         ("the value loss added with the wrong sign: the critic ascends its squared error",
          "the value loss weighted 0 (c1 = 0): the critic is never trained",
          "value targets computed once and never refreshed (stale)"),
         "atlas-value-loss", (math.nan, math.nan)),
    Rule("value-loss-grows", "value_loss", "all updates", "last over first", ">", math.nan,
         ("the value loss added with the wrong sign: the critic ascends its squared error",
          "returns growing faster than the critic follows (rewards not scaled, γ = 1)"),
         "atlas-value-loss", (math.nan, math.nan)),
)  # fmt: skip


@dataclass(frozen=True)
class Check:
    """A setting outside the range in which PPO's objective (eq. 9) does what it is for: a bound by definition, not a
    threshold calibrated on runs."""

    id: str
    setting: str  # a key of doctor_logs.SETTINGS
    comparison: str  # <, <= or >=
    bound: float
    why: str  # what goes wrong beyond the bound
    causes: tuple[str, ...]
    anchor: str  # a key of ANCHORS

    def holds(self, settings: dict) -> bool:
        value = settings.get(self.setting)
        if value is None or not math.isfinite(value):
            return False
        return {"<": value < self.bound, "<=": value <= self.bound, ">=": value >= self.bound}[self.comparison]


CHECKS = (
    Check("entropy-bonus-negative", "entropy_coef", "<", 0.0,
          "c2 < 0 makes eq. 9's entropy bonus a penalty: it pays the policy for being certain",
          ("an entropy coefficient with the wrong sign (c2 < 0): the bonus pushes the policy towards certainty",),
          "atlas-entropy"),
    Check("critic-not-trained", "value_coef", "<=", 0.0,
          "with c1 ≤ 0 the value loss of eq. 9 gives the critic no gradient (c1 = 0) or one that climbs its error",
          ("the value loss weighted 0 (c1 = 0): the value loss never trains the critic, so the advantages rest on "
           "values it never fitted",),
          "atlas-value-loss"),
    Check("clip-cannot-bind", "clip_epsilon", ">=", 1.0,
          "with ε ≥ 1 the lower clip 1 − ε ≤ 0 is never reached (a ratio is positive): nothing holds r_t down where "
          "Â_t < 0",
          ("the clip range ε far too large: the clip no longer holds the update near θ_old",),
          "atlas-clip"),
)  # fmt: skip


def load_thresholds(path=THRESHOLDS_JSON) -> dict:
    """The calibrated thresholds: {"sources": {source: {rule id: {"threshold", "healthy", "also": {...}}}}, and how
    they were set}; an empty table when the file is missing."""
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        return {"rules": {}}


def calibrated(signatures=SIGNATURES, table: dict | None = None, source: str = "minippo") -> tuple[Rule, ...]:
    """The rules of ``signatures`` that ``table`` (load_thresholds()) has thresholds for, with them: those of the
    log's ``source`` (a key of doctor_logs.SOURCES) when the table has thresholds per source."""
    table = load_thresholds() if table is None else table
    entries = table["sources"].get(source, {}) if "sources" in table else table["rules"]
    rules = []
    for rule in signatures:
        entry = entries.get(rule.id)
        if entry is None or (rule.also is None) != ("also" not in entry):
            continue
        also = rule.also and replace(rule.also, threshold=entry["also"]["threshold"],
                                     healthy=tuple(entry["also"]["healthy"]))  # fmt: skip
        rules.append(replace(rule, threshold=entry["threshold"], healthy=tuple(entry["healthy"]), also=also))
    return tuple(rules)


# A threshold is set per source: the libraries log the same names for different measurements (doctor_logs.py's
# tables: SB3's approx KL is an average over the last epoch's minibatches, CleanRL's the last minibatch's, both before
# their step; minippo's the whole batch's after the update), so each is held to the healthy runs of its own library.
THRESHOLDS = load_thresholds()
RULES_BY_SOURCE = {source: calibrated(SIGNATURES, THRESHOLDS, source) for source in SOURCES}
RULES = RULES_BY_SOURCE["minippo"]
UNCALIBRATED = {source: tuple(rule.id for rule in SIGNATURES if rule.id not in {r.id for r in rules})
                for source, rules in RULES_BY_SOURCE.items()}  # fmt: skip


def _range(low_high) -> str:
    return "–".join(f"{x:.4g}" for x in low_high)


@dataclass(frozen=True)
class Finding:
    rule: Rule
    value: float
    first_update: int
    last_update: int
    also_value: float = math.nan  # the second condition's statistic, for a rule that has one

    def lines(self) -> list[str]:
        rule = self.rule
        lines = [f"{rule.condition.describe()} over updates {self.first_update}-{self.last_update} is "
                 f"{self.value:.4g} ({rule.comparison} {rule.threshold:.4g}; healthy runs: {_range(rule.healthy)})  "
                 f"[{rule.id}]"]  # fmt: skip
        if rule.also:
            also = rule.also
            lines += [f"  and {also.describe()} over {also.window} is {self.also_value:.4g} ({also.comparison} "
                      f"{also.threshold:.4g}; healthy runs: {_range(also.healthy)})"]  # fmt: skip
        return lines + [
            "  likely causes, likeliest first: " + "; ".join(rule.causes),
            f"  read: {CHAPTER}#{rule.anchor} ({ANCHORS[rule.anchor]})",
        ]


@dataclass(frozen=True)
class SettingFinding:
    """A check of the settings that holds: ``rule`` (a Check) and the setting's value."""

    rule: Check
    value: float
    settings_file: str = ""

    def lines(self) -> list[str]:
        check = self.rule
        return [f"setting {check.setting} = {self.value:.4g} ({check.comparison} {check.bound:g} by definition; read "
                f"from {self.settings_file})  [{check.id}]", f"  {check.why}",
                "  likely causes, likeliest first: " + "; ".join(check.causes),
                f"  read: {CHAPTER}#{check.anchor} ({ANCHORS[check.anchor]})"]  # fmt: skip


def check_settings(settings: dict, checks=CHECKS, settings_file: str = "") -> list[SettingFinding]:
    """The checks that hold on ``settings`` (doctor_logs.SETTINGS names: values), in the order of ``checks``."""
    return [SettingFinding(check, settings[check.setting], settings_file) for check in checks if check.holds(settings)]


def read_run(path) -> tuple[str, list[dict]]:
    """(the source: "minippo", "sb3" or "cleanrl", the rows of updates in minippo's names and units) of the log at
    ``path`` (minippo/doctor_logs.py reads it)."""
    log = read_log(path)
    return log.source, log.rows


def diagnose(rows: list[dict], rules=RULES, settings: dict | None = None, checks=CHECKS) -> list:
    """The checks of ``settings`` that hold (SettingFinding), then the rules that hold on ``rows`` (one dict per
    update, minippo's names; Finding), each in its order."""
    if len(rows) < MIN_UPDATES:
        raise MinippoError(f"{len(rows)} updates are too few to judge: the doctor needs at least {MIN_UPDATES}")
    findings = check_settings(settings or {}, checks)
    for rule in rules:
        value, first, last = rule.measure(rows)
        also_value = rule.also.measure(rows)[0] if rule.also else math.nan
        if rule.holds(value, also_value):
            findings.append(Finding(rule, value, first, last, also_value))
    return findings


def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None  # strict JSON has no NaN


def report(path, as_json: bool = False, settings=None) -> tuple[str, int]:
    """The doctor's report of the run at ``path`` and its exit status: 0 when every rule was checked and none holds, 1
    when a rule or a check of the settings holds, 3 when none holds but some rules could not be checked (their data
    is missing). ``settings``: a file of the run's settings, when the log does not carry them."""
    log = read_log(path, settings)
    rows = log.rows
    settings_found = check_settings(log.settings, CHECKS, log.settings_file or "")
    rules = RULES_BY_SOURCE[log.source]
    findings = settings_found + diagnose(rows, rules, checks=())
    missing = {rule.id: rule.missing(rows, log) for rule in rules}
    if rules and all(missing.values()):
        reasons = dict.fromkeys(reason.split(": ", 1)[1] for reason in missing.values())
        raise MinippoError(f"{path}: not enough data for any rule: " + "; ".join(reasons))
    measured = [(rule, *rule.measure(rows), rule.also.measure(rows)[0] if rule.also else math.nan) for rule in rules]
    status = 1 if findings else 3 if any(missing.values()) or not rules else 0  # no rule for its source: unchecked
    if as_json:

        def described(rule, value, first, last, also_value):
            return {**asdict(rule), "kind": "signature", "value": _finite(value), "updates": [first, last],
                    "also_value": _finite(also_value) if rule.also else None, "found": rule.holds(value, also_value),
                    "missing": missing[rule.id], "read": f"{CHAPTER}#{rule.anchor}"}  # fmt: skip

        def setting(finding):
            return {**asdict(finding.rule), "kind": "setting", "value": finding.value, "found": True,
                    "read": f"{CHAPTER}#{finding.rule.anchor}"}  # fmt: skip

        text = json.dumps({"run": str(path), "format": log.source, "file": log.file, "updates": len(rows),
                           "notes": log.notes, "settings": log.settings, "settings_file": log.settings_file,
                           "findings": [setting(f) for f in settings_found]
                                       + [described(f.rule, f.value, f.first_update, f.last_update, f.also_value)
                                          for f in findings[len(settings_found):]],
                           "checked": [described(*m) for m in measured],
                           "settings_checked": [{"id": check.id, "setting": check.setting,
                                                 "value": log.settings.get(check.setting),
                                                 "found": check.holds(log.settings)} for check in CHECKS],
                           "not_checked": [rule.id for rule in rules if missing[rule.id]],
                           "uncalibrated": list(UNCALIBRATED[log.source])},
                          indent=1, allow_nan=False)  # fmt: skip
        return text, status
    head = f"{path}: {NAMES[log.source]} {log.file}, {len(rows)} updates"
    if log.source in UNITS:
        head += f" ({UNITS[log.source]})"
    lines = [head, *(f"  note: {note}" for note in log.notes)]
    if log.settings:
        lines += [f"  settings ({log.settings_file}): " + ", ".join(
            f"{check.setting} = {log.settings[check.setting]:.4g} (bound: {check.comparison} {check.bound:g})"
            for check in CHECKS if check.setting in log.settings)]  # fmt: skip
    checked = [m for m in measured if not missing[m[0].id]]
    if findings:
        signatures = len(findings) - len(settings_found)
        found = [f"{len(settings_found)} setting{'s' * (len(settings_found) > 1)} out of bounds"] * bool(settings_found)
        found += [f"{signatures} failure signature{'s' * (signatures > 1)}"] * bool(signatures)
        lines += [" and ".join(found) + " found:"]
        for number, finding in enumerate(findings, 1):
            first, *rest = finding.lines()
            lines += [f"{number}. {first}", *rest]
    else:
        by = f"by the {len(checked)} rules of {len(rules)} that could be checked " if len(checked) < len(rules) else ""
        lines += [f"no failure signature found {by}in {len(rows)} updates; what was checked, against the healthy "
                  f"ranges ({CHAPTER}#atlas-healthy):"]  # fmt: skip
        for rule, value, first, last, also_value in checked:
            line = (f"  {rule.condition.describe()} over updates {first}-{last} = {value:.4g} (flagged "
                    f"{rule.comparison} {rule.threshold:.4g}; healthy runs: {_range(rule.healthy)})")
            if rule.also:
                line += (f", with {rule.also.describe()} = {also_value:.4g} (flagged {rule.also.comparison} "
                         f"{rule.also.threshold:.4g}; healthy runs: {_range(rule.also.healthy)})  [{rule.id}]")
            lines += [line]
    lines += [reason for reason in missing.values() if reason]
    if UNCALIBRATED[log.source]:
        lines += [f"not applied to {NAMES[log.source]} logs (no calibration run of that library has their faults): "
                  + ", ".join(UNCALIBRATED[log.source])]  # fmt: skip
    return "\n".join(lines), status
