"""The logs ``minippo doctor`` reads, turned into rows of updates in minippo's names and units.

A run is a CSV file, a TensorBoard events file, or a folder holding progress.csv or the event files of one run:

- minippo's progress.csv, one row an update;
- Stable-Baselines3's logger: its CSV (``configure(folder, ["csv"])``, progress.csv) or its TensorBoard events
  (``PPO(..., tensorboard_log=folder)`` writes folder/PPO_1/events.out.tfevents.*);
- CleanRL's ``ppo.py`` and ``ppo_continuous_action.py``: their TensorBoard events (runs/RUN_NAME/);
- W&B's CSV export of a run of either (its history: the tags as columns, and ``global_step`` or ``_step``).

The run's settings are read too (SETTINGS) where the log carries them: minippo's config.json beside its progress.csv,
a config.yml in rl-zoo's format (an OrderedDict dumped by PyYAML) beside an SB3 log or in a folder above it up to the
path given (SB3's PPO defaults for what it leaves out), and the hyperparameters table CleanRL writes to its events
file. rl-zoo itself saves its config.yml apart from the logs (in <algo>/<env>_<n>/<env>/), and a W&B export keeps its
run's config apart: ``minippo doctor RUN --settings FILE`` names the file.

SOURCES holds each source's columns or tags, the factor that turns a value into minippo's units, and when it is
logged. What differs beyond the factor (minippo's debug variables are over the whole batch after the update):

Stable-Baselines3 (PPO.train, OnPolicyAlgorithm.dump_logs): an SB3 row of iteration i carries the train/ values of
update i − 1, logged before update i trains; the doctor pairs them with that update's rollout, so update i − 1 reads
the rollout/ columns of row i − 1 and the train/ columns of row i. The step is time/total_timesteps in the CSV and the
event's step in TensorBoard (SB3 writes neither time/iterations nor time/total_timesteps there).

=============================  ===================  =====================================================
Stable-Baselines3               minippo              what differs
=============================  ===================  =====================================================
rollout/ep_rew_mean             return_mean          the same: the mean of the last 100 episodes
train/approx_kl                 approx_kl            both Ê[(r − 1) − log r]; SB3's is the mean over the minibatches of
                                                     the last epoch, each before its step (so usually smaller)
train/clip_fraction             clip_fraction        SB3's: the mean over the minibatches of every epoch, in training
−train/entropy_loss             entropy              SB3 logs −entropy, averaged over the minibatches in training
−train/policy_gradient_loss     policy_objective     the same: L^CLIP averaged over the minibatches
train/value_loss / 2            value_loss           SB3's is the mean squared error; minippo's is ½(V − V^targ)²
train/explained_variance        explained_variance   the same: the rollout's values against its returns
=============================  ===================  =====================================================

CleanRL (ppo.py): each update's scalars are written at the global step its rollout ended, so the n-th step with
losses/ tags is update n. Episodes are written one point each, at the global step they ended: the doctor averages
the episodes that ended in each update's rollout (minippo's return_mean is the mean of the last 100).

=============================  ===================  =====================================================
CleanRL                         minippo              what differs
=============================  ===================  =====================================================
charts/episodic_return          return_mean          one point per finished episode, averaged per update
losses/approx_kl                approx_kl            the same estimator on the last minibatch of the last epoch,
                                                     before its step (losses/old_approx_kl, Ê[−log r], is not read)
losses/clipfrac                 clip_fraction        the mean over the minibatches of every epoch, in training
losses/entropy                  entropy              the last minibatch's entropy (itself, not its negative)
−losses/policy_loss             policy_objective     −L^CLIP of the last minibatch
losses/value_loss               value_loss           ½(V − V^targ)² of the last minibatch (clipped with clip_vloss)
losses/explained_variance       explained_variance   the same (NaN when the returns have no variance)
=============================  ===================  =====================================================
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from minippo.errors import MinippoError
from minippo.run_folder import RunFolder

# what the doctor reads of an update, beside its number and its step
FIELDS = ("return_mean", "length_mean", "approx_kl", "clip_fraction", "entropy", "policy_objective", "value_loss",
          "explained_variance", "lr", "steps_per_s")  # fmt: skip
# source: {minippo's name: (the source's column or tag, the factor into minippo's units, when it is logged)}. When:
# "update", the update's own value; "rollout" (SB3), of the rollout the row was written after, one iteration later than
# its train/ values; "episode" (CleanRL), one point per finished episode, averaged over each update's rollout.
# The tags as the libraries write them: stable-baselines3 (commit e05d2db), common/on_policy_algorithm.py lines 289-298
# (dump_logs: time/iterations and time/total_timesteps excluded from TensorBoard), ppo/ppo.py lines 287-298 (train),
# common/base_class.py line 296 (train/learning_rate); cleanrl (commit fe8d8a0), cleanrl/ppo.py lines 214-215 and
# 300-309, cleanrl/ppo_continuous_action.py lines 229-230 and 315-324.
SOURCES = {
    "minippo": {name: (name, 1.0, "update") for name in FIELDS},
    "sb3": {
        "return_mean": ("rollout/ep_rew_mean", 1.0, "rollout"),
        "length_mean": ("rollout/ep_len_mean", 1.0, "rollout"),
        "approx_kl": ("train/approx_kl", 1.0, "update"),
        "clip_fraction": ("train/clip_fraction", 1.0, "update"),
        "entropy": ("train/entropy_loss", -1.0, "update"),
        "policy_objective": ("train/policy_gradient_loss", -1.0, "update"),
        "value_loss": ("train/value_loss", 0.5, "update"),
        "explained_variance": ("train/explained_variance", 1.0, "update"),
        "lr": ("train/learning_rate", 1.0, "update"),
        "steps_per_s": ("time/fps", 1.0, "rollout"),
    },
    "cleanrl": {
        "return_mean": ("charts/episodic_return", 1.0, "episode"),
        "length_mean": ("charts/episodic_length", 1.0, "episode"),
        "approx_kl": ("losses/approx_kl", 1.0, "update"),
        "clip_fraction": ("losses/clipfrac", 1.0, "update"),
        "entropy": ("losses/entropy", 1.0, "update"),
        "policy_objective": ("losses/policy_loss", -1.0, "update"),
        "value_loss": ("losses/value_loss", 1.0, "update"),
        "explained_variance": ("losses/explained_variance", 1.0, "update"),
        "lr": ("charts/learning_rate", 1.0, "update"),
        "steps_per_s": ("charts/SPS", 1.0, "update"),
    },
}  # fmt: skip
NAMES = {"minippo": "minippo", "sb3": "Stable-Baselines3", "cleanrl": "CleanRL"}
UNITS = {  # what a reader of the report should know of a source's numbers
    "sb3": "SB3's approx_kl and clip_fraction are measured during training: usually smaller",
    "cleanrl": "CleanRL's approx_kl, entropy and value_loss are the last minibatch's, before its step; return_mean is "
    "the mean of the episodes that ended in each update's rollout",
}
# the settings the doctor reads: minippo's name: {source: its name for the setting}, and SB3's PPO defaults (from
# PPO.__init__), which rl-zoo's config.yml leaves out when a task's entry does not change them
SETTINGS = {
    "clip_epsilon": {"minippo": "clip_epsilon", "sb3": "clip_range", "cleanrl": "clip_coef"},
    "value_coef": {"minippo": "value_coef", "sb3": "vf_coef", "cleanrl": "vf_coef"},
    "entropy_coef": {"minippo": "entropy_coef", "sb3": "ent_coef", "cleanrl": "ent_coef"},
    "lr": {"minippo": "lr", "sb3": "learning_rate", "cleanrl": "learning_rate"},
    "epochs": {"minippo": "epochs", "sb3": "n_epochs", "cleanrl": "update_epochs"},
}
SB3_DEFAULTS = {"clip_range": 0.2, "vf_coef": 0.5, "ent_coef": 0.0, "learning_rate": 3e-4, "n_epochs": 10}
SB3_CONFIG = "config.yml"  # the name rl-zoo's ExperimentManager saves a run's hyperparameters under
CLEANRL_HYPERPARAMETERS = "hyperparameters/text_summary"  # writer.add_text("hyperparameters", a markdown table)
SB3_ITERATIONS, SB3_STEPS = "time/iterations", "time/total_timesteps"  # in SB3's CSV only
READS = ("minippo's or Stable-Baselines3's progress.csv, a W&B CSV export of an SB3 or CleanRL run (a CSV file: give "
         "its path), or SB3's or CleanRL's TensorBoard event files (with the tensorboard package: "
         "pip install 'minippo[doctor]')")  # fmt: skip


@dataclass
class Log:
    """A run's log read into rows of updates: one dict an update with update, step and FIELDS (NaN where missing)."""

    path: Path
    source: str  # a key of SOURCES
    file: str  # what was read: progress.csv, a W&B CSV export, TensorBoard events
    rows: list[dict]
    absent: set = field(default_factory=set)  # the FIELDS whose column the log does not have
    notes: list = field(default_factory=list)  # what the reader dropped, assumed or could not find, one line each
    settings: dict = field(default_factory=dict)  # the run's SETTINGS that the log carries, in minippo's names
    settings_file: str | None = None  # where they were read, or None when the log carries none

    def column(self, name: str) -> str:
        """``name`` and, when the source names it otherwise, its column or tag: ``entropy (train/entropy_loss)``."""
        column = SOURCES[self.source][name][0]
        return name if column == name else f"{name} ({column})"


def _number(text: str | None, where: str) -> float:
    if text is None or text.strip() == "":
        return math.nan
    try:
        return float(text)
    except ValueError:
        raise MinippoError(f"{where}: {text!r} is not a number") from None


def _csv_table(path: Path, notes: list) -> tuple[list[str], list[list[str]]]:
    """The header and the rows of the CSV file ``path``. A last line with no line end was cut short by a run stopped
    mid-write (every writer ends its rows with one): it is dropped, and said in ``notes``."""
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as error:
        raise MinippoError(f"cannot read {path} as CSV ({error})") from None
    if text and not text.endswith("\n") and "\n" in text:
        text = text[: text.rindex("\n") + 1]
        notes.append(f"the last line of {path} has no line end (the run stopped mid-write): dropped, not counted")
    try:
        table = [row for row in csv.reader(io.StringIO(text, newline="")) if row]
    except csv.Error as error:
        raise MinippoError(f"cannot read {path} as CSV ({error})") from None
    if not table:
        raise MinippoError(f"{path} is empty")
    header, *rows = table
    for i, row in enumerate(rows):
        if len(row) != len(header):
            raise MinippoError(f"{path}, line {i + 2}: {len(row)} fields, the header has {len(header)}")
    return header, rows


def _source_of(names) -> str | None:
    """The source whose columns or tags ``names`` hold: minippo's update column, or a tag of SB3's or CleanRL's
    updates (train/..., losses/...)."""
    if "update" in names and any(name in names for name in FIELDS):
        return "minippo"
    for source in ("sb3", "cleanrl"):
        if any(tag in names for tag, _, when in SOURCES[source].values() if when == "update"):
            return source
    return None


def _unknown(path: Path, names) -> MinippoError:
    found = ", ".join(sorted(names)[:8]) + (", ..." if len(names) > 8 else "") or "nothing"
    return MinippoError(f"{path} has none of the columns or tags the doctor reads (found: {found}); it reads {READS}")


def _read_csv(path: Path) -> Log:
    notes = []
    header, table = _csv_table(path, notes)
    source = _source_of(header)
    if source is None:
        raise _unknown(path, header)
    index = {name: i for i, name in enumerate(header)}
    if source == "minippo":
        rows = []
        for line, cells in enumerate(table, 2):
            values = {name: _number(cells[index[name]], f"{path}, line {line}, {name}") if name in index else math.nan
                      for name in ("update", "step", *FIELDS)}  # fmt: skip
            if math.isnan(values["update"]):
                raise MinippoError(f"{path}, line {line}: no update number")
            rows.append(values)
        return _finished(Log(path, source, path.name, rows, notes=notes), header)
    if SB3_STEPS in index:  # SB3's own CSV logger
        step_column, kind = SB3_STEPS, path.name
    elif "global_step" in index or "_step" in index:
        step_column, kind = ("global_step" if "global_step" in index else "_step"), "W&B CSV export"
        if step_column == "_step":
            notes.append("no global_step column: W&B's _step (its own count of logged rows) is taken as the step")
    else:
        raise MinippoError(f"{path} has {NAMES[source]}'s columns but no step ({SB3_STEPS}, global_step or _step)")
    tags = [tag for tag, _, _ in SOURCES[source].values()] + [SB3_ITERATIONS]
    scalars = {tag: [] for tag in tags if tag in index}
    for line, cells in enumerate(table, 2):
        values = {tag: _number(cells[index[tag]], f"{path}, line {line}, {tag}") for tag in scalars}
        present = {tag: value for tag, value in values.items() if cells[index[tag]].strip()}
        if not present:
            continue
        step = _number(cells[index[step_column]], f"{path}, line {line}, {step_column}")
        if math.isnan(step):
            raise MinippoError(f"{path}, line {line}: no {step_column}")
        for tag, value in present.items():
            scalars[tag].append((step, value))
    return _from_scalars(path, source, kind, scalars, notes, header)


def _read_events(path: Path) -> Log:
    try:
        from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
    except ImportError:
        raise MinippoError(f"{path}: reading TensorBoard event files needs the tensorboard package: "
                           "pip install 'minippo[doctor]'") from None  # fmt: skip
    accumulator = EventAccumulator(str(path), size_guidance={"scalars": 0})  # 0: every point (the default samples 10k)
    accumulator.Reload()
    tags = accumulator.Tags()["scalars"]
    source = _source_of(tags)
    if source is None:
        raise _unknown(path, tags)
    scalars = {tag: [(event.step, event.value) for event in accumulator.Scalars(tag)] for tag in tags}
    log = _from_scalars(path, source, "TensorBoard events", scalars, [], tags)
    if source == "cleanrl" and (named := _cleanrl_hyperparameters(accumulator)):
        where = f"{path}: {CLEANRL_HYPERPARAMETERS}"
        log.settings, log.settings_file = _named_settings("cleanrl", named, where, log.notes), where
    return log


def _from_scalars(path: Path, source: str, kind: str, scalars: dict, notes: list, names) -> Log:
    rows = (_sb3_rows if source == "sb3" else _cleanrl_rows)(scalars, notes)
    return _finished(Log(path, source, kind, rows, notes=notes), names)


def _sb3_rows(scalars: dict, notes: list) -> list[dict]:
    """One row an SB3 update: the train/ values of the dump of iteration i are those of update i − 1 (PPO.train
    records them after the dump of its own rollout), paired with the rollout/ values of iteration i − 1's dump."""
    table = SOURCES["sb3"]
    tags = [tag for tag, _, _ in table.values()] + [SB3_ITERATIONS]  # not a callback's own tags, at other steps
    at = {tag: dict(scalars[tag]) for tag in tags if tag in scalars}  # tag: {step: value}, the last at a step
    dumps = sorted({step for points in at.values() for step in points})
    if not dumps:
        return []
    update_tags = [tag for tag, _, when in table.values() if when == "update" and tag in at]
    trained = [step for step in dumps if any(step in at[tag] for tag in update_tags)]
    if SB3_ITERATIONS in at:
        iteration = {step: at[SB3_ITERATIONS].get(step, math.nan) for step in dumps}
        if any(math.isnan(value) for value in iteration.values()):
            raise MinippoError(f"a row of SB3's log has no {SB3_ITERATIONS}")
    elif trained and trained[0] == dumps[0]:  # TensorBoard, its first record after an update: log_interval > 1
        notes.append(f"no {SB3_ITERATIONS} (SB3 writes none to TensorBoard), and the first record already follows an "
                     "update, so SB3 logged every few iterations (log_interval > 1): the updates are numbered by "
                     "record, the step is the record's, and return_mean, length_mean and steps_per_s are of the "
                     "rollout after each update")  # fmt: skip
        return [{"update": update, "step": step, **{name: factor * at.get(tag, {}).get(step, math.nan)
                                                    for name, (tag, factor, _) in table.items()}}
                for update, step in enumerate(trained, 1)]  # fmt: skip
    else:  # TensorBoard, or W&B's copy of it
        iteration = {step: i + 1 for i, step in enumerate(dumps)}
        notes.append(f"no {SB3_ITERATIONS} (SB3 writes none to TensorBoard): read as one record an iteration, "
                     "learn()'s default log_interval=1")  # fmt: skip
    step_of = {value: step for step, value in iteration.items()}  # an iteration: the step of its dump
    first, last = dumps[0], dumps[-1]
    per_iteration = (last - first) / (iteration[last] - iteration[first]) if last > first else first / iteration[first]
    rows, later = [], 0
    for step in trained:
        update = iteration[step] - 1
        own = step_of.get(update)  # the dump written after the update's own rollout, when it was logged
        later += own is None
        row = {"update": update, "step": step - per_iteration if own is None else own}
        for name, (tag, factor, when) in table.items():
            written = (step if own is None else own) if when == "rollout" else step
            row[name] = factor * at.get(tag, {}).get(written, math.nan)
        rows.append(row)
    if later:
        logged = sorted(step_of)
        gaps = {b - a for a, b in zip(logged, logged[1:])}
        gap = gaps.pop() if len(gaps) == 1 else None
        every = f"every {gap:g} iterations (log_interval={gap:g})" if gap else "some iterations only"
        which = "each" if later == len(rows) else f"{later} of them"
        notes.append(f"SB3 logged {every}: {len(rows)} of updates 1-{rows[-1]['update']:g} are read; {which} takes "
                     "return_mean, length_mean and steps_per_s from the rollout after the update (its own rollout's "
                     "were not logged)")  # fmt: skip
    return rows


def _cleanrl_rows(scalars: dict, notes: list) -> list[dict]:
    """One row a CleanRL update: the n-th global step with update scalars is update n; the episodes that ended in
    its rollout (after the step before, up to its own) give its return_mean and length_mean."""
    table = SOURCES["cleanrl"]
    at = {tag: dict(points) for tag, points in scalars.items()}
    steps = np.array(sorted({step for tag, _, when in table.values() if when == "update" for step in at.get(tag, ())}))
    rows = [{"update": update, "step": float(step)} for update, step in enumerate(steps, 1)]
    for name, (tag, factor, when) in table.items():
        if when == "episode":
            points = np.array(scalars.get(tag, ()), dtype=float).reshape(-1, 2)
            update_of = np.searchsorted(steps, points[:, 0], side="left")  # the first update whose step is ≥ the end
            kept = update_of < len(steps)  # an episode after the last update's step: its update was not logged
            total = np.bincount(update_of[kept], weights=points[kept, 1], minlength=len(steps))
            count = np.bincount(update_of[kept], minlength=len(steps))
            for row, episodes, value in zip(rows, count, total):
                row[name] = factor * value / episodes if episodes else math.nan
            if name == "return_mean" and not kept.all():
                notes.append(f"{np.sum(~kept)} episodes ended after the last update's step (its update was not "
                             "logged): not counted")  # fmt: skip
        else:
            for row in rows:
                row[name] = factor * at.get(tag, {}).get(row["step"], math.nan)
    return rows


def _finished(log: Log, names) -> Log:
    """``log`` with what it lacks said in its notes: the columns it has not, and those empty on some updates."""
    log.absent = {name for name in FIELDS if SOURCES[log.source][name][0] not in names}
    if log.absent:
        log.notes.append("not in the log: " + ", ".join(log.column(name) for name in FIELDS if name in log.absent))
    for name in FIELDS:
        empty = sum(math.isnan(row[name]) for row in log.rows)
        if name in log.absent or not empty:
            continue
        where = "any" if empty == len(log.rows) else str(empty)
        log.notes.append(f"{log.column(name)} has no value on {where} of the {len(log.rows)} updates")
    return log


def _setting(value) -> float | None:
    """A setting as a finite number: rl-zoo's "lin_X" (a schedule falling linearly from X) as X; None when it is not
    one (a word, a boolean, a table, NaN or infinity)."""
    if isinstance(value, bool):
        return None
    if isinstance(value, str) and value.strip().startswith("lin_"):
        value = value.strip()[4:]
    try:
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        return None
    return number if math.isfinite(number) else None


def _named_settings(source: str, named: dict, where: str, notes: list) -> dict:
    """The SETTINGS that ``named`` (the source's names: values) holds, in minippo's names; what it holds that is not a
    finite number is said in ``notes``."""
    settings = {}
    for name, names in SETTINGS.items():
        if names[source] not in named:
            continue
        value = _setting(named[names[source]])
        if value is None:
            notes.append(f"{where}: {names[source]} = {named[names[source]]!r} is not a number: not checked")
        else:
            settings[name] = value
    return settings


_UNREAD = object()  # a settings file that could not be parsed (a note says why)


def _yaml_table(config: Path, notes: list):
    """What a YAML file such as rl-zoo's config.yml holds (an OrderedDict dumped by PyYAML as a dict), or _UNREAD."""
    try:
        import yaml
    except ImportError:
        notes.append(f"{config}: reading it needs the PyYAML package (pip install 'minippo[doctor]'): no settings read")
        return _UNREAD

    class Loader(yaml.SafeLoader):  # rl-zoo dumps an OrderedDict: a python/object/apply tag over a list of pairs
        pass

    def ordered(loader, node):
        return dict(loader.construct_sequence(node, deep=True)[0])

    Loader.add_constructor("tag:yaml.org,2002:python/object/apply:collections.OrderedDict", ordered)
    try:
        named = yaml.load(config.read_text(encoding="utf-8"), Loader=Loader)  # noqa: S506 (a SafeLoader)
    except (yaml.YAMLError, UnicodeDecodeError, ValueError, TypeError, IndexError) as error:
        notes.append(f"{config} cannot be read as YAML ({str(error).splitlines()[0]}): no settings read")
        return _UNREAD
    return named


def _json_table(config: Path, notes: list):
    """What a JSON file holds, or _UNREAD."""
    try:
        return json.loads(config.read_text(encoding="utf-8"))
    except (ValueError, UnicodeDecodeError) as error:
        notes.append(f"{config} cannot be read as JSON ({error}): no settings read")
        return _UNREAD


def _settings_file(source: str, config: Path, notes: list) -> dict:
    """The settings in ``config`` (JSON or YAML), in the source's names; an SB3 file gets SB3's PPO defaults for what
    it leaves out, as rl-zoo's config.yml leaves out what a task's entry does not change."""
    yaml_file = config.suffix in (".yml", ".yaml")
    named = (_yaml_table if yaml_file else _json_table)(config, notes)
    if named is _UNREAD:
        return {}
    if not isinstance(named, dict):
        notes.append(f"{config} holds no table of {'hyperparameters' if yaml_file else 'settings'}: no settings read")
        return {}
    if not any(names[source] in named for names in SETTINGS.values()) and not (source == "sb3" and "policy" in named):
        notes.append(f"{config} holds none of the settings the doctor checks ("
                     + ", ".join(names[source] for names in SETTINGS.values()) + "): no settings read")  # fmt: skip
        return {}
    return _named_settings(source, (SB3_DEFAULTS | named) if source == "sb3" else named, str(config), notes)


def _nearest(name: str, file: Path, top: Path) -> Path | None:
    """The file ``name`` in the folder of ``file`` or the nearest folder above it, up to ``top``."""
    folder = file.parent
    while True:
        if (folder / name).is_file():
            return folder / name
        if folder == top or folder == folder.parent or top not in folder.parents:
            return None
        folder = folder.parent


def _cleanrl_hyperparameters(accumulator) -> dict:
    """CleanRL's hyperparameters table (``|param|value|`` rows of markdown) as {param: value}, or {} without one."""
    if CLEANRL_HYPERPARAMETERS not in accumulator.Tags().get("tensors", ()):
        return {}
    strings = accumulator.Tensors(CLEANRL_HYPERPARAMETERS)[0].tensor_proto.string_val
    text = strings[0].decode("utf-8", "replace") if strings else ""
    cells = (line.strip().strip("|").split("|") for line in text.splitlines())
    return {row[0].strip(): row[1].strip() for row in cells if len(row) == 2}


def _with_settings(log: Log, file: Path, top: Path, settings_path: Path | None = None) -> Log:
    """``log`` with the run's settings: from ``settings_path`` when given, else those its run left beside it (or in
    its events file); or a note that it carries none."""
    if settings_path is not None:
        if not settings_path.is_file():
            raise MinippoError(f"--settings: no file {settings_path}")
        log.settings, log.settings_file = _settings_file(log.source, settings_path, log.notes), str(settings_path)
    elif log.source == "minippo" and (config := _nearest(RunFolder.CONFIG, file, file.parent)):
        log.settings, log.settings_file = _settings_file("minippo", config, log.notes), str(config)
    elif log.source == "sb3" and log.file != "W&B CSV export" and (config := _nearest(SB3_CONFIG, file, top)):
        log.settings, log.settings_file = _settings_file("sb3", config, log.notes), str(config)
    if not log.settings:
        log.settings_file = None
        if not any("no settings read" in note for note in log.notes):
            where = {"minippo": f"no {RunFolder.CONFIG} beside {file.name}",
                     "sb3": f"no {SB3_CONFIG} in rl-zoo's format beside the log or above it",
                     "cleanrl": "no hyperparameters table in the events file"}[log.source]  # fmt: skip
            if log.file == "W&B CSV export":
                where = "a W&B export keeps its run's config apart"
            log.notes.append(f"the run's settings are not in the log ({where}; give them with --settings FILE): the "
                             "checks of its settings were not made")  # fmt: skip
    return log


def read_log(path, settings=None) -> Log:
    """The log at ``path`` (a CSV file, an events file, or a folder holding progress.csv or one run's event files), with
    the run's settings: from the file ``settings`` (a JSON or YAML table in the source's names) when given, else where
    the log carries them."""
    log, file = _read_log(Path(path))
    top = Path(path) if Path(path).is_dir() else file.parent
    return _with_settings(log, file, top, None if settings is None else Path(settings))


def _read_log(path: Path) -> tuple[Log, Path]:
    """The log at ``path``, and the file it was read from (of an events file, any one in its folder)."""
    if path.is_file():
        return (_read_events(path) if "tfevents" in path.name else _read_csv(path)), path
    if not path.is_dir():
        raise MinippoError(f"no run folder or log file {path}")
    progress = RunFolder(path).progress_csv  # minippo's, or Stable-Baselines3's of the same name
    if progress.is_file():
        return _read_csv(progress), progress
    folders = sorted({events.parent for events in path.rglob("*tfevents*") if events.is_file()})
    if len(folders) == 1:
        return _read_events(folders[0]), next(folders[0].glob("*tfevents*"))
    if len(folders) > 1:
        names = ", ".join(str(folder.relative_to(path)) for folder in folders[:4]) + ", ..." * (len(folders) > 4)
        raise MinippoError(f"{path} holds the TensorBoard event files of {len(folders)} runs ({names}): name one")
    found = ", ".join(sorted(item.name for item in path.iterdir())[:8]) or "nothing"
    raise MinippoError(f"{path} has no progress.csv and no TensorBoard event files (found: {found}); the doctor "
                       f"reads {READS}")  # fmt: skip
