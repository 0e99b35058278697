"""Chapter 10's ablations: every implementation detail of minippo switched off, one at a time, against the defaults.

Each run goes through the minippo command line, one training at a time, and leaves its config.json and progress.csv
in ``runs/<ablation>-seed<S>/`` beside this file. Every finished run appends one row to ``results.csv`` with the
exact command that produced it, so the book can quote it. Runs already in results.csv are skipped, so the script can
be stopped and started again.

    python benchmarks/ablations/run_ablations.py              # all ablations, seeds 1 and 2, Hopper-v5, 163,840 steps
    python benchmarks/ablations/run_ablations.py --dry-run    # print the commands only
    python benchmarks/ablations/run_ablations.py --only default anneal_lr --seeds 3
"""

from __future__ import annotations

import argparse
import hashlib
import shlex
import subprocess
import sys
from pathlib import Path

from minippo.records import append_row, commit_of_code, read_rows

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
RESULTS = HERE / "results.csv"
FIELDS = [
    "ablation",
    "override",
    "env",
    "seed",
    "steps",
    "return_mean",
    "return_last10",
    "wall_s",
    "steps_per_s",
    "commit",
    "command",
]

# The detail each run switches off; "default" is Config() as it is (the paper's MuJoCo settings).
ABLATIONS = {
    "default": "",
    "normalize_advantages": "normalize_advantages=false",
    "clip_value_loss": "clip_value_loss=false",
    "grad_norm_clipping": "grad_norm_clipping=false",
    "anneal_lr": "anneal_lr=false",
    "orthogonal_init": "orthogonal_init=false",
    "normalize_observations": "normalize_observations=false",
    "scale_rewards": "scale_rewards=false",
    "use_gae": "use_gae=false",
    "shuffle_minibatches": "shuffle_minibatches=false",
}


class Parser(argparse.ArgumentParser):
    def error(self, message):
        print(f"run_ablations: error: {message}", file=sys.stderr)
        raise SystemExit(2)


def command_for(ablation: str, env: str, steps: int, seed: int) -> list[str]:
    out = HERE.relative_to(ROOT) / "runs" / f"{ablation}-seed{seed}"
    command = ["minippo", "train", env, "--steps", str(steps), "--seed", str(seed), "--out", str(out)]
    command += ["--quiet", "--force"]
    if ABLATIONS[ablation]:
        command += ["--config", ABLATIONS[ablation]]
    return command


def recorded() -> set[tuple[str, str, int, int]]:
    return {(r["ablation"], r["env"], int(r["seed"]), int(r["steps"])) for r in read_rows(RESULTS)}


def source_digest() -> str:
    """A digest of minippo's source, to notice a change of the code while a run is going on."""
    digest = hashlib.sha256()
    for path in sorted((ROOT / "minippo").glob("*.py")):
        digest.update(path.name.encode() + path.read_bytes())
    return digest.hexdigest()


def run_one(ablation: str, env: str, steps: int, seed: int) -> dict:
    command = command_for(ablation, env, steps, seed)
    commit, digest = commit_of_code(root=ROOT), source_digest()
    result = subprocess.run(command, cwd=ROOT, capture_output=True, text=True)
    if result.returncode != 0:
        message = (result.stderr.strip().splitlines() or ["no message"])[-1]
        raise RuntimeError(f"{ablation} seed {seed} failed: {message}")
    if source_digest() != digest:
        raise RuntimeError(f"minippo's source changed during {ablation} seed {seed}; run the script again")
    run_dir = ROOT / command[command.index("--out") + 1]
    rows = read_rows(run_dir / "progress.csv")
    for name in ("checkpoint.npz", "policy.npz", "curve.png"):  # the record is config.json + progress.csv
        (run_dir / name).unlink(missing_ok=True)
    last = rows[-1]
    tail = [float(r["return_mean"]) for r in rows[-10:]]
    return {
        "ablation": ablation,
        "override": ABLATIONS[ablation] or "(none)",
        "env": env,
        "seed": seed,
        "steps": int(last["step"]),
        "return_mean": round(float(last["return_mean"]), 2),
        "return_last10": round(sum(tail) / len(tail), 2),
        "wall_s": round(float(last["wall_s"]), 1),
        "steps_per_s": round(float(last["steps_per_s"]), 1),
        "commit": commit,
        "command": shlex.join(command),
    }


def main(argv=None) -> int:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="Hopper-v5")
    parser.add_argument("--steps", type=int, default=163_840, help="per run (80 updates of T = 2048 by default)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--only", nargs="+", metavar="ABLATION", help=f"a subset of: {', '.join(ABLATIONS)}")
    parser.add_argument("--dry-run", action="store_true", help="print the commands, run nothing")
    args = parser.parse_args(argv)
    names = args.only or list(ABLATIONS)
    unknown = [name for name in names if name not in ABLATIONS]
    if unknown:
        parser.error(f"unknown ablation(s) {', '.join(unknown)}; choose from {', '.join(ABLATIONS)}")
    if args.steps < 2048:
        parser.error("--steps must be at least one batch (2048)")
    done = recorded()
    # steps in results.csv are whole batches: the command line trains floor(steps / 2048) updates
    expected_steps = (args.steps // 2048) * 2048
    for seed in args.seeds:  # seed by seed, so that a partial run still covers every ablation once
        for name in names:
            if (name, args.env, seed, expected_steps) in done:
                continue
            if args.dry_run:
                print(shlex.join(command_for(name, args.env, args.steps, seed)))
                continue
            try:
                row = run_one(name, args.env, args.steps, seed)
            except RuntimeError as error:
                print(f"run_ablations: error: {error}", file=sys.stderr)
                return 1
            append_row(RESULTS, FIELDS, row)
            print(f"{name} seed {seed}: return {row['return_mean']:.1f} after {row['steps']} steps", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
