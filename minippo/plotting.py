"""Learning curves from run folders: one run, or the mean and spread of several seeds."""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import numpy as np

from minippo.errors import MinippoError
from minippo.records import read_rows
from minippo.run_folder import RunFolder

ORANGE, SAGE, INK = "#c8643b", "#7d9a72", "#2f2a26"  # the course's palette (clay orange, sage, ink)
PALETTE = [ORANGE, SAGE, "#4f6d8f", "#b59a3c", "#8a5a83", "#5f8f8c", INK]


def read_progress(run_dir) -> dict[str, np.ndarray]:
    """progress.csv as columns of floats."""
    path = RunFolder(run_dir).progress_csv
    if not path.exists():
        raise MinippoError(f"no {path.name} in {run_dir}")
    rows = read_rows(path)
    if not rows:
        raise MinippoError(f"{path} has no rows yet")
    return {key: np.array([float(row[key]) for row in rows]) for key in rows[0]}


def seed_curves(runs: list[dict], metric: str = "return_mean", points: int = 200):
    """(grid, values): each run's ``metric`` (runs as ``read_progress`` gives them) on the steps all of them cover,
    one row per run; None when no run has a finite value."""
    runs = [run for run in runs if np.isfinite(run[metric]).any()]
    if not runs:
        return None
    grid = np.linspace(max(run["step"][0] for run in runs), min(run["step"][-1] for run in runs), points)
    values = []
    for run in runs:
        keep = np.isfinite(run[metric])
        values.append(np.interp(grid, run["step"][keep], run[metric][keep]))
    return grid, np.array(values)


def draw_seed_band(ax, grid, values, colour: str, label: str | None = None, alpha: float = 0.2, x_scale=1.0) -> None:
    """On ``ax``: the mean over seeds (rows of ``values``) as a line, and the band from the lowest seed to the
    highest (when there are several); steps are divided by ``x_scale``."""
    if len(values) > 1:
        ax.fill_between(grid / x_scale, values.min(axis=0), values.max(axis=0), color=colour, alpha=alpha, lw=0)
    ax.plot(grid / x_scale, values.mean(axis=0), color=colour, lw=2, label=label)


def run_label(run_dir) -> str:
    try:
        config = json.loads(RunFolder(run_dir).config_json.read_text())
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
        curves = seed_curves(runs, metric)
        if curves is None:
            continue
        grid, values = curves
        suffix = f", {len(values)} seeds" if len(values) > 1 else ""
        draw_seed_band(ax, grid, values, colour, f"{label}{suffix}")
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
