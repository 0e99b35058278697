"""Execute the book's pages under several draws of their seeds, without Sphinx, and judge each claim by its margin.

    python tools/check_claims.py                      # every page, BOOK_SEED = 0 … 15, both CPUs
    python tools/check_claims.py --seeds 3 --pages 11-mujoco 13-language-model
    python tools/check_claims.py --env OPENBLAS_CORETYPE=Sandybridge --seeds 0 --out /tmp/sandybridge.csv
    python tools/check_claims.py --report             # judge the record's claims over its draws, running nothing

A page's sentences about a live run are glued from its cells and each value-dependent word is asserted where it is
glued: a claim is one ``assert`` statement of a page. The book refuses to build when one fails, so a build reports
only the first failure of the first draw. Here every ``assert`` of every code cell is rewritten (with ``ast``) into a
call that records whether its condition held and goes on, so one execution of a page under one seed gives the verdict
of every claim on it, and each ordered comparison in it records its slack, how far it was from flipping
(``tools/claim_runtime.py``). Pages are read as myst-nb reads them and run by the same executor as the book's
ahead-of-time execution (``book/_ext/execute_ahead.py``), several at a time, each in a kernel of its own with
``BOOK_SEED`` set.

A claim that held on the draws run may still be fitted to them. So a claim *stands* only when it held on every draw and
each comparison's slack, over the draws, keeps its median at least ``needed_spreads(n)`` standard deviations above zero
(3.85 for 16 draws; the deviation read from the draws below the median, since a slack fails on its low side only): the
one-sided 99.9 % prediction bound for a draw not yet run is then above zero (on a log scale for two sides of one sign, a
KL under a bound or a ratio over a factor; as a difference otherwise). A claim that held everywhere but is closer than
that is *thin*, and a page with a thin claim fails as one with a failed claim does. With fewer than eight draws only the
verdicts are judged.

The record (``--out``, default ``benchmarks/results/book_claims.csv``) has one row per claim and draw: the page, the
claim's line in the page's source, its text, the seed, the environment, the verdict (``held``, ``failed``, ``not
reached`` after a cell stopped with an error, or ``error: …`` when the condition raised), the margin (the tightest
comparison's slack relative to its larger side) and the slacks (JSON: comparison number → slack), with the command
and commit of each run that made it in ``book_claims.json`` beside it. ``--update`` replaces only the rows of the
pages and draws it runs (a page changed since, another kernel). The closing table prints claims × seeds, failures and
thin claims first, then a line per page with its tightest claim. The exit status is 1 when any claim failed or is
thin, or any page stopped with an error, 0 otherwise.
"""

from __future__ import annotations

import argparse
import ast
import csv
import hashlib
import json
import math
import os
import platform
import statistics
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
            args=ast.arguments(posonlyargs=[], args=[], kwonlyargs=[], kw_defaults=[], defaults=[]),
            body=_Atoms().claim(node.test),
        )
        call = ast.Call(ast.Name(RECORDER, ast.Load()), [condition, ast.Constant(key)], [])
        return ast.copy_location(ast.Expr(call), node)


_ALL_ANY = {"all": "min", "any": "max"}  # all(...), np.all(...), numpy.all(...), (...).all(); any likewise


class _Atoms:
    """Rewrites a claim's condition so that each ordered comparison of its conjunction records its slack
    (tools/claim_runtime.py): it descends through ``and``, through ``all``/``any`` (as functions of NumPy or Python, or
    as an array's methods; into a generator's element) and through chained comparisons, numbering the comparisons it
    meets in the order of the source. What lies under ``or``, ``not`` or any other call is left as written."""

    def __init__(self):
        self.atoms = 0
        self.compared: list[tuple[int, ast.Compare]] = []  # each comparison met, with the number of its first atom

    def claim(self, test: ast.expr, reduce: str = "min") -> ast.expr:
        if isinstance(test, ast.BoolOp) and isinstance(test.op, ast.And):
            return ast.BoolOp(ast.And(), [self.claim(value, reduce) for value in test.values])
        if isinstance(test, ast.Compare):
            first, self.atoms = self.atoms, self.atoms + len(test.ops)
            self.compared.append((first, test))
            ops = ast.Tuple([ast.Constant(_OP_TEXT[type(op)]) for op in test.ops], ast.Load())
            return ast.Call(
                ast.Name(COMPARE, ast.Load()),
                [ast.Constant(first), ast.Constant(reduce), ops, test.left, *test.comparators],
                [],
            )
        if isinstance(test, ast.Call) and not test.keywords:
            name = test.func.attr if isinstance(test.func, ast.Attribute) else getattr(test.func, "id", "")
            is_method = isinstance(test.func, ast.Attribute) and not test.args  # (x > 0).all()
            if name in _ALL_ANY and (len(test.args) == 1 or is_method):
                inner = _ALL_ANY[name]
                if is_method:
                    receiver = self.claim(test.func.value, inner)
                    return ast.Call(ast.Attribute(receiver, name, ast.Load()), [], [])
                argument = test.args[0]
                if isinstance(argument, (ast.GeneratorExp, ast.ListComp)):
                    argument = type(argument)(self.claim(argument.elt, inner), argument.generators)
                else:
                    argument = self.claim(argument, inner)
                return ast.Call(test.func, [argument], [])
        return test


def distance_atoms(claim: str) -> set[int]:
    """The atoms of ``claim`` (an assert's text, numbered as ``_Atoms`` numbers them) that bound an error's size by a
    tolerance: the side that must be the smaller holds ``abs`` (Python's, or ``np.abs``/``numpy.abs``, perhaps under a
    max or a mean) and the other side holds none. Such a size is near 0 by design, where the log scale stretches a small
    error into a large slack and a typical one into risk; it is judged as a difference (``judge``)."""
    try:
        test = ast.parse(claim).body[0]
    except (SyntaxError, IndexError):
        return set()
    if not isinstance(test, ast.Assert):
        return set()

    def has_abs(node: ast.expr) -> bool:
        for sub in ast.walk(node):
            if isinstance(sub, ast.Call):
                name = sub.func.attr if isinstance(sub.func, ast.Attribute) else getattr(sub.func, "id", "")
                if name in ("abs", "absolute"):
                    return True
        return False

    found: set[int] = set()
    numbering = _Atoms()  # numbers the comparisons as the recorded claim's were numbered
    numbering.claim(test.test)
    for first, node in numbering.compared:
        sides = [node.left, *node.comparators]
        for k, op in enumerate(node.ops):
            below = isinstance(op, (ast.Lt, ast.LtE))
            small, large = (sides[k], sides[k + 1]) if below else (sides[k + 1], sides[k])
            if isinstance(op, (ast.Lt, ast.LtE, ast.Gt, ast.GtE)) and has_abs(small) and not has_abs(large):
                found.add(first + k)
    return found


COMPARE = "__claim_compare__"
_OP_TEXT = {
    ast.Lt: "<",
    ast.LtE: "<=",
    ast.Gt: ">",
    ast.GtE: ">=",
    ast.Eq: "==",
    ast.NotEq: "!=",
    ast.Is: "is",
    ast.IsNot: "is not",
    ast.In: "in",
    ast.NotIn: "not in",
}


def instrument(page: Path, notebook) -> list[dict]:
    """Rewrites the asserts of ``notebook`` (read from ``page``) in place; returns its claims (``_Recorder``)."""
    recorder = _Recorder(page)
    for cell in notebook.cells:
        if cell.cell_type == "code" and "assert" in cell.source:
            cell.source = recorder.cell(cell.source)
    return recorder.claims


def _prelude(log: Path) -> str:
    """The first cell of an instrumented page: tools/claim_runtime.py, writing to ``log``."""
    runtime = (Path(__file__).resolve().parent / "claim_runtime.py").read_text(encoding="utf-8")
    return runtime + f"\nCLAIMS_LOG = {str(log)!r}\n__claims_watch__({str(ROOT)!r})\n"


def _combine(entries: list[dict]) -> dict:
    """One claim's evaluations on one draw (several when a loop evaluates it) as one: it holds if it always held, and
    each atom keeps its smallest slack, in both of its units (``tools/claim_runtime.py``)."""
    verdict = next((e["verdict"] for e in entries if e["verdict"] != "held"), "held")
    slacks: dict[str, list] = {}
    for entry in entries:
        for atom, pair in entry.get("slacks", {}).items():
            known = slacks.setdefault(atom, pair)
            slacks[atom] = [_smaller(known[0], pair[0]), _smaller(known[1], pair[1])]
    margins = [e["margin"] for e in entries if e.get("margin") is not None]
    return {"verdict": verdict, "slacks": slacks, "margin": min(margins) if margins else None}


def _smaller(a, b):
    return None if a is None or b is None else min(a, b)


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
        notebook.cells.append(nbformat.v4.new_code_cell(f"__claims_files__({str(ROOT)!r});"))
        started = time.monotonic()
        single_nb_execution(notebook, cwd=str(page.parent), allow_errors=True, timeout=timeout, meta_override=True)
        seconds = time.monotonic() - started
        evaluations: dict[str, list[dict]] = {}
        files: list[str] = []
        for line in log.read_text(encoding="utf-8").splitlines():
            entry = json.loads(line)
            if "files" in entry:
                files = entry["files"]
            else:
                evaluations.setdefault(entry["key"], []).append(entry)
    errors = [
        f"{output.ename}: {output.evalue}".splitlines()[0][:160]
        for cell in notebook.cells
        if cell.cell_type == "code"
        for output in cell.get("outputs", [])
        if output.output_type == "error"
    ]
    for claim in claims:
        if claim["key"] in evaluations:
            claim.update(_combine(evaluations[claim["key"]]))
        else:
            claim.update(verdict="not reached", slacks={}, margin=None)
    code = code_of(page, files)
    return {
        "page": page.stem,
        "seed": seed,
        "claims": claims,
        "errors": errors,
        "seconds": seconds,
        "code": code,
        "files": files,
    }


def code_of(page: Path, files: list[str]) -> str:
    """A fingerprint of what a page's execution depended on: its code cells and the course's files it read or imported
    (``files``, relative to the repository, as its kernel noted them). Rows with the same fingerprint came from the
    same code and data, so a page whose prose moved its claims to other lines keeps its rows (``--relocate``) until
    its code, or a file it reads, changes."""
    digest = hashlib.sha256()
    for cell in read_page(page).cells:
        if cell.cell_type == "code":
            digest.update(cell.source.encode("utf-8") + b"\0")
    for name in sorted(files):
        path = ROOT / name
        digest.update(name.encode() + b"\0" + (path.read_bytes() if path.is_file() else b"(gone)") + b"\0")
    return digest.hexdigest()[:12]


def relocate(rows: list[dict], book: Path, depends: dict[str, list[str]]) -> tuple[list[dict], list[str]]:
    """Gives each row of a page whose fingerprint is today's the line its claim now has (claims matched by text, in
    order); returns the rows and the pages whose code has changed since their rows were made (to be run again).
    ``depends`` maps each page to the files its last run read."""
    stale, current = set(), {}
    for page in {row["page"] for row in rows}:
        path = book / f"{page}.md"
        if (
            not path.exists()
            or page not in depends
            or any(row["code"] != code_of(path, depends[page]) for row in rows if row["page"] == page)
        ):
            stale.add(page)
            continue
        claims = instrument(path, read_page(path))
        current[page] = [(c["text"], c["line"]) for c in claims]
    for page, claims in current.items():
        for seed in {row["seed"] for row in rows if row["page"] == page}:
            mine = sorted(
                (row for row in rows if row["page"] == page and row["seed"] == seed), key=lambda r: int(r["line"])
            )
            if [row["claim"] for row in mine] != [text for text, _ in claims]:
                stale.add(page)
                break
            for row, (_, line) in zip(mine, claims):
                row["line"] = line
    return rows, sorted(stale)


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


FIELDS = ["page", "line", "claim", "seed", "env", "verdict", "margin", "slacks", "code"]
FEWEST_DRAWS = 8  # below this many draws a claim's spread is not judged, only its verdicts
COVERAGE = 0.999  # the one-sided prediction interval a claim's slack must clear on a draw not yet run


def needed_spreads(draws: int) -> float:
    """How many standard deviations of its spread a slack's mean over ``draws`` draws must be above 0: the one-sided
    99.9 % prediction bound for the next draw, mean − t(0.999, n − 1) · s · √(1 + 1/n), is then above 0 (3.85 for 16
    draws, 5.07 for 8). Under a normal spread, a claim just at the bound fails about one fresh draw in a thousand."""
    from scipy.stats import t

    return float(t.ppf(COVERAGE, draws - 1) * math.sqrt(1 + 1 / draws))


def downside_spread(values: list[float]) -> float:
    """The standard deviation that the draws below the median imply: √(2 Σ_{x < median} (x − median)² / (n − 1)). A
    slack fails on its low side only, so a draw far above the rest (a bound met by a factor of a hundred once) must
    not pass for risk, nor pull the centre up; for a spread symmetric about its median this is the ordinary standard
    deviation."""
    if len(values) < 2:
        return 0.0
    centre = statistics.median(values)
    return math.sqrt(2 * sum((x - centre) ** 2 for x in values if x < centre) / (len(values) - 1))


def judge(rows: list[dict]) -> list[dict]:
    """Each claim (page, line, text, env) over the draws in ``rows``: ``stands`` when it held on every draw and each
    of its atoms' slack clears ``needed_spreads`` (an atom whose slack never moves clears it by holding), ``thin``
    when it held on every draw but some atom's spread leaves too little room, ``failed`` when some draw failed it,
    and ``held`` when it held on fewer than FEWEST_DRAWS draws, too few to judge a spread. ``spreads`` is the
    smallest over the atoms of the slack's median over its downside spread (``downside_spread``; None: no atom
    moved, or none is ordered). An atom whose two sides kept one sign on every draw is judged on the log scale,
    where a threshold is a factor away and a ratio's long right tail does not pass for spread; any other on the
    difference, and so is an error's size against a tolerance (``distance_atoms``). Which scale is decided by the
    signs and the claim's text alone, before any slack is looked at."""
    claims: dict[tuple, dict] = {}
    for row in rows:
        key = (row["page"], int(row["line"]), row["claim"], row["env"])
        claim = claims.setdefault(
            key,
            {
                "page": row["page"],
                "line": int(row["line"]),
                "claim": row["claim"],
                "env": row["env"],
                "verdicts": {},
                "slacks": {},
                "margins": [],
            },
        )
        claim["verdicts"][int(row["seed"])] = row["verdict"]
        slacks = row["slacks"] if isinstance(row["slacks"], dict) else json.loads(row["slacks"] or "{}")
        for atom, pair in slacks.items():
            claim["slacks"].setdefault(atom, []).append(pair if isinstance(pair, list) else [pair, None])
        if row["margin"] not in (None, ""):
            claim["margins"].append(float(row["margin"]))
    judged = []
    for claim in claims.values():
        draws = len(claim["verdicts"])
        held = all(v == "held" for v in claim["verdicts"].values())
        spreads = None
        distances = distance_atoms(claim["claim"])
        for atom, pairs in claim["slacks"].items():
            if len(pairs) < draws:
                continue  # not evaluated on some draw: the verdicts say it
            # on a log scale when both sides kept one sign on every draw (a factor away), else as differences; an
            # error's size against a tolerance always as a difference
            logged = all(pair[1] is not None for pair in pairs) and int(atom) not in distances
            values = [pair[1] if logged else pair[0] for pair in pairs]
            if any(v is None for v in values):
                continue
            centre, sd = statistics.median(values), downside_spread(values)
            z = math.inf if sd == 0 else centre / sd
            spreads = z if spreads is None else min(spreads, z)
        if not held:
            status = "failed"
        elif draws < FEWEST_DRAWS:
            status = "held"
        else:
            status = "thin" if spreads is not None and spreads < needed_spreads(draws) else "stands"
        judged.append(
            {
                **claim,
                "draws": draws,
                "status": status,
                "spreads": None if spreads == math.inf else spreads,
                "smallest_margin": min(claim["margins"]) if claim["margins"] else None,
            }
        )
    return sorted(judged, key=lambda c: (c["status"] in ("stands", "held"), c["page"], c["line"]))


def table(judged: list[dict]) -> str:
    """Claims × draws as Markdown, failures and thin margins first: ✓ held, ✗ failed, · not reached, ! its condition
    raised; then the smallest relative margin over the draws, the slack's mean in standard deviations (∞: it never
    moved; –: no ordered comparison) and the claim's status."""
    marks = {"held": "✓", "failed": "✗", "not reached": "·"}
    seeds = sorted({seed for claim in judged for seed in claim["verdicts"]})
    lines = [
        "| claim | " + " | ".join(map(str, seeds)) + " | margin | mean/sd | status |",
        "|---|" + "---|" * (len(seeds) + 3),
    ]
    for c in judged:
        text = c["claim"][:70].replace("|", "\\|")
        cells = [marks.get(c["verdicts"].get(seed, ""), "!" if seed in c["verdicts"] else "") for seed in seeds]
        margin = "–" if c["smallest_margin"] is None else f"{c['smallest_margin']:.3g}"
        spreads = "–" if not c["slacks"] else ("∞" if c["spreads"] is None else f"{c['spreads']:.3g}")
        lines.append(
            f"| `{c['page']}:{c['line']}` {text} | " + " | ".join(cells) + f" | {margin} | {spreads} | {c['status']} |"
        )
    return "\n".join(lines)


def summary(judged: list[dict]) -> str:
    """A line per page: its claims by status, and its tightest claim in spreads; then the rule."""
    lines = []
    for page in sorted({c["page"] for c in judged}):
        mine = [c for c in judged if c["page"] == page]
        counts = {s: sum(c["status"] == s for c in mine) for s in ("stands", "held", "thin", "failed")}
        finite = [c for c in mine if c["spreads"] is not None]
        tightest = min(finite, key=lambda c: c["spreads"]) if finite else None
        lines.append(
            f"{page}: "
            + ", ".join(f"{n} {s}" for s, n in counts.items() if n)
            + (f"; tightest {tightest['spreads']:.2f} sd (line {tightest['line']})" if tightest else "")
        )
    draws = max((c["draws"] for c in judged), default=0)
    if draws >= FEWEST_DRAWS:
        lines.append(f"rule: held on all {draws} draws and median slack >= {needed_spreads(draws):.2f} sd")
    return "\n".join(lines)


def depends_of(record: Path) -> dict[str, list[str]]:
    """Each page's files as its latest run in ``record``'s JSON noted them."""
    about = record.with_suffix(".json")
    depends: dict[str, list[str]] = {}
    if about.exists():
        for run in json.loads(about.read_text(encoding="utf-8")).get("runs", []):
            depends.update(run.get("depends", {}))
    return depends


def _short(value):
    return None if value is None else float(f"{value:.6g}")


def read_record(path: Path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    for row in rows:  # a record from before slacks were kept
        for field in ("margin", "slacks", "code"):
            row[field] = row.get(field) or ""
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", default="0-15", help="the draws, as BOOK_SEED values: 0-15, or 0,3,5 (default 0-15)")
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
    parser.add_argument(
        "--report", action="store_true", help="run nothing: judge the claims of --out (of --pages) over its draws"
    )
    parser.add_argument(
        "--relocate",
        action="store_true",
        help="run nothing: move --out's rows to their claims' current lines where a page's code is unchanged, and "
        "name the pages whose code changed (to run again)",
    )
    args = parser.parse_args(argv)
    try:
        seeds = seeds_from(args.seeds)
        env = dict(item.split("=", 1) for item in args.env)
    except ValueError:
        parser.error("--seeds takes integers such as 0-15 or 0,3,5, and --env takes NAME=VALUE")
    if args.relocate:
        if not args.out.exists():
            parser.error(f"no record at {args.out}")
        rows, stale = relocate(read_record(args.out), args.book, depends_of(args.out))
        rows.sort(key=lambda row: (row["env"], row["page"], int(row["seed"]), int(row["line"])))
        with open(args.out, "w", newline="", encoding="utf-8") as handle:
            writer = csv.DictWriter(handle, FIELDS)
            writer.writeheader()
            writer.writerows(rows)
        print("code changed since their rows were made: " + (" ".join(stale) if stale else "none"))
        return 1 if stale else 0
    if args.report:
        if not args.out.exists():
            parser.error(f"no record at {args.out}")
        rows = [r for r in read_record(args.out) if not args.pages or r["page"] in args.pages]
        judged = judge(rows)
        print(table(judged))
        print(summary(judged))
        return 0 if all(c["status"] in ("stands", "held") for c in judged) else 1
    pages = executable_pages(args.book)
    if args.pages:
        unknown = set(args.pages) - {p.stem for p in pages}
        if unknown:
            parser.error(f"no executable page named {', '.join(sorted(unknown))}")
        pages = [p for p in pages if p.stem in args.pages]
    label = ",".join(f"{k}={v}" for k, v in env.items())
    started_at = commit()  # the code the pages run, read before they run

    # the longest pages first, so that the last to finish is a short one
    jobs = sorted(((p, s) for s in seeds for p in pages), key=lambda job: -job[0].stat().st_size)
    results = []
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        futures = {pool.submit(run_page, page, seed, env, args.timeout): (page, seed) for page, seed in jobs}
        for future in as_completed(futures):
            result = future.result()
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
    rows = [
        {
            "page": result["page"],
            "line": claim["line"],
            "claim": claim["text"],
            "seed": result["seed"],
            "env": label,
            "verdict": claim["verdict"],
            "margin": "" if claim["margin"] is None else f"{claim['margin']:.6g}",
            "slacks": json.dumps({a: [_short(v) for v in pair] for a, pair in claim["slacks"].items()}),
            "code": result["code"],
        }
        for result in results
        for claim in result["claims"]
    ]
    runs = []
    if args.update and args.out.exists():  # keep the other pages' and draws' rows, and the runs that made them
        ran = {(r["page"], str(r["seed"]), label) for r in results}
        kept = [row for row in read_record(args.out) if (row["page"], row["seed"], row["env"]) not in ran]
        rows = kept + rows
        about_path = args.out.with_suffix(".json")
        if about_path.exists():
            runs = json.loads(about_path.read_text(encoding="utf-8")).get("runs", [])
    rows.sort(key=lambda row: (row["env"], row["page"], int(row["seed"]), int(row["line"])))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with open(args.out, "w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, FIELDS)
        writer.writeheader()
        writer.writerows(rows)
    runs.append(
        {
            "command": "python tools/check_claims.py " + " ".join(argv if argv is not None else sys.argv[1:]),
            "commit": started_at,
            "date": time.strftime("%Y-%m-%d"),
            "machine": platform.processor() or platform.machine(),
            "pages": sorted({r["page"] for r in results}),
            "seeds": seeds,
            "depends": {r["page"]: r["files"] for r in results},
            "errors": {f"{r['page']} {r['seed']}": r["errors"] for r in results if r["errors"]},
        }
    )
    args.out.with_suffix(".json").write_text(json.dumps({"runs": runs}, indent=1) + "\n", encoding="utf-8")
    ran_rows = [
        row
        for row in rows
        if (row["page"], int(row["seed"]), row["env"]) in {(r["page"], r["seed"], label) for r in results}
    ]
    judged = judge(ran_rows)
    print(table(judged))
    print(summary(judged))
    bad = any(c["status"] not in ("stands", "held") for c in judged) or any(r["errors"] for r in results)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
