"""Execute the book's pages under several draws of their seeds, without Sphinx, and record which claim held on which.

    python tools/check_claims.py                      # every page, BOOK_SEED = 0 … 7, both CPUs
    python tools/check_claims.py --seeds 3 --pages 11-mujoco 13-language-model
    python tools/check_claims.py --env OPENBLAS_CORETYPE=Sandybridge --seeds 0 --out /tmp/sandybridge.csv

A page's sentences about a live run are glued from its cells and each value-dependent word is asserted where it is
glued: a claim is one ``assert`` statement of a page. The book refuses to build when one fails, so a build reports
only the first failure of the first draw. Here every ``assert`` of every code cell is rewritten (with ``ast``) into a
call that records whether its condition held and goes on, so one execution of a page under one seed gives the verdict
of every claim on it. Pages are read as myst-nb reads them and run by the same executor as the book's ahead-of-time
execution (``book/_ext/execute_ahead.py``), several at a time, each in a kernel of its own with ``BOOK_SEED`` set.

The record (``--out``, default ``benchmarks/results/book_claims.csv``) has one row per claim and draw: the page, the
claim's line in the page's source, its text, the seed, the environment, and ``held``, ``failed`` or ``not reached`` (a
cell before it stopped with an error), with the command and commit of each run that made it in ``book_claims.json``
beside it. ``--update`` replaces only the rows of the pages and draws it runs (a page changed since, another kernel).
The closing table prints claims × seeds, failures first. The exit status is 1 when any claim failed or any page
stopped with an error, 0 when every claim held on every draw.
"""

from __future__ import annotations

import argparse
import ast
import csv
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BOOK = ROOT / "book"
RECORD = ROOT / "benchmarks" / "results" / "book_claims.csv"
RECORDER = "__book_claim__"


def executable_pages(book: Path = BOOK) -> list[Path]:
    """The book's pages that have code cells, in the order of the file names."""
    return sorted(p for p in book.glob("*.md") if "```{code-cell}" in p.read_text(encoding="utf-8"))


class _Recorder(ast.NodeTransformer):
    """Turns each ``assert test, message`` of a page into ``__book_claim__(lambda: test, key)``: the condition is
    still evaluated where the assert stood, but a false one is recorded instead of raised, and so is a condition that
    raises (its verdict names the exception). ``claims`` lists them in the order of the source: ``key``
    (page:line), ``line`` (the line in the page's Markdown source) and ``text``."""

    def __init__(self, page: Path):
        self.page, self.lines = page.stem, page.read_text(encoding="utf-8").splitlines()
        self.claims: list[dict] = []
        self.searched_from = 0
        self.source = ""

    def cell(self, source: str) -> str:
        try:
            tree = ast.parse(source)
        except SyntaxError:  # IPython syntax: the cell keeps its asserts, which stop the page as they would
            return source
        self.source = source
        return ast.unparse(ast.fix_missing_locations(self.visit(tree)))

    def visit_Assert(self, node: ast.Assert):
        first = self.source.splitlines()[node.lineno - 1].strip()
        found = (i + 1 for i in range(self.searched_from, len(self.lines)) if self.lines[i].strip() == first)
        line = next(found, 0)
        self.searched_from = max(self.searched_from, line)
        key = f"{self.page}:{line}"
        taken = {claim["key"] for claim in self.claims}
        while key in taken:
            key += "'"
        text = " ".join(ast.get_source_segment(self.source, node).split())
        self.claims.append({"key": key, "line": line, "text": text})
        condition = ast.Lambda(
            args=ast.arguments(posonlyargs=[], args=[], kwonlyargs=[], kw_defaults=[], defaults=[]), body=node.test
        )
        call = ast.Call(ast.Name(RECORDER, ast.Load()), [condition, ast.Constant(key)], [])
        return ast.copy_location(ast.Expr(call), node)


def instrument(page: Path, notebook) -> list[dict]:
    """Rewrites the asserts of ``notebook`` (read from ``page``) in place; returns its claims (``_Recorder``)."""
    recorder = _Recorder(page)
    for cell in notebook.cells:
        if cell.cell_type == "code" and "assert" in cell.source:
            cell.source = recorder.cell(cell.source)
    return recorder.claims


def _prelude(log: Path) -> str:
    return (
        f"def {RECORDER}(condition, key, _path={str(log)!r}):\n"
        "    import json\n"
        "    try:\n"
        "        verdict = 'held' if bool(condition()) else 'failed'\n"
        "    except Exception as error:\n"
        "        verdict = 'error: ' + type(error).__name__\n"
        "    with open(_path, 'a', encoding='utf-8') as handle:\n"
        "        handle.write(json.dumps({'key': key, 'verdict': verdict}) + '\\n')\n"
    )


def read_page(page: Path):
    from myst_nb.core.read import read_myst_markdown_notebook
    from myst_parser.config.main import MdParserConfig

    return read_myst_markdown_notebook(page.read_text(encoding="utf-8"), MdParserConfig(), path=str(page))


def run_page(page: Path, seed: int, env: dict[str, str], timeout: int) -> dict:
    """Executes ``page`` under ``BOOK_SEED = seed`` (and ``env``); returns its claims, their verdicts and errors."""
    import nbformat
    from jupyter_cache.executors.utils import single_nb_execution

    os.environ.update(env)
    os.environ["BOOK_SEED"] = str(seed)
    notebook = read_page(page)
    claims = instrument(page, notebook)
    with tempfile.TemporaryDirectory() as scratch:
        log = Path(scratch) / "claims.jsonl"
        log.touch()
        notebook.cells.insert(0, nbformat.v4.new_code_cell(_prelude(log)))
        started = time.monotonic()
        single_nb_execution(notebook, cwd=str(page.parent), allow_errors=True, timeout=timeout, meta_override=True)
        seconds = time.monotonic() - started
        verdicts: dict[str, str] = {}
        for line in log.read_text(encoding="utf-8").splitlines():
            entry = json.loads(line)
            if verdicts.get(entry["key"], "held") == "held":  # a claim evaluated in a loop holds if it always held
                verdicts[entry["key"]] = entry["verdict"]
    errors = [
        f"{output.ename}: {output.evalue}".splitlines()[0][:160]
        for cell in notebook.cells
        if cell.cell_type == "code"
        for output in cell.get("outputs", [])
        if output.output_type == "error"
    ]
    for claim in claims:
        claim["verdict"] = verdicts.get(claim["key"], "not reached")
    return {"page": page.stem, "seed": seed, "claims": claims, "errors": errors, "seconds": seconds}


def seeds_from(text: str) -> list[int]:
    seeds: list[int] = []
    for part in text.split(","):
        low, _, high = part.partition("-")
        seeds += list(range(int(low), int(high or low) + 1))
    return seeds


def commit() -> str:
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True, check=True)
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--", "book", "minippo"], cwd=ROOT, capture_output=True, text=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head.stdout.strip() + ("+dirty" if dirty else "")


def table(results: list[dict], columns: list[str]) -> str:
    """Claims × draws as Markdown: ✓ held, ✗ failed, · not reached, ! its condition raised; failures first."""
    marks = {"held": "✓", "failed": "✗", "not reached": "·"}
    rows: dict[str, dict] = {}
    for result in results:
        for claim in result["claims"]:
            row = rows.setdefault(claim["key"], {"text": claim["text"], "page": result["page"], "line": claim["line"]})
            row[result["column"]] = marks.get(claim["verdict"], "!")
    ordered = sorted(
        rows.items(), key=lambda kv: (all(kv[1].get(c) == "✓" for c in columns), kv[1]["page"], kv[1]["line"])
    )
    lines = ["| claim | " + " | ".join(columns) + " |", "|---|" + "---|" * len(columns)]
    for key, row in ordered:
        text = row["text"][:70].replace("|", "\\|")
        lines.append(f"| `{key}` {text} | " + " | ".join(row.get(c, "") for c in columns) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", default="0-7", help="the draws, as BOOK_SEED values: 0-7, or 0,3,5 (default 0-7)")
    parser.add_argument("--pages", nargs="*", help="page names (e.g. 11-mujoco); default every page with code")
    parser.add_argument(
        "--env",
        nargs="*",
        default=[],
        metavar="NAME=VALUE",
        help="environment for the kernels, e.g. OPENBLAS_CORETYPE=Sandybridge",
    )
    parser.add_argument("--jobs", type=int, default=len(os.sched_getaffinity(0)), help="pages at a time")
    parser.add_argument("--timeout", type=int, default=900, help="seconds a cell may take")
    parser.add_argument("--out", type=Path, default=RECORD, help="the CSV record (default %(default)s)")
    parser.add_argument("--book", type=Path, default=BOOK, help="the book's folder (default %(default)s)")
    parser.add_argument(
        "--update", action="store_true", help="replace only these pages' and draws' rows of --out, keep the others"
    )
    args = parser.parse_args(argv)
    try:
        seeds = seeds_from(args.seeds)
        env = dict(item.split("=", 1) for item in args.env)
    except ValueError:
        parser.error("--seeds takes integers such as 0-7 or 0,3,5, and --env takes NAME=VALUE")
    pages = executable_pages(args.book)
    if args.pages:
        unknown = set(args.pages) - {p.stem for p in pages}
        if unknown:
            parser.error(f"no executable page named {', '.join(sorted(unknown))}")
        pages = [p for p in pages if p.stem in args.pages]
    label = ",".join(f"{k}={v}" for k, v in env.items())
    started_at = commit()  # the code the pages run, read before they run

    def column(seed: int) -> str:
        return f"{seed} {label}".strip()

    # the longest pages first, so that the last to finish is a short one
    jobs = sorted(((p, s) for s in seeds for p in pages), key=lambda job: -job[0].stat().st_size)
    results = []
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        futures = {pool.submit(run_page, page, seed, env, args.timeout): (page, seed) for page, seed in jobs}
        for future in as_completed(futures):
            result = future.result()
            result["column"] = column(result["seed"])
            results.append(result)
            counts = {}
            for claim in result["claims"]:
                counts[claim["verdict"]] = counts.get(claim["verdict"], 0) + 1
            status = ", ".join(f"{n} {verdict}" for verdict, n in sorted(counts.items()))
            print(
                f"{result['page']} seed {result['seed']}: {status} ({result['seconds']:.0f} s)"
                + "".join(f"\n    {e}" for e in result["errors"]),
                flush=True,
            )
    results.sort(key=lambda r: (r["page"], r["seed"]))
    header = ["page", "line", "claim", "seed", "env", "verdict"]
    rows = [
        [result["page"], claim["line"], claim["text"], result["seed"], label, claim["verdict"]]
        for result in results
        for claim in result["claims"]
    ]
    runs = []
    if args.update and args.out.exists():  # keep the other pages' and draws' rows, and the runs that made them
        ran = {(r["page"], str(r["seed"]), label) for r in results}
        with open(args.out, newline="", encoding="utf-8") as handle:
            kept = [row for row in csv.reader(handle)][1:]
        rows = [row for row in kept if (row[0], row[3], row[4]) not in ran] + rows
        about_path = args.out.with_suffix(".json")
        if about_path.exists():
            runs = json.loads(about_path.read_text(encoding="utf-8")).get("runs", [])
    rows.sort(key=lambda row: (row[4], row[0], int(row[3]), int(row[1])))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with open(args.out, "w", newline="", encoding="utf-8") as handle:
        csv.writer(handle).writerows([header, *rows])
    runs.append(
        {
            "command": "python tools/check_claims.py " + " ".join(argv if argv is not None else sys.argv[1:]),
            "commit": started_at,
            "date": time.strftime("%Y-%m-%d"),
            "machine": platform.processor() or platform.machine(),
            "pages": sorted({r["page"] for r in results}),
            "errors": {f"{r['page']} {r['seed']}": r["errors"] for r in results if r["errors"]},
        }
    )
    args.out.with_suffix(".json").write_text(json.dumps({"runs": runs}, indent=1) + "\n", encoding="utf-8")
    columns = [column(s) for s in seeds]
    print(table(results, columns))
    bad = any(c["verdict"] != "held" for r in results for c in r["claims"]) or any(r["errors"] for r in results)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
