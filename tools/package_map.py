"""The map of minippo's package: every module a box, every import between two of them an arrow, in its room.

    python tools/package_map.py            # print the Mermaid diagram
    python tools/package_map.py --write    # put it into docs/structure.md, between its two markers
    python tools/package_map.py --check    # exit 1 when docs/structure.md's diagram is not the package's as it is

The rooms: the core (what chapters 1-10 build: networks, distributions, losses, advantages, Adam, the rollout and
Algorithm 1), the library around it (environments, presets, the run folder, the command line, sweeps), and the
subpackages, one room each (the grader, the language models, the toys). The arrows are read from the modules' own
``import`` statements with ``ast``; nothing is imported or run.
"""

from __future__ import annotations

import argparse
import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "minippo"
DOC = ROOT / "docs" / "structure.md"
BEGIN, END = "<!-- package map: begin (python tools/package_map.py --write) -->", "<!-- package map: end -->"
CORE = {
    "network", "conv", "distributions", "losses", "advantages", "optimizer", "normalization", "agent", "rollout",
    "minibatches", "ppo", "config", "gradcheck",
}  # fmt: skip
ROOMS = {  # room: (its title, its colour)
    "core": ("the core: PPO from scratch (chapters 1-10)", "#dbeafe"),
    "library": ("the library around it: tasks, runs, the command line", "#e5e7eb"),
    "grading": ("minippo.grading: the class grader", "#fde68a"),
    "lm": ("minippo.lm: language models, RLHF, GRPO, DPO", "#d1fae5"),
    "toys": ("minippo.toys: the book's small exact worlds", "#fce7f3"),
}
LEFT_OUT = {"__init__", "__main__", "errors"}  # the package's door, `python -m minippo`, and the errors every room uses


def modules() -> dict[str, Path]:
    """{dotted name below minippo: its file}, e.g. {'ppo': …/ppo.py, 'lm.grpo': …/lm/grpo.py}."""
    found = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE).with_suffix("").parts
        if parts[-1] not in LEFT_OUT:
            found[".".join(parts)] = path
    return found


def room(name: str) -> str:
    if "." in name:
        return name.split(".")[0]
    return "core" if name in CORE else "library"


def imports(path: Path, known: set[str]) -> set[str]:
    """The modules of ``known`` that the file at ``path`` imports (at its top or inside a function)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("minippo"):
            base = node.module.removeprefix("minippo").lstrip(".")
            candidates = [f"{base}.{alias.name}".lstrip(".") for alias in node.names] + [base]
        elif isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
            candidates = [name.removeprefix("minippo.") for name in names if name.startswith("minippo.")]
        else:
            continue
        found |= {name for name in candidates if name in known}
    return found


def diagram() -> str:
    """The Mermaid flowchart: a subgraph for each room, a box for each module, an arrow from importer to imported."""
    found = modules()
    lines = ["flowchart LR"]
    for key, (title, colour) in ROOMS.items():
        members = [name for name in found if room(name) == key]
        if not members:
            continue
        lines.append(f'  subgraph {key}["{title}"]')
        lines += [f'    {node_id(name)}["{name.split(".")[-1]}"]' for name in members]
        lines.append("  end")
        lines.append(f"  style {key} fill:{colour},stroke:#6b7280")
    for name, path in found.items():
        for target in sorted(imports(path, set(found)) - {name}):
            lines.append(f"  {node_id(name)} --> {node_id(target)}")
    return "\n".join(lines) + "\n"


def node_id(name: str) -> str:
    return name.replace(".", "_")


def block() -> str:
    return f"{BEGIN}\n```mermaid\n{diagram()}```\n{END}"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write", action="store_true", help="write the diagram into docs/structure.md")
    parser.add_argument("--check", action="store_true", help="exit 1 when docs/structure.md's diagram is out of date")
    args = parser.parse_args(argv)
    if not (args.write or args.check):
        print(diagram(), end="")
        return 0
    text = DOC.read_text()
    if BEGIN not in text or END not in text:
        print(f"package_map: {DOC} has no package map markers", file=sys.stderr)
        return 2
    start, stop = text.index(BEGIN), text.index(END) + len(END)
    current = text[:start] + block() + text[stop:]
    if args.check:
        if current != text:
            print(f"package_map: the diagram in {DOC} is not the package's; run python tools/package_map.py --write")
            return 1
        return 0
    DOC.write_text(current)
    return 0


if __name__ == "__main__":
    sys.exit(main())
