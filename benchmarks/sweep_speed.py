"""What ``minippo sweep`` saves: the same small grid trained one run after the other, then on the sweep engine with
two workers, wall time side by side.

    python -m benchmarks.sweep_speed                        # Hopper-v5, clip_epsilon 0.1 and 0.2, seeds 1-2
    python -m benchmarks.sweep_speed --steps 204800 --workers 2

One after the other is each run's ``minippo train`` command, run in this process (no interpreter start-up counted);
the sweep is ``minippo sweep`` with the same runs, timed from the start of Ray to its stop. The script checks that
every run's progress.csv is the same on both sides apart from the clock columns, and appends one row to
benchmarks/results/sweep_speed.csv: both wall times, their ratio, the trainings' own clocks summed, the load average
before and after, the commit and the command.
"""

from __future__ import annotations

import argparse
import os
import shlex
import tempfile
import time
from pathlib import Path

from benchmarks import common
from minippo.errors import MinippoError
from minippo.records import append_row, read_rows

CSV_PATH = common.RESULTS / "sweep_speed.csv"
FIELDS = ["env", "grid", "runs", "steps", "workers", "cpus", "sequential_s", "sweep_s", "speedup", "sequential_train_s"]
FIELDS += ["sweep_train_s", "same_progress", "load_before", "load_after", "commit", "command"]


def progress(folder) -> list[dict]:
    """A run's progress.csv without its clock columns."""
    rows = read_rows(folder / "progress.csv")
    return [{key: value for key, value in row.items() if key not in ("steps_per_s", "wall_s")} for row in rows]


def train_seconds(folder) -> float:
    return float(read_rows(folder / "progress.csv")[-1]["wall_s"])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default="Hopper-v5")
    parser.add_argument("--grid", default="clip_epsilon=0.1,0.2", help="KEY=V1,V2 as minippo sweep takes it")
    parser.add_argument("--seeds", default="1-2")
    parser.add_argument("--steps", type=int, default=102400)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--csv", default=str(CSV_PATH))
    args = parser.parse_args(argv)
    from minippo import sweep
    from minippo.cli import main as minippo

    try:
        runs = sweep.plan([args.env], sweep.parse_seeds(args.seeds), args.steps, sweep.parse_grid([args.grid]))
    except MinippoError as error:
        common.fail(str(error))
    if args.workers < 1 or args.steps < 2048:
        common.fail("--workers must be at least 1 and --steps at least one horizon (2048)")
    load_before, commit = os.getloadavg()[0], common.git_commit()  # the code as it starts
    with tempfile.TemporaryDirectory(prefix="sweep-speed-") as scratch:
        alone, swept = Path(scratch) / "alone", Path(scratch) / "swept"
        started = time.perf_counter()
        for run in runs:
            if minippo(shlex.split(run.command(alone))[1:]) != 0:
                common.fail(f"'{run.command(alone)}' failed")
        sequential = time.perf_counter() - started
        started = time.perf_counter()
        failed = sweep.Sweep(runs, swept, workers=args.workers, quiet=True).run()
        swept_s = time.perf_counter() - started
        if failed:
            common.fail(f"{failed} runs of the sweep failed; see {swept / 'sweep.csv'}")
        same = all(progress(alone / run.name) == progress(swept / run.name) for run in runs)
        train_alone = sum(train_seconds(alone / run.name) for run in runs)
        train_swept = sum(train_seconds(swept / run.name) for run in runs)
    steps = runs[0].config.num_updates * runs[0].config.batch_size
    row = {"env": args.env, "grid": args.grid, "runs": len(runs), "steps": steps, "workers": args.workers}
    row |= {"cpus": os.cpu_count(), "sequential_s": round(sequential, 1), "sweep_s": round(swept_s, 1)}
    row |= {"speedup": round(sequential / swept_s, 2), "sequential_train_s": round(train_alone, 1)}
    row |= {"sweep_train_s": round(train_swept, 1), "same_progress": "yes" if same else "no"}
    row |= {"load_before": round(load_before, 2), "load_after": round(os.getloadavg()[0], 2), "commit": commit}
    append_row(args.csv, FIELDS, {**row, "command": common.invocation("sweep_speed", argv)})
    print(
        f"{len(runs)} runs of {args.env}: one after the other {row['sequential_s']} s, on the sweep engine with "
        f"{args.workers} workers {row['sweep_s']} s ({row['speedup']}x); the same progress: {row['same_progress']}"
    )
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
