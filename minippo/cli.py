"""The command line: ``minippo train | eval | plot | grade``. Bad input gets one line on stderr and exit code 2."""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import signal
import sys
import threading
from pathlib import Path

from minippo.config import Config, field_types
from minippo.errors import ConfigError, MinippoError, NonFiniteError
from minippo.flags import add_config_options, flag, train_argv  # noqa: F401 (train_argv: train_config's inverse)
from minippo.presets import PRESETS

PRESET_NAMES = tuple(PRESETS)


class HelpWithDefaults(argparse.HelpFormatter):
    """Each option's help ends with its default, where it has one worth saying."""

    def _get_help_string(self, action):
        text = action.help or ""
        unsaid = action.default is None or action.default is False or action.default == [] or not action.option_strings
        if not unsaid and action.default is not argparse.SUPPRESS and "%(default)" not in text:
            text += " (default: %(default)s)"
        return text

    def _fill_text(self, text, width, indent):  # a text of several lines (the list of Config fields) keeps them
        if "\n" in text:
            return "".join(indent + line for line in text.splitlines(keepends=True))
        return super()._fill_text(text, width, indent)


class Parser(argparse.ArgumentParser):
    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", HelpWithDefaults)
        super().__init__(*args, **kwargs)

    def error(self, message):  # one line, no usage dump
        raise MinippoError(message)


def steps_notice(config) -> str | None:
    """What a --steps that is not a whole number of batches trains: Algorithm 1 collects N·T steps an update, so a
    run is a whole number of updates (at least one); the rest is dropped, and said."""
    trained = config.num_updates * config.batch_size
    if trained == config.total_steps:
        return None
    updates = f"{config.num_updates} update{'s' if config.num_updates > 1 else ''}"
    return (
        f"--steps {config.total_steps:,} is not a multiple of the batch (N·T = {config.batch_size:,} steps); "
        f"training {trained:,} steps ({updates})"
    )


def settings_from_args(args) -> dict:
    """{field: value} of the fields a command sets: --preset's, then --config's, then each field's own option."""
    settings = dict(PRESETS[args.preset]) if getattr(args, "preset", None) else {}
    settings |= Config.parse_overrides(args.config)
    given = {field.name: getattr(args, f"set_{field.name}", None) for field in dataclasses.fields(Config)}
    return settings | {key: value for key, value in given.items() if value is not None}


def config_from_args(args) -> Config:
    """The Config of ``minippo train``: ENV, --steps, then --preset, --config and the fields' own options."""
    return Config(env_id=args.env_id, total_steps=args.steps, **settings_from_args(args))


def train_config(argv) -> Config:
    """The Config that ``minippo train`` with the words ``argv`` trains: ``train_config(train_argv(c, out)) == c``."""
    return config_from_args(build_parser().parse_args(["train", *argv]))


def progress_bar(config: Config):
    """A tqdm bar on stderr, counting the run's environment steps."""
    from tqdm import tqdm

    return tqdm(
        total=config.num_updates * config.batch_size,
        unit="step",
        dynamic_ncols=True,
        desc=config.env_id,
        file=sys.stderr,
        # tqdm's own rate would count the start-up too; the trainer's steps/s in the postfix is the one rate
        bar_format="{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} [{elapsed}<{remaining}{postfix}]",
    )


def cmd_train(args) -> int:
    from minippo.ppo import Trainer, train
    from minippo.run_folder import RunFolder

    folder = RunFolder(args.out)
    if args.resume:
        config = folder.resumed_config(args.steps)
        if config is None:
            return 0
    else:
        folder.check_new(args.force)  # refused unless --force; the old run's files are removed once the Trainer exists
        if args.steps is None:
            raise MinippoError("--steps is required")
        config = config_from_args(args)
    trainer = Trainer(config)  # bad settings or an unknown environment stop here, before the folder is touched
    notice = steps_notice(config)
    if notice and not args.resume:
        print(f"minippo: {notice}", file=sys.stderr)

    bar = None if args.quiet else progress_bar(config)

    def on_update(row):
        if bar is not None:
            bar.n = row["step"]
            bar.set_postfix_str(f"return {row['return_mean']:.1f}, {row['steps_per_s']:.0f} steps/s", refresh=True)

    # Ctrl-C: the update under way is finished and checkpointed, then the run stops; a second Ctrl-C stops at once
    stop = threading.Event()

    def interrupt(signum, frame):
        if stop.is_set():
            raise KeyboardInterrupt
        stop.set()

    in_main_thread = threading.current_thread() is threading.main_thread()  # where Python lets a handler be set
    previous = signal.signal(signal.SIGINT, interrupt) if in_main_thread else None
    out = folder.path
    continue_with = f"continue with: minippo train {config.env_id} --out {out} --resume"
    try:
        rows = train(trainer, out, resume=args.resume, on_update=on_update, stop=stop)
    except NonFiniteError as error:
        kept = "the last good checkpoint is kept there" if folder.checkpoint_npz.exists() else "no checkpoint yet"
        raise MinippoError(f"stopped: {error}; {kept} ({out})") from None
    except KeyboardInterrupt:
        kept = folder.checkpoint_update()
        kept = "no checkpoint yet" if kept is None else f"the checkpoint of update {kept} is kept; {continue_with}"
        print(f"minippo: interrupted at once; {kept}", file=sys.stderr)
        return 130
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
        if bar is not None:
            bar.close()
    last = rows[-1]
    if stop.is_set() and last["update"] < config.num_updates:
        print(f"minippo: interrupted; checkpoint written at update {last['update']}; {continue_with}", file=sys.stderr)
        return 130
    from minippo.plotting import plot_runs

    plot_runs([out], folder.curve_png, title=f"{config.env_id}, seed {config.seed}")
    print(
        f"{config.env_id}: {last['step']} steps, return (last 100 episodes) {last['return_mean']:.1f}, "
        f"{last['steps_per_s']:.0f} steps/s, {last['wall_s']:.0f} s -> {out}"
    )
    return 0


def cmd_eval(args) -> int:
    import numpy as np

    from minippo.evaluate import evaluate

    returns = evaluate(args.run, args.episodes, args.seed, args.gif)
    print(
        f"return {np.mean(returns):.1f} ± {np.std(returns):.1f} over {len(returns)} episodes"
        + (f"; animation in {args.gif}" if args.gif else "")
    )
    return 0


def cmd_plot(args) -> int:
    from minippo.plotting import plot_runs

    for run in args.runs:
        if not Path(run).is_dir():
            raise MinippoError(f"no run folder {run}")
    print(plot_runs(args.runs, args.out, title=args.title))
    return 0


def cmd_sweep(args) -> int:
    from minippo import sweep

    if args.steps is None:
        raise MinippoError("--steps is required")
    if args.workers is not None and args.workers < 1:
        raise MinippoError(f"--workers must be at least 1, not {args.workers}")
    if args.retries < 0:
        raise MinippoError(f"--retries must be 0 or more, not {args.retries}")
    if len(set(args.env_ids)) != len(args.env_ids):
        raise MinippoError("a task is named twice")
    seeds, grid = sweep.parse_seeds(args.seeds), sweep.parse_grid(args.grid)
    for key, _ in grid:
        if key in ("env_id", "seed", "total_steps"):
            raise MinippoError(f"--grid {key}: give the tasks, --seeds and --steps instead")
    runs = sweep.plan(args.env_ids, seeds, args.steps, grid, settings_from_args(args))
    from minippo.envs import make_env

    for env_id in args.env_ids:  # an unknown id is refused before Ray starts
        make_env(env_id).close()
    job = sweep.Sweep(runs, args.out, args.csv, args.workers, args.address, args.retries, quiet=args.quiet)
    try:
        failed = job.run()
    except KeyboardInterrupt:
        print(
            f"minippo: interrupted; {job.recorded} runs recorded in {job.csv_path}; the same command continues",
            file=sys.stderr,
        )
        return 130
    return 1 if failed else 0


def sweep_file_words(line: str) -> list[str]:
    """A line of a ``minippo sweep @FILE``: shell words, several to a line, # starts a comment."""
    import shlex

    return shlex.split(line, comments=True)


def cmd_grade(args) -> int:
    from minippo.grading.grade import grade, grade_class
    from minippo.grading.gradescope import autograder_zip

    if args.class_folder is not None:
        if args.solutions:
            raise MinippoError("--class grades the students' folders; leave out --solutions")
        if args.submission is not None or args.gradescope is not None:
            raise MinippoError("--class grades a whole class into --csv; --submission and --gradescope grade one")
        return grade_class(args.class_folder, args.chapter, csv_path=args.csv)
    if args.csv is not None:
        raise MinippoError("--csv goes with --class FOLDER (a folder of student folders)")
    if args.autograder_zip is not None:
        if not (args.repo and args.commit):
            raise MinippoError("--autograder-zip needs --repo URL and --commit SHA (where setup.sh installs minippo)")
        return autograder_zip(args.autograder_zip, args.repo, args.commit, args.chapter)
    if args.submission is not None and args.solutions:
        raise MinippoError("--submission grades that folder; leave out --solutions")
    return grade(
        args.chapter, solutions=args.solutions, impl=args.submission, verbose=args.verbose, gradescope=args.gradescope
    )


def cmd_doctor(args) -> int:
    from minippo.doctor import report

    text, status = report(args.run, as_json=args.json, settings=args.settings)
    print(text)
    return status


def build_parser() -> Parser:
    parser = Parser(prog="minippo", description="PPO in NumPy, with hand-derived gradients.")
    sub = parser.add_subparsers(dest="command", parser_class=Parser)
    sub.required = True

    p = sub.add_parser(
        "train",
        help="train PPO on a Gymnasium environment",
        description="Train PPO (Algorithm 1 with the paper's MuJoCo settings) and write the run folder: config.json, "
        "progress.csv (one row per update), policy.npz, checkpoint.npz and curve.png.",
        formatter_class=lambda prog: HelpWithDefaults(prog, width=120),
    )
    p.add_argument(
        "env_id",
        help="a Gymnasium id with flat or image Box observations, e.g. CartPole-v1, Hopper-v5, or "
        "MinAtar/Breakout-v1 (with --preset atari)",
    )
    p.add_argument(
        "--steps",
        type=int,
        help="environment steps to train (required unless --resume); a run is whole updates of N·T steps, so a "
        "number that is not a multiple is cut down to one (and said)",
    )
    p.add_argument("--out", required=True, help="the run folder to write (created if missing)")
    p.add_argument("--preset", choices=PRESET_NAMES,
                   help="start from named settings (minippo/presets.py): atari is the paper's Table 5 on MinAtar's "
                   "network, a2c its A2C baseline; the options below override them")  # fmt: skip
    p.add_argument("--config", nargs="*", default=[], metavar="KEY=VALUE",
                   help="set fields of minippo.Config by name, e.g. horizon=512 entropy_coef=0.01")  # fmt: skip
    p.add_argument("--force", action="store_true",
                   help="replace the run files in an existing --out (once the new settings prove valid)")  # fmt: skip
    p.add_argument("--resume", action="store_true", help="continue from --out's last checkpoint")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_config_options(p)
    p.set_defaults(func=cmd_train)

    p = sub.add_parser("eval", help="run a saved policy deterministically")
    p.add_argument("run", help="a run folder (or a policy.npz)")
    p.add_argument("--episodes", type=int, default=10, help="episodes to run; their mean ± std return is printed")
    p.add_argument("--seed", type=int, default=0, help="episode i resets the environment with seed + i")
    p.add_argument("--gif", metavar="FILE", help="write an animation of the first episode to FILE")
    p.set_defaults(func=cmd_eval)

    p = sub.add_parser("plot", help="overlay learning curves (mean and spread over seeds)")
    p.add_argument("runs", nargs="+", help="run folders; runs that differ only in their seed are drawn as one curve")
    p.add_argument("--out", required=True, help="the PNG to write")
    p.add_argument("--title", help="the figure's title")
    p.set_defaults(func=cmd_plot)

    p = sub.add_parser(
        "sweep",
        help="train a grid of runs at once on Ray (this machine, or a cluster with --address)",
        description="Every task x seed x combination of --grid values, each run what minippo train runs alone. "
        "minippo sweep @FILE reads the arguments from a file (shell words, # for comments).",
        fromfile_prefix_chars="@",
    )
    p.convert_arg_line_to_args = sweep_file_words
    p.add_argument("env_ids", nargs="+", metavar="ENV", help="one or more Gymnasium ids")
    p.add_argument("--seeds", default="1", help="seeds: 1-3, 1,4,7 (default 1)")
    p.add_argument("--steps", type=int, help="environment steps per run (required)")
    p.add_argument("--grid", action="append", default=[], metavar="KEY=V1,V2", help="a Config field and its values")
    p.add_argument("--config", nargs="*", default=[], metavar="KEY=VALUE", help="set Config fields in every run")
    p.add_argument("--preset", choices=PRESET_NAMES, help="start every run from named settings (as minippo train)")
    p.add_argument("--out", required=True, help="the folder of run folders (and of sweep.csv)")
    p.add_argument("--csv", help="the sweep's CSV (default OUT/sweep.csv)")
    p.add_argument("--workers", type=int, help="runs at once (default: every core, or every CPU of the cluster)")
    p.add_argument("--address", help="a running Ray cluster, HOST:PORT (default: $RAY_ADDRESS, else this machine)")
    p.add_argument("--retries", type=int, default=0, help="tries again a failed run this many times")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_config_options(p, skip=("env_id", "total_steps", "seed"))
    p.set_defaults(func=cmd_sweep)

    p = sub.add_parser("grade", help="grade your exercises, chapter by chapter (or a whole class with --class)")
    p.add_argument("chapter", nargs="?", help="a chapter number or name (default: all)")
    p.add_argument("--solutions", action="store_true", help="grade the reference solutions instead")
    p.add_argument("--verbose", "-v", action="store_true", help="list every failing test with its message")
    p.add_argument("--class", dest="class_folder", metavar="FOLDER",
                   help="grade a class: FOLDER holds one folder of chNN_*.py modules per student")  # fmt: skip
    p.add_argument("--csv", metavar="FILE", help="with --class: write one row per student and chapter to FILE")
    p.add_argument("--submission", metavar="FOLDER", help="grade the chNN_*.py modules in FOLDER (one student's)")
    p.add_argument("--gradescope", metavar="FILE", help="also write the results to FILE in Gradescope's format")
    p.add_argument(
        "--autograder-zip",
        metavar="ZIP",
        help="write Gradescope's autograder zip (setup.sh, run_autograder) to ZIP; needs --repo, --commit",
    )
    p.add_argument("--repo", help="with --autograder-zip: the course repository's address, for setup.sh")
    p.add_argument("--commit", help="with --autograder-zip: the commit setup.sh installs")
    p.set_defaults(func=cmd_grade)

    p = sub.add_parser(
        "doctor",
        help="name the failure signatures in a run's log",
        description="Read a run's log (minippo's or Stable-Baselines3's progress.csv, SB3's or CleanRL's TensorBoard "
        "event files, or W&B's CSV export of either) and report each failure signature its debug variables show: what "
        "was seen against the healthy range, the likely causes in order, and the section of the book to read; where "
        "the log carries the run's settings, or --settings names them, three are first checked against bounds that "
        "PPO's objective sets. A rule whose data the log lacks is reported as not checked. Exit status: 0 when every "
        "rule was checked and none holds, 1 when one holds (or a setting is out of bounds), 2 on bad input, 3 when "
        "none holds but some rules could not be checked.",
    )
    p.add_argument("run", help="a run folder (holding progress.csv or one run's TensorBoard event files), a CSV file "
                   "or an events file")  # fmt: skip
    p.add_argument("--json", action="store_true", help='the report as JSON, and an error as {"error": ...}')
    p.add_argument("--settings", metavar="FILE", help="the run's settings, when its log does not carry them: a JSON "
                   "or YAML table in the log's library's names (minippo's config.json, rl-zoo's config.yml, CleanRL's "
                   "arguments)")  # fmt: skip
    p.set_defaults(func=cmd_doctor)
    return parser


def option_message(error: ConfigError) -> str:
    """A field's error in the command line's words: the option that sets the field, then the field, however it was
    set (--preset, --config or the option itself): --minibatch-size (minibatch_size): 4096 exceeds the batch …"""
    message, field = str(error), error.field
    if not field:
        return f"--config: {message}"  # a --config word that is not KEY=VALUE
    if field not in field_types():
        return message  # an unknown field, which the message names
    rest = message[len(field) :]
    if message.startswith(field) and rest[:1] in (" ", ":"):
        message = rest.lstrip(": ")
    return f"{flag(field)} ({field}): {message}"


def error_exit(message: str, as_json: bool) -> int:
    """One line on stderr (and, for --json, {"error": ...} on stdout); exit status 2."""
    if as_json:
        print(json.dumps({"error": message}))
    print(f"minippo: error: {message}", file=sys.stderr)
    return 2


def wants_json(argv, args) -> bool:
    """Whether errors go out as JSON: ``minippo doctor --json``, even when its other arguments did not parse."""
    if args is not None:
        return bool(getattr(args, "json", False))
    words = sys.argv[1:] if argv is None else list(argv)
    return bool(words) and words[0] == "doctor" and "--json" in words


def main(argv=None) -> int:
    args = None
    try:
        args = build_parser().parse_args(argv)
        status = args.func(args)
        sys.stdout.flush()  # here, so that a reader gone away (| head) is caught below, not at exit
        return status
    except ConfigError as error:
        return error_exit(option_message(error), wants_json(argv, args))
    except MinippoError as error:
        return error_exit(str(error), wants_json(argv, args))
    except BrokenPipeError:  # stdout's reader went away (minippo doctor RUN | head): stop quietly, as a command that
        # SIGPIPE ends does, with its status; stdout goes to /dev/null so that Python's last flush cannot fail again
        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return 128 + 13  # SIGPIPE
    except KeyboardInterrupt:
        print("minippo: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
