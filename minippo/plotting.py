"""Learning curves from run folders: one run, or the mean and spread of several seeds."""

from __future__ import annotations

import csv
import json
from collections import defaultdict
from pathlib import Path

import numpy as np

from minippo.errors import MinippoError

ORANGE, SAGE, INK = "#c8643b", "#7d9a72", "#2f2a26"  # the course's palette (clay orange, sage, ink)
PALETTE = [ORANGE, SAGE, "#4f6d8f", "#b59a3c", "#8a5a83", "#5f8f8c", INK]


def read_progress(run_dir) -> dict[str, np.ndarray]:
    """progress.csv as columns of floats."""
    path = Path(run_dir) / "progress.csv"
    try:
        with open(path, newline="") as handle:
            rows = list(csv.DictReader(handle))
    except FileNotFoundError:
        raise MinippoError(f"no progress.csv in {run_dir}")
    if not rows:
        raise MinippoError(f"{path} has no rows yet")
    return {key: np.array([float(row[key]) for row in rows]) for key in rows[0]}


def run_label(run_dir) -> str:
    try:
        config = json.loads((Path(run_dir) / "config.json").read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return Path(run_dir).name
    objective = config.get("objective", "clip")
    return f"{config.get('env_id', '?')} ({objective})"


def plot_runs(run_dirs, out, title: str | None = None, metric: str = "return_mean") -> Path:
    """Overlay the runs' curves, grouping runs with the same env and objective: mean line, min–max band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = defaultdict(list)
    for run_dir in run_dirs:
        groups[run_label(run_dir)].append(read_progress(run_dir))
    fig, ax = plt.subplots(figsize=(7, 4), dpi=110)
    for colour, (label, runs) in zip(PALETTE * 10, sorted(groups.items())):
        end = min(run["step"][-1] for run in runs)
        grid = np.linspace(min(run["step"][0] for run in runs), end, 200)
        curves = []
        for run in runs:
            keep = np.isfinite(run[metric])
            if keep.sum() >= 1:
                curves.append(np.interp(grid, run["step"][keep], run[metric][keep]))
        if not curves:
            continue
        curves = np.array(curves)
        suffix = f", {len(curves)} seeds" if len(curves) > 1 else ""
        ax.plot(grid, curves.mean(axis=0), color=colour, lw=2, label=f"{label}{suffix}")
        if len(curves) > 1:
            ax.fill_between(grid, curves.min(axis=0), curves.max(axis=0), color=colour, alpha=0.2, lw=0)
    ax.set_xlabel("environment steps")
    ax.set_ylabel("mean return, last 100 episodes" if metric == "return_mean" else metric)
    ax.grid(alpha=0.3)
    ax.legend(frameon=False, fontsize=8)
    if title:
        ax.set_title(title)
    fig.tight_layout()
    out = Path(out)
    fig.savefig(out)
    plt.close(fig)
    return out
