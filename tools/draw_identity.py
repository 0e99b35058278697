"""Draws the book's logo, icons and link-preview card into book/_static/ (run it again after changing a shape).

The mark is PPO's clipped objective for a positive advantage: L^CLIP rises with the probability ratio r until
r = 1 + ε and then stays flat, while the unclipped objective (faded) would keep rising. The same points make the
SVG files (written out by hand below) and the PNG card (drawn with matplotlib).

    python tools/draw_identity.py
"""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import FancyBboxPatch  # noqa: E402

STATIC = Path(__file__).resolve().parents[1] / "book" / "_static"
INK, PAPER, ACCENT, FAINT = "#16324f", "#ffffff", "#f2a541", "#7fa7cf"

# the mark, in a 64 × 64 box with y downwards (SVG's convention)
RISE = [(10, 50), (38, 22)]  # r from 0 to 1 + ε: the objective follows r·Â
FLAT = [(38, 22), (55, 22)]  # past 1 + ε: clipped, flat
UNCLIPPED = [(38, 22), (52, 8)]  # what r·Â alone would do
OLD = (27, 33)  # r = 1: the old policy, where every update starts
BASE = [(9, 54), (56, 54)]


def _points(points) -> str:
    return " ".join(f"{x},{y}" for x, y in points)


def mark_svg(background: str, line: str, faint: str) -> str:
    return (
        f'<rect x="1" y="1" width="62" height="62" rx="13" fill="{background}"/>'
        f'<polyline points="{_points(BASE)}" fill="none" stroke="{faint}" stroke-width="2.5" stroke-linecap="round"/>'
        f'<polyline points="{_points(UNCLIPPED)}" fill="none" stroke="{faint}" stroke-width="4" '
        f'stroke-dasharray="4 4" stroke-linecap="round"/>'
        f'<line x1="38" y1="22" x2="38" y2="54" stroke="{faint}" stroke-width="2" stroke-dasharray="3 3"/>'
        f'<polyline points="{_points(RISE + FLAT[1:])}" fill="none" stroke="{line}" stroke-width="6" '
        f'stroke-linecap="round" stroke-linejoin="round"/>'
        f'<circle cx="{OLD[0]}" cy="{OLD[1]}" r="5" fill="{ACCENT}"/>'
    )


def icon(background: str = INK) -> str:
    return (
        f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 64 64" width="64" height="64">'
        f"<title>minippo</title>{mark_svg(background, PAPER, FAINT)}</svg>\n"
    )


def logo(text: str, background: str) -> str:
    return (
        '<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 250 64" width="250" height="64">'
        "<title>minippo: PPO from scratch</title>"
        f"{mark_svg(background, PAPER, FAINT)}"
        f'<text x="76" y="41" font-family="Helvetica, Arial, sans-serif" font-size="34" font-weight="700" '
        f'fill="{text}">minippo</text>'
        f'<text x="77" y="58" font-family="Helvetica, Arial, sans-serif" font-size="12.5" fill="{text}" '
        f'opacity="0.8">PPO from scratch</text></svg>\n'
    )


def draw_mark(ax, scale: float = 1.0):
    """The mark on matplotlib axes spanning the 64 × 64 box; ``scale`` thickens the lines for a large picture."""
    ax.set_xlim(0, 64)
    ax.set_ylim(64, 0)
    ax.set_aspect("equal")
    ax.axis("off")
    ax.add_patch(FancyBboxPatch((1, 1), 62, 62, boxstyle="round,pad=0,rounding_size=13", color="#214a73"))
    xs, ys = zip(*BASE)
    ax.plot(xs, ys, color=FAINT, lw=4 * scale, solid_capstyle="round")
    xs, ys = zip(*UNCLIPPED)
    ax.plot(xs, ys, color=FAINT, lw=7 * scale, ls=(0, (1.6, 1.6)), dash_capstyle="round")
    ax.plot([38, 38], [22, 54], color=FAINT, lw=3 * scale, ls=(0, (1.5, 1.5)))
    xs, ys = zip(*(RISE + FLAT[1:]))
    ax.plot(xs, ys, color=PAPER, lw=11 * scale, solid_capstyle="round", solid_joinstyle="round")
    ax.plot(*OLD, "o", color=ACCENT, ms=20 * scale)


def share_card(path: Path):
    """1200 × 630, the size link previews use."""
    fig = plt.figure(figsize=(12, 6.3), dpi=100)
    fig.patch.set_facecolor(INK)
    draw_mark(fig.add_axes([0.06, 0.2, 0.6 * 630 / 1200, 0.6]))  # a square on the left
    fig.text(0.43, 0.56, "minippo", color=PAPER, fontsize=88, fontweight="bold", va="baseline")
    fig.text(0.435, 0.43, "Proximal Policy Optimization built", color=PAPER, fontsize=26, va="baseline")
    fig.text(0.435, 0.365, "from scratch in NumPy", color=PAPER, fontsize=26, va="baseline")
    fig.text(0.435, 0.26, "one idea a chapter, every gradient by hand", color=FAINT, fontsize=20, va="baseline")
    fig.savefig(path, facecolor=INK, metadata={"Software": None})
    plt.close(fig)


def touch_icon(path: Path):
    """180 × 180 on an opaque square: the icon phones put on the home screen (they round the corners)."""
    fig = plt.figure(figsize=(1.8, 1.8), dpi=100)
    fig.patch.set_facecolor("#214a73")
    ax = fig.add_axes([-0.02, -0.02, 1.04, 1.04])
    draw_mark(ax, scale=0.45)
    fig.savefig(path, facecolor="#214a73", metadata={"Software": None})
    plt.close(fig)


def main():
    STATIC.mkdir(parents=True, exist_ok=True)
    (STATIC / "favicon.svg").write_text(icon(), encoding="utf-8")
    (STATIC / "logo.svg").write_text(logo(INK, INK), encoding="utf-8")
    (STATIC / "logo-dark.svg").write_text(logo("#e6edf5", "#214a73"), encoding="utf-8")
    share_card(STATIC / "share-card.png")
    touch_icon(STATIC / "apple-touch-icon.png")
    print("wrote favicon.svg, logo.svg, logo-dark.svg, share-card.png and apple-touch-icon.png in", STATIC)


if __name__ == "__main__":
    main()
