"""Does the current minippo compute the same training as an earlier commit? A short run of each, side by side.

    python -m benchmarks.same_math 92bb26d --env InvertedDoublePendulum-v5 --seed 1 --updates 20

The earlier commit is checked out into a temporary git worktree; both codes train the same task and seed for a few
updates, one BLAS thread each, and each update's statistics and their largest relative difference go to a CSV. Same
math agrees to rounding (about 1e-15 relative in float64) at update 1; a changed loss or random draw shows far above.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from benchmarks import common
from minippo.records import read_rows

CSV_PATH = common.RESULTS / "same_math.csv"
COLUMNS = ("return_mean", "approx_kl", "entropy", "value_loss", "explained_variance")
FIELDS = ["env", "seed", "dtype", "update", "earlier_commit", "commit"]
FIELDS += [f"{column}_{side}" for column in COLUMNS for side in ("earlier", "current")]
FIELDS += ["max_relative_difference", "command"]


def git(*args) -> str:
    result = subprocess.run(["git", *args], cwd=common.ROOT, capture_output=True, text=True)
    if result.returncode != 0:
        message = (result.stderr.strip().splitlines() or [f"exit code {result.returncode}"])[-1]
        raise common.BenchmarkError(f"git {' '.join(args)}: {message}")
    return result.stdout.strip()


def train(code_dir: Path, args, out: Path) -> list[dict]:
    """``python -m minippo train`` of ``args``' task, seed, updates and dtype, run from ``code_dir`` so that the minippo
    imported is the one in that folder."""
    env = {**os.environ, **common.THREAD_ENV}
    probe = "import minippo, minippo.ppo as p; print(minippo.__file__); print('dtype' in p.Config.__dataclass_fields__)"
    probed = subprocess.run([sys.executable, "-c", probe], cwd=code_dir, env=env, capture_output=True, text=True)
    where, has_dtype = probed.stdout.split()
    if not Path(where).resolve().is_relative_to(code_dir.resolve()):
        raise common.BenchmarkError(f"running from {code_dir} imported minippo from {where}, not from that folder")
    argv = [sys.executable, "-m", "minippo", "train", args.env, "--steps", str(args.updates * 2048), "--seed"]
    argv += [str(args.seed), "--out", str(out), "--quiet", "--force"]
    if has_dtype == "True":
        argv += ["--config", f"dtype={args.dtype}"]
    elif args.dtype != "float64":  # before the dtype field, minippo computed in float64 only
        raise common.BenchmarkError(f"the code at {code_dir} has no dtype setting: it computes in float64 only")
    result = subprocess.run(argv, cwd=code_dir, env=env, capture_output=True, text=True)
    if result.returncode != 0:
        raise common.BenchmarkError(f"training at {code_dir} failed: {result.stderr.strip()[-300:]}")
    return read_rows(out / "progress.csv")


@common.one_line_errors
def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("earlier", help="the earlier commit to compare with (any git revision)")
    parser.add_argument("--env", default="InvertedDoublePendulum-v5")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--updates", type=int, default=20)
    parser.add_argument("--dtype", choices=("float64", "float32"), default="float64")
    parser.add_argument("--csv", default=str(CSV_PATH), help="the record (a comparison of the same is replaced)")
    args = parser.parse_args(argv)
    if not 1 <= args.updates <= 500:
        common.fail(f"--updates must be between 1 and 500, not {args.updates}")
    try:
        earlier = git("rev-parse", "--short", "--verify", "--quiet", f"{args.earlier}^{{commit}}")
    except common.BenchmarkError:
        raise common.BenchmarkError(f"no commit named {args.earlier!r} in this repository") from None
    current = common.git_commit()
    with tempfile.TemporaryDirectory(prefix="minippo-same-math-") as scratch:
        worktree = Path(scratch) / "earlier"
        git("worktree", "add", "--detach", str(worktree), earlier)
        try:
            earlier_rows = train(worktree, args, worktree.with_name("earlier-run"))
            current_rows = train(common.ROOT, args, worktree.with_name("run"))
        finally:
            git("worktree", "remove", "--force", str(worktree))
    table = []
    for before, now in zip(earlier_rows, current_rows):
        row = {"env": args.env, "seed": args.seed, "dtype": args.dtype, "update": now["update"]}
        row |= {"earlier_commit": earlier, "commit": current, "command": common.invocation("same_math", argv)}
        for column in COLUMNS:
            row[f"{column}_earlier"], row[f"{column}_current"] = before[column], now[column]
        pairs = [(float(before[column]), float(now[column])) for column in COLUMNS]
        row["max_relative_difference"] = f"{max(abs(a - b) / (max(abs(a), abs(b)) or 1.0) for a, b in pairs):.3g}"
        table.append(row)
    same = ("env", "seed", "dtype", "earlier_commit")
    kept = [old for old in read_rows(args.csv) if any(str(old[k]) != str(table[0][k]) for k in same)]
    common.write_rows(args.csv, kept + table, FIELDS)
    for row in table:
        print(f"update {row['update']:>3}: largest relative difference {row['max_relative_difference']}")
    print(f"{args.env} seed {args.seed}, {args.dtype}: {earlier} against {current} -> {common.relative(args.csv)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
