"""The command line: ``minippo train | eval | plot | grade``. Bad input gets one line on stderr and exit code 2."""

from __future__ import annotations

import argparse
import dataclasses
import difflib
import json
import sys
from pathlib import Path

from minippo.errors import MinippoError, NonFiniteError

RUN_FILES = ("config.json", "progress.csv", "policy.npz", "checkpoint.npz", "curve.png")


class Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, no usage dump
        raise MinippoError(message)


def parse_override(text: str, fields: dict):
    """'key=value' → (key, value typed like the Config field)."""
    if "=" not in text:
        raise MinippoError(f"--config takes key=value, not '{text}'")
    key, raw = text.split("=", 1)
    key = key.strip().replace("-", "_")
    if key not in fields:
        close = difflib.get_close_matches(key, list(fields), n=3)
        hint = f"; did you mean {', '.join(close)}?" if close else ""
        raise MinippoError(f"unknown config field '{key}'{hint}")
    default = fields[key]
    raw = raw.strip()
    try:
        if raw.lower() == "none":
            return key, None
        if isinstance(default, bool):
            if raw.lower() not in ("true", "false", "1", "0", "yes", "no", "on", "off"):
                raise ValueError
            return key, raw.lower() in ("true", "1", "yes", "on")
        if isinstance(default, int):
            return key, int(float(raw)) if float(raw).is_integer() else int(raw)
        if isinstance(default, float) or default is None:
            return key, float(raw)
        if isinstance(default, tuple):
            return key, tuple(int(x) for x in raw.split(",") if x)
        return key, raw
    except ValueError:
        raise MinippoError(f"--config {key}: cannot read '{raw}' as {type(default).__name__}")


def cmd_train(args) -> int:
    from minippo.ppo import Config, train

    out = Path(args.out)
    defaults = {f.name: getattr(Config(), f.name) for f in dataclasses.fields(Config)}
    if args.resume:
        if not (out / "checkpoint.npz").exists():
            raise MinippoError(f"--resume: no checkpoint in {out}")
        try:
            config = Config.from_dict(json.loads((out / "config.json").read_text()))
        except (FileNotFoundError, json.JSONDecodeError) as error:
            raise MinippoError(f"--resume: cannot read {out / 'config.json'} ({error})")
        if args.steps is not None:
            config.total_steps = args.steps
    else:
        if out.exists() and any(out.iterdir()):
            if not args.force:
                raise MinippoError(f"{out} exists and is not empty; pass --force to overwrite or --resume to continue")
            for name in RUN_FILES:
                (out / name).unlink(missing_ok=True)
        overrides = dict(parse_override(text, defaults) for text in args.config)
        if args.steps is None:
            raise MinippoError("--steps is required")
        config = Config(
            env_id=args.env_id, total_steps=args.steps, seed=args.seed, objective=args.objective, **overrides
        )
    config.validate()
    from minippo.envs import make_env

    make_env(config.env_id).close()  # an unknown id or an unsupported space is refused before anything starts

    bar = None
    if not args.quiet:
        from tqdm import tqdm

        bar = tqdm(
            total=config.num_updates * config.batch_size,
            unit="step",
            dynamic_ncols=True,
            desc=config.env_id,
            file=sys.stderr,
        )

    def on_update(row):
        if bar is not None:
            bar.n = row["step"]
            bar.set_postfix_str(f"return {row['return_mean']:.1f}, {row['steps_per_s']:.0f} steps/s", refresh=True)

    try:
        rows = train(config, out, resume=args.resume, on_update=on_update)
    except NonFiniteError as error:
        kept = "the last good checkpoint is kept there" if (out / "checkpoint.npz").exists() else "no checkpoint yet"
        raise MinippoError(f"stopped: {error}; {kept} ({out})") from None
    except KeyboardInterrupt:
        if bar is not None:
            bar.close()
        print(
            f"minippo: interrupted; continue with: minippo train {config.env_id} --out {out} --resume", file=sys.stderr
        )
        return 130
    if bar is not None:
        bar.close()
    from minippo.plotting import plot_runs

    plot_runs([out], out / "curve.png", title=f"{config.env_id}, seed {config.seed}")
    last = rows[-1]
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


def cmd_grade(args) -> int:
    from minippo.grade import grade, grade_class

    if args.class_folder is not None:
        if args.solutions:
            raise MinippoError("--class grades the students' folders; leave out --solutions")
        return grade_class(args.class_folder, args.chapter, csv_path=args.csv)
    if args.csv is not None:
        raise MinippoError("--csv goes with --class FOLDER (a folder of student folders)")
    return grade(args.chapter, solutions=args.solutions, verbose=args.verbose)


def build_parser() -> Parser:
    parser = Parser(prog="minippo", description="PPO in NumPy, with hand-derived gradients.")
    sub = parser.add_subparsers(dest="command", parser_class=Parser)
    sub.required = True

    p = sub.add_parser("train", help="train PPO on a Gymnasium environment")
    p.add_argument("env_id")
    p.add_argument("--steps", type=int)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--out", required=True)
    p.add_argument("--objective", choices=["clip", "cpi", "klpen", "pg"], default="clip")
    p.add_argument("--config", nargs="*", default=[], metavar="KEY=VALUE", help="override Config fields")
    p.add_argument("--force", action="store_true", help="overwrite the run files in an existing --out")
    p.add_argument("--resume", action="store_true", help="continue from --out's last checkpoint")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_train)

    p = sub.add_parser("eval", help="run a saved policy deterministically")
    p.add_argument("run", help="a run folder (or a policy.npz)")
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--gif", help="write an animation of the first episode")
    p.set_defaults(func=cmd_eval)

    p = sub.add_parser("plot", help="overlay learning curves (mean and spread over seeds)")
    p.add_argument("runs", nargs="+")
    p.add_argument("--out", required=True)
    p.add_argument("--title")
    p.set_defaults(func=cmd_plot)

    p = sub.add_parser("grade", help="grade your exercises, chapter by chapter (or a whole class with --class)")
    p.add_argument("chapter", nargs="?", help="a chapter number or name (default: all)")
    p.add_argument("--solutions", action="store_true", help="grade the reference solutions instead")
    p.add_argument("--verbose", "-v", action="store_true", help="list every failing test with its message")
    p.add_argument("--class", dest="class_folder", metavar="FOLDER",
                   help="grade a class: FOLDER holds one folder of chNN_*.py modules per student")  # fmt: skip
    p.add_argument("--csv", metavar="FILE", help="with --class: write one row per student and chapter to FILE")
    p.set_defaults(func=cmd_grade)
    return parser


def main(argv=None) -> int:
    try:
        args = build_parser().parse_args(argv)
        return args.func(args)
    except MinippoError as error:
        print(f"minippo: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("minippo: interrupted", file=sys.stderr)
        return 130
