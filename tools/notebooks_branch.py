"""Makes the contents of the `notebooks` branch: the book's executed chapters as .ipynb, ready for Colab and Binder.

The chapters are MyST Markdown; Colab and Binder open notebooks from a repository. The built site already holds each
chapter executed (``_sources/NAME.ipynb``, the download menu's file). This copies them to OUT with one cell added at
the top that, outside a clone of the repository, fetches minippo at the commit the site was built from, installs it
and moves into its ``book/`` folder (the chapters read benchmark records from there). OUT also gets a
``requirements.txt`` and ``runtime.txt`` for Binder, and a README. The Pages workflow commits OUT as the whole of
the `notebooks` branch.

    python tools/notebooks_branch.py book/_build/html book/_build/notebooks \\
        --repository https://github.com/someone/minippo --commit 0123abc...
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

SETUP = """\
# Opened outside a clone of the repository (Colab, Binder): fetch minippo at the commit this page was built from,
# install it with the book's tools, and run from its book/ folder, where the chapters find the benchmark records.
# In a clone, or run a second time, this cell does nothing.
import os
import subprocess
import sys
from pathlib import Path

if not Path("../minippo/__init__.py").exists():
    if not Path("minippo-src").exists():
        subprocess.run(["git", "clone", "--quiet", "{repository}", "minippo-src"], check=True)
        subprocess.run(["git", "-C", "minippo-src", "checkout", "--quiet", "{commit}"], check=True)
    subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "./minippo-src", "myst-nb"], check=True)
    os.chdir("minippo-src/book")
    sys.path.insert(0, os.path.abspath(".."))
"""

README = """# The executed chapters of minippo's book

Made by the Pages workflow from {repository}
at commit {commit}.

Every push to the default branch replaces this branch whole. Colab and Binder open these notebooks from the book's
launch buttons. Edit the chapters in `book/*.md` on the default branch, never here.
"""


def setup_cell(repository: str, commit: str) -> dict:
    source = SETUP.format(repository=repository, commit=commit)
    return {
        "cell_type": "code",
        "execution_count": None,
        "id": "minippo-setup",
        "metadata": {"tags": ["setup"]},
        "outputs": [],
        "source": source.splitlines(keepends=True),
    }


def write_branch(html: Path, out: Path, repository: str, commit: str) -> list[str]:
    notebooks = sorted((html / "_sources").glob("*.ipynb"))
    if not notebooks:
        raise SystemExit(f"error: no executed chapters in {html / '_sources'}: build the book first")
    out.mkdir(parents=True, exist_ok=True)
    for old in out.glob("*.ipynb"):
        old.unlink()
    for path in notebooks:
        notebook = json.loads(path.read_text(encoding="utf-8"))
        notebook["cells"].insert(0, setup_cell(repository, commit))
        (out / path.name).write_text(json.dumps(notebook, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    (out / "requirements.txt").write_text(f"minippo @ git+{repository}@{commit}\nmyst-nb\n", encoding="utf-8")
    (out / "runtime.txt").write_text("python-3.11\n", encoding="utf-8")  # Binder's Python, the one CI tests
    (out / "README.md").write_text(README.format(repository=repository, commit=commit), encoding="utf-8")
    return [path.name for path in notebooks]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("html", type=Path, help="the built site, e.g. book/_build/html")
    parser.add_argument("out", type=Path, help="the folder to fill, e.g. book/_build/notebooks")
    parser.add_argument("--repository", required=True, help="https://github.com/OWNER/NAME")
    parser.add_argument("--commit", required=True, help="the full commit the site was built from")
    args = parser.parse_args(argv)
    if not re.fullmatch(r"https://github\.com/[\w.-]+/[\w.-]+", args.repository):
        print(
            f"error: --repository must look like https://github.com/OWNER/NAME, not {args.repository!r}",
            file=sys.stderr,
        )
        return 2
    if not re.fullmatch(r"[0-9a-f]{40}", args.commit):
        print(f"error: --commit must be a full 40-digit commit, not {args.commit!r}", file=sys.stderr)
        return 2
    names = write_branch(args.html, args.out, args.repository, args.commit)
    print(f"{len(names)} notebooks in {args.out}: {' '.join(names)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
