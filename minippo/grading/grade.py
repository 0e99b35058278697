"""``minippo grade [CHAPTER] [--solutions] [--verbose] [--class FOLDER --csv FILE]``: run the grading tests and print
a scoreboard, chapter by chapter (or one line per student and chapter for a whole class).

The tests (tests/exercises/test_chNN_*.py) run in a child pytest process with a time limit per test, so code that
raises, returns NaN or never returns fails its tests instead of stopping the grader. Each result is written to a
log as soon as it is known (this module is also the pytest plugin that writes it), so even a run that has to be
stopped still reports what finished; if student code kills the test process itself, the test that was running is
failed and the rest run in a new process.

Which code is graded: exercises/ by default; solutions/ with --solutions; a folder with --submission FOLDER or the
environment variable MINIPPO_IMPL (``exercises``, ``solutions``, or a folder holding chNN_*.py modules). With --class,
every sub-folder of FOLDER is one student's folder of chNN_*.py modules, graded in its own process.

A student's code never runs in the test process: the tests call it through a worker process (minippo.grading.sandbox and
minippo.grading.worker) that cannot see the repository, the other students or this log, under CPU, memory, file-size and
process limits. Every record of the log is signed with a key only this process and its tests know, so a record the tests
did not write is ignored (and reported). What the worker or the source scan saw a submission do that an instructor
should know of (importing the reference, using minippo's own version of the exercise, reaching for the grader's files)
goes to the integrity column; how far the worker was isolated, to the isolation column.
``--gradescope FILE`` writes the results in Gradescope's results.json format; ``--autograder-zip`` builds the zip
Gradescope runs.

The chapters are found, not listed: a chapter is graded when tests/exercises/test_chNN_<topic>.py exists, and its
book name (``minippo grade the-min``) comes from book/NN-<name>.md. A new chapter needs only those two files.
"""

from __future__ import annotations

import csv
import hashlib
import hmac
import io
import json
import os
import re
import secrets
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
TESTS = ROOT / "tests" / "exercises"
BOOK = ROOT / "book"
IMPL_VARIABLE = "MINIPPO_IMPL"
LOG_VARIABLE = "MINIPPO_GRADE_LOG"
STOP_VARIABLE = "MINIPPO_GRADE_STOP_AT_FIRST_FAILURE"
KEY_VARIABLE = "MINIPPO_GRADE_KEY"  # signs every record of the log, so that a record the tests did not write is ignored
HIDE_VARIABLE = "MINIPPO_GRADE_HIDE"
TIME_FACTOR_VARIABLE = "MINIPPO_GRADE_TIME_FACTOR"
WORKER_TIME_FACTOR = 2  # the per-test time limits, for code graded through a worker process
RUN_LIMIT_S = 1800  # the whole run; each test has its own, much shorter limit
RESTARTS = 5  # how many times a run whose test process died goes on with the tests that had not run
# the book's chapter names, so "minippo grade the-min" works as well as "minippo grade 6"; book_names() adds any
# book/NN-<name>.md page that is not here
BOOK_NAMES = {
    1: "network",
    2: "distributions",
    3: "vanilla-pg",
    4: "cpi",
    5: "clipping",
    6: "the-min",
    7: "advantages",
    8: "shared-network",
    9: "kl-penalty",
    10: "everything-together",
    11: "mujoco",
    12: "pixels",
    13: "language-model",
}


@dataclass
class Result:
    nodeid: str
    outcome: str  # passed | failed | skipped
    message: str = ""

    @property
    def chapter(self) -> int:
        return chapter_of_nodeid(self.nodeid)


def chapter_files() -> dict[int, Path]:
    """{chapter number: its grading test file}."""
    files = {}
    for path in sorted(TESTS.glob("test_ch[0-9][0-9]_*.py")):
        files[int(path.name[7:9])] = path
    return files


def book_names() -> dict[int, str]:
    """{chapter number: the book page's name}, from book/NN-<name>.md, with BOOK_NAMES for what the book lacks."""
    names = dict(BOOK_NAMES)
    for page in BOOK.glob("[0-9][0-9]-*.md"):
        names[int(page.name[:2])] = page.stem[3:]
    return names


def chapter_title(number: int) -> str:
    path = chapter_files().get(number)
    topic = path.stem[10:] if path else book_names().get(number, "")
    return f"ch{number:02d} {topic.replace('_', ' ')}"


def chapter_of_nodeid(nodeid: str) -> int:
    match = re.search(r"test_ch(\d\d)_", nodeid)
    return int(match.group(1)) if match else 0


def resolve_chapter(text: str) -> int | None:
    """'5', '05', 'ch05', 'clipping', 'ch05_clipping', 'the-min' -> 5; None if no chapter has that name."""
    key = text.strip().lower().replace("-", "_").removesuffix(".py")
    match = re.fullmatch(r"(?:ch(?:apter)?)?_?0*(\d+)(?:_\w*)?", key)
    if match:
        return int(match.group(1))
    for number, path in chapter_files().items():
        if key in (path.stem[10:], path.stem[5:]):
            return number
    for number, name in book_names().items():
        if key == name.replace("-", "_"):
            return number
    return None


# the pytest plugin: loaded in the child process with ``-p minippo.grading.grade``

_variant_of_test: dict[str, str] = {}
_rejected_variants: set[str] = set()


_KEY = os.environ.pop(KEY_VARIABLE, "")  # read once, when pytest loads this plugin, and kept out of the environment


def _signature(text: str, key: str) -> str:
    return hmac.new(key.encode(), text.encode(), hashlib.sha256).hexdigest()


def _log(record: dict) -> None:
    path = os.environ.get(LOG_VARIABLE)
    if path:
        text = json.dumps(record)
        with open(path, "a", encoding="utf-8") as handle:
            handle.write(json.dumps({"record": text, "mac": _signature(text, _KEY)}) + "\n")


def log_integrity(chapter: str, note: str | None, isolation: str | None = None) -> None:
    """Record what a submission was seen doing that the instructor should know of (``note``), or how its worker was
    isolated; both go to the CSV's integrity and isolation columns."""
    _log({"integrity": chapter, "note": note, "isolation": isolation})


def pytest_collection_modifyitems(items) -> None:
    """Under MINIPPO_GRADE_TIME_FACTOR, every test's time limit times that factor: a student's code runs in a worker
    process, and each of its calls costs a round trip there and back (a test may make a thousand)."""
    factor = float(os.environ.get(TIME_FACTOR_VARIABLE) or 1)
    if factor == 1:
        return
    import pytest

    for item in items:
        marker = item.get_closest_marker("timeout")
        if marker is not None and marker.args:
            item.add_marker(pytest.mark.timeout(float(marker.args[0]) * factor))


def pytest_collection_finish(session) -> None:
    _log({"collected": [item.nodeid for item in session.items]})


def pytest_runtest_logstart(nodeid, location) -> None:
    _log({"started": nodeid})


def pytest_collectreport(report) -> None:
    if report.failed:
        _log(
            {
                "nodeid": report.nodeid,
                "outcome": "failed",
                "message": "the test file itself could not be loaded: " + plain_message(report),
            }
        )


def pytest_runtest_setup(item) -> None:
    """With MINIPPO_GRADE_STOP_AT_FIRST_FAILURE, a wrong variant that has failed once skips the rest of its tests."""
    callspec = getattr(item, "callspec", None)
    if not (os.environ.get(STOP_VARIABLE) and callspec and "student" in callspec.params):
        return
    variant = f"{item.module.__name__}:{callspec.params['student']}"
    _variant_of_test[item.nodeid] = variant
    if variant in _rejected_variants:
        import pytest

        pytest.skip("already rejected by an earlier test")


def pytest_runtest_logreport(report) -> None:
    if report.failed and report.nodeid in _variant_of_test:
        _rejected_variants.add(_variant_of_test[report.nodeid])
    if report.when == "call" or report.outcome != "passed":
        message = "" if report.passed else plain_message(report)
        _log({"nodeid": report.nodeid, "outcome": report.outcome, "when": report.when, "message": message})


def plain_message(report) -> str:
    """The first line of why a test failed, without the exception class when the class says nothing to a student."""
    if report.skipped and isinstance(report.longrepr, tuple):
        return str(report.longrepr[2]).removeprefix("Skipped: ")
    crash = getattr(report.longrepr, "reprcrash", None)
    text = crash.message if crash is not None else str(report.longrepr)
    first = text.strip().splitlines()[0] if text.strip() else "failed"
    timeout = re.match(r"Failed: Timeout \(?>?([\d.]+)s\)?", first)
    if timeout:
        return f"took longer than {float(timeout.group(1)):g} s and was stopped (an endless loop?)"
    for prefix in ("AssertionError: ", "_harness.StudentError: ", "StudentError: ", "Failed: "):
        if first.startswith(prefix):
            return first[len(prefix) :]
    if first == "AssertionError":
        return "a check failed"
    return f"the test crashed: {first}"


# running the tests and printing the scoreboard


def run_tests(
    impl: str,
    files,
    stop_at_first_failure: bool = False,
    limit_s: float = RUN_LIMIT_S,
    extra_args=(),
    integrity: dict | None = None,
    hide=(),
):
    """Run pytest on ``files`` against ``impl`` in a child process; return (collected node ids, results, note).
    ``integrity``, if given, is filled with {chapter number: [notes]} and {"isolation": how the worker was kept apart}.
    ``hide``: folders the student's worker must not see besides the repository (the class folder).

    If the child process dies (student code that calls os._exit, crashes the interpreter or is killed), the test it
    was running fails with that reason and the tests that had not run yet run in a new child, so one crash costs one
    test. The whole run, restarts included, stops after ``limit_s`` seconds."""
    env = dict(os.environ)
    env[IMPL_VARIABLE] = impl
    if stop_at_first_failure:
        env[STOP_VARIABLE] = "1"
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env.setdefault(name, "1")  # small matrices: extra BLAS threads only spin
    key = secrets.token_hex(32)
    env[KEY_VARIABLE] = key
    if hide:
        env[HIDE_VARIABLE] = os.pathsep.join(str(p) for p in hide)
    if impl not in ("solutions", "wrong", "right") and not env.get(TIME_FACTOR_VARIABLE):
        env[TIME_FACTOR_VARIABLE] = str(WORKER_TIME_FACTOR)
    integrity = integrity if integrity is not None else {}
    collected, results, note = [], {}, ""
    targets = [str(f) for f in files]
    deadline = time.monotonic() + limit_s
    with tempfile.TemporaryDirectory(prefix="minippo-grade-") as folder:
        for attempt in range(RESTARTS + 1):
            log = Path(folder) / f"results-{attempt}.jsonl"
            env[LOG_VARIABLE] = str(log)
            command = [
                sys.executable, "-m", "pytest", *targets, "-p", "minippo.grading.grade", "-p", "no:cacheprovider",
                "-q", "--no-header", "-o", "addopts=", "--continue-on-collection-errors", "--tb=line", *extra_args,
            ]  # fmt: skip
            returncode = None
            try:
                left = max(1.0, deadline - time.monotonic())
                finished = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, timeout=left)
                returncode = finished.returncode
                if returncode not in (0, 1):
                    tail = (finished.stdout + finished.stderr).strip().splitlines()[-3:]
                    note = f"pytest stopped with exit code {returncode}: {' / '.join(tail)}"
            except subprocess.TimeoutExpired:
                note = f"the run was stopped after {limit_s:g} s"
            running = _read_log(log, results, key, integrity)
            if attempt == 0:
                collected = running.pop("collected", [])
            missing = [nodeid for nodeid in collected if nodeid not in results]
            started = running.get("started")
            if returncode in (0, 1) or returncode is None or not missing or started not in missing:
                break
            # the child died inside ``started``: fail that test, run the rest afresh
            results[started] = Result(
                started, "failed", f"the test process died while running it ({_death(returncode)})"
            )
            targets = [nodeid for nodeid in missing if nodeid != started]
            note = ""
            if not targets:
                break
    for nodeid in collected:
        if nodeid not in results:
            results[nodeid] = Result(nodeid, "failed", f"did not finish ({note or 'no result'})")
    ordered = [results[nodeid] for nodeid in collected] + [r for n, r in results.items() if n not in set(collected)]
    return collected, ordered, note


def _read_log(log: Path, results: dict, key: str, integrity: dict) -> dict:
    """Read one child's log into ``results`` and ``integrity``; return {"collected": [...], "started": the last test
    begun}. A line that is not a record signed with ``key`` (which only the grader and its tests know) is ignored and
    counted in the integrity notes."""
    found = {}
    if not log.exists():
        return found
    forged = 0
    for line in log.read_text(encoding="utf-8", errors="replace").splitlines():
        try:
            signed = json.loads(line)
            text = signed["record"]
            if not hmac.compare_digest(str(signed["mac"]), _signature(text, key)):
                raise ValueError
            record = json.loads(text)
        except (ValueError, KeyError, TypeError):
            forged += 1
            continue
        if "integrity" in record:
            number = chapter_of_nodeid(f"test_{record['integrity']}.py")
            if record.get("note"):
                notes = integrity.setdefault(number, [])
                if record["note"] not in notes:
                    notes.append(record["note"])
            if record.get("isolation"):
                integrity["isolation"] = record["isolation"]
            continue
        if "collected" in record:
            found["collected"] = record["collected"]
            continue
        if "started" in record:
            found["started"] = record["started"]
            continue
        old = results.get(record["nodeid"])
        if old is None or old.outcome == "passed":  # a failing teardown spoils a passed call
            results[record["nodeid"]] = Result(record["nodeid"], record["outcome"], record["message"])
    if forged:
        integrity.setdefault("log", []).append(f"{forged} line(s) of the grader's log were not written by the tests")
    return found


def _death(returncode: int) -> str:
    if returncode < 0:
        try:
            return f"killed by signal {signal.Signals(-returncode).name}"
        except ValueError:
            return f"killed by signal {-returncode}"
    return f"it exited with code {returncode}: does the code call sys.exit or os._exit?"


def scoreboard(results, numbers) -> tuple[list[str], bool]:
    lines, all_passed = [], True
    width = max(len(chapter_title(n)) for n in numbers)
    total_passed = total = 0
    for number in numbers:
        mine = [r for r in results if r.chapter == number]
        passed = sum(r.outcome == "passed" for r in mine)
        total_passed, total = total_passed + passed, total + len(mine)
        first_failure = next((r for r in mine if r.outcome != "passed"), None)
        if not mine:
            comment = "no tests ran"
        elif first_failure is None:
            comment = "all passed"
        else:
            comment = first_failure.message
        if not mine or first_failure is not None:
            all_passed = False
        score = f"{passed}/{len(mine)}"
        lines.append(f"{chapter_title(number):<{width}}  {score:>7}  {comment}")
    lines.append(f"{'total':<{width}}  {f'{total_passed}/{total}':>7}")
    return lines, all_passed and total > 0


def failures_in_detail(results, numbers) -> list[str]:
    """Every failing test of the chapters, each with its message, for ``--verbose``."""
    lines = []
    for number in numbers:
        failing = [r for r in results if r.chapter == number and r.outcome != "passed"]
        if failing:
            lines.append(f"{chapter_title(number)}: {len(failing)} failing")
            lines.extend(f"  {r.nodeid.split('::', 1)[-1]}: {r.message}" for r in failing)
    return lines


def _chapters(chapter) -> list[int]:
    """The chapter numbers to grade; raises ValueError with the one-line reason for a bad name."""
    files = chapter_files()
    if not files:
        raise ValueError(f"no grading tests found in {TESTS} (grade from the course's repository)")
    if chapter is None:
        return sorted(files)
    number = resolve_chapter(str(chapter))
    if number is None or number not in files:
        known = ", ".join(f"{n} ({chapter_title(n)[5:]})" for n in sorted(files))
        why = f"chapter {number} has no exercise" if number in book_names() else f"unknown chapter '{chapter}'"
        raise ValueError(f"{why}; chapters with exercises: {known}")
    return [number]


def _check_pytest_timeout() -> bool:
    try:
        import pytest_timeout  # noqa: F401 - the per-test time limits need it
    except ImportError:
        print("minippo: error: grading needs pytest and pytest-timeout: pip install -e '.[grade]'", file=sys.stderr)
        return False
    return True


def integrity_notes(integrity: dict, number: int) -> list[str]:
    """What the instructor should know of one chapter's submission: its own notes and the log's."""
    return integrity.get(number, []) + integrity.get("log", [])


def find_submission(folder: Path) -> Path:
    """The folder that holds a submission's chNN_*.py modules: ``folder`` itself, or the sub-folder with the most of
    them (a submission uploaded as a zip of its folder)."""

    def count(path: Path) -> int:
        return len(list(path.glob("ch[0-9][0-9]_*.py")))

    candidates = [folder] + sorted(p for p in folder.rglob("*") if p.is_dir() and not p.name.startswith((".", "_")))
    return max(candidates, key=count) if count(folder) == 0 else folder


def grade(
    chapter: str | None = None,
    solutions: bool = False,
    impl: str | None = None,
    out=None,
    verbose: bool = False,
    gradescope: str | None = None,
) -> int:
    """Grade one chapter (or all), print the scoreboard; 0 if every test passed, 1 if not, 2 for bad input.
    ``verbose`` lists every failing test with its message below the scoreboard; ``gradescope`` also writes the
    results to that file in Gradescope's results.json format."""
    out = out or sys.stdout
    started = time.monotonic()
    try:
        numbers = _chapters(chapter)
    except ValueError as error:
        print(f"minippo: error: {error}", file=sys.stderr)
        return 2
    if gradescope is not None and not Path(gradescope).expanduser().resolve().parent.is_dir():
        print(f"minippo: error: no folder for the results file {gradescope}", file=sys.stderr)
        return 2
    if gradescope is not None and Path(gradescope).expanduser().is_dir():
        print(f"minippo: error: {gradescope} is a folder; --gradescope takes the results file's name", file=sys.stderr)
        return 2
    if not _check_pytest_timeout():
        return 2
    files = chapter_files()
    if impl is None:
        impl = "solutions" if solutions else os.environ.get(IMPL_VARIABLE, "").strip() or "exercises"
    if impl not in ("exercises", "solutions", "wrong", "right"):
        if not Path(impl).expanduser().is_dir():
            print(f"minippo: error: no submission folder {impl}", file=sys.stderr)
            return 2
        impl = str(find_submission(Path(impl).expanduser().resolve()))
    where = f"{impl}/" if impl in ("exercises", "solutions") else impl
    print(
        f"Grading {where} (chapter {', '.join(map(str, numbers))}); the time limit is per test.", file=out, flush=True
    )
    integrity: dict = {}
    hide = [Path(gradescope).expanduser().resolve()] if gradescope is not None else []
    _, results, note = run_tests(impl, [files[n] for n in numbers], integrity=integrity, hide=hide)
    lines, all_passed = scoreboard(results, numbers)
    print("\n".join(lines), file=out)
    if note:
        print(f"note: {note}", file=out)
    for number in numbers:
        for text in integrity_notes(integrity, number):
            print(f"integrity: {chapter_title(number)}: {text}", file=out)
    if gradescope is not None:
        report = gradescope_results(results, numbers, integrity, time.monotonic() - started)
        write_fresh(Path(gradescope).expanduser(), json.dumps(report, indent=1))
        print(f"Wrote the results to {gradescope}.", file=out)
    if verbose and not all_passed:
        print("", file=out)
        print("\n".join(failures_in_detail(results, numbers)), file=out)
    elif not all_passed:
        again = f"minippo grade {numbers[0]} --verbose" if len(numbers) == 1 else "minippo grade N --verbose"
        print(f"Every failing test with its message: {again}", file=out)
    return 0 if all_passed else 1


def gradescope_results(results, numbers, integrity: dict, seconds: float) -> dict:
    """Gradescope's autograder results.json: one test entry per chapter (score = tests passed, max_score = tests),
    its output the first failure's message and any integrity note."""
    tests = []
    for number in numbers:
        mine = [r for r in results if r.chapter == number]
        passed = sum(r.outcome == "passed" for r in mine)
        first = next((r for r in mine if r.outcome != "passed"), None)
        output = (first.message if first else "all passed") if mine else "no tests ran"
        notes = integrity_notes(integrity, number)
        if notes:
            output += "\nIntegrity: " + "; ".join(notes)
        tests.append(
            {
                "name": chapter_title(number),
                "number": str(number),
                "score": float(passed),
                "max_score": float(len(mine)),
                "status": "passed" if mine and first is None else "failed",
                "output": output,
                "visibility": "visible",
            }
        )
    return {
        "score": float(sum(t["score"] for t in tests)),
        "execution_time": int(round(seconds)),
        "output": f"Graded with minippo grade, isolation: {integrity.get('isolation', 'none')}.",
        "stdout_visibility": "hidden",
        "tests": tests,
    }


SETUP_SH = """#!/usr/bin/env bash
# Gradescope runs this once, as root, when it builds the autograder's image: minippo's grading extra from the
# course's repository, at the commit the zip was built for.
set -euo pipefail
apt-get install -y python3 python3-pip python3-venv git util-linux
python3 -m venv /autograder/venv
git clone {repo} /autograder/course
git -C /autograder/course checkout {commit}
/autograder/venv/bin/pip install -e '/autograder/course[grade]'
"""

RUN_AUTOGRADER = """#!/usr/bin/env bash
# Gradescope runs this for every submission: grade /autograder/submission into /autograder/results/results.json.
cd /autograder/course
mkdir -p /autograder/results
{python} -m minippo grade {chapter}--submission /autograder/submission --gradescope /autograder/results/results.json
exit 0
"""


def autograder_zip(path: str, repo: str, commit: str, chapter: str | None = None, python: str = "") -> int:
    """Write Gradescope's autograder zip: setup.sh (installs minippo's grading extra from ``repo`` at ``commit``) and
    run_autograder (grades /autograder/submission, ``chapter`` or every chapter). 0, or 2 for bad input."""
    import zipfile

    if not re.fullmatch(r"[0-9a-fA-F]{7,40}|[\w./-]+", commit) or commit.startswith("-"):
        print(f"minippo: error: not a commit: {commit}", file=sys.stderr)
        return 2
    if not repo or any(c in repo for c in " '\"\n;&|$`") or repo.startswith("-"):
        print(f"minippo: error: not a repository address: {repo}", file=sys.stderr)
        return 2
    if chapter is not None:
        try:
            number = _chapters(chapter)[0]
        except ValueError as error:
            print(f"minippo: error: {error}", file=sys.stderr)
            return 2
    target = Path(path).expanduser()
    if not target.resolve().parent.is_dir():
        print(f"minippo: error: no folder for {path}", file=sys.stderr)
        return 2
    run = RUN_AUTOGRADER.format(
        python=python or "/autograder/venv/bin/python", chapter=f"{number} " if chapter is not None else ""
    )
    with zipfile.ZipFile(target, "w") as archive:
        for name, text in (("setup.sh", SETUP_SH.format(repo=repo, commit=commit)), ("run_autograder", run)):
            info = zipfile.ZipInfo(name)
            info.external_attr = 0o755 << 16
            archive.writestr(info, text)
    return 0


def write_fresh(path: Path, text: str) -> None:
    """Write ``text`` to a new file at ``path``: whatever stood there (a link a submission left, say) is removed
    first, so the file written is the grader's own."""
    if path.is_symlink() or path.is_file():
        path.unlink()
    with open(path, "x", encoding="utf-8", newline="") as handle:
        handle.write(text)


def csv_cell(value) -> str:
    """A CSV cell that a spreadsheet shows as text: one line, and a leading = + - @ (a formula) quoted with '."""
    text = " ".join(str(value).split())
    if text[:1] in ("=", "+", "-", "@", "\t", "\r", "|", "%"):
        text = "'" + text
    return text


CSV_FIELDS = ["student", "chapter", "passed", "total", "first_failure", "integrity", "isolation"]


def grade_class(
    folder: str, chapter: str | None = None, csv_path: str | None = None, out=None, limit_s: float = RUN_LIMIT_S
) -> int:
    """Grade every student of a class: each sub-folder of ``folder`` holds one student's chNN_*.py modules. Each
    student's code runs in its own child process under the same per-test time limits (and ``limit_s`` for the whole
    student), so an endless loop or a crash costs only that student's line. Writes one CSV row per student and
    chapter (student, chapter, passed, total, first_failure) to ``csv_path`` and prints the same as a table.
    Returns 0 once every student is graded, 2 for bad input."""
    out = out or sys.stdout
    root = Path(folder).expanduser()
    if not root.is_dir():
        print(f"minippo: error: no class folder {folder}", file=sys.stderr)
        return 2
    students = sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith((".", "_")))
    if not students:
        print(
            f"minippo: error: {folder} holds no student folders (one folder of chNN_*.py files each)", file=sys.stderr
        )
        return 2
    try:
        numbers = _chapters(chapter)
    except ValueError as error:
        print(f"minippo: error: {error}", file=sys.stderr)
        return 2
    if csv_path is not None and not Path(csv_path).expanduser().resolve().parent.is_dir():
        print(f"minippo: error: no folder for the CSV file {csv_path}", file=sys.stderr)
        return 2
    if not _check_pytest_timeout():
        return 2
    files = chapter_files()
    print(
        f"Grading {len(students)} students in {folder} (chapter {', '.join(map(str, numbers))}).", file=out, flush=True
    )
    rows = []
    hidden = [root.resolve()] + ([Path(csv_path).expanduser().resolve()] if csv_path is not None else [])
    width = max(len(s.name) for s in students + [Path("student")])
    print(f"{'student':<{width}}  {'chapter':<22}  {'passed':>7}  first failure", file=out, flush=True)
    for student in students:
        integrity: dict = {}
        _, results, note = run_tests(
            str(student.resolve()), [files[n] for n in numbers], limit_s=limit_s, integrity=integrity, hide=hidden
        )
        for number in numbers:
            mine = [r for r in results if r.chapter == number]
            passed = sum(r.outcome == "passed" for r in mine)
            first = next((r for r in mine if r.outcome != "passed"), None)
            comment = first.message if first else ("no tests ran" if not mine else "")
            if note and not mine:
                comment = note
            notes = "; ".join(integrity_notes(integrity, number))
            row = {"student": csv_cell(student.name), "chapter": number, "passed": passed, "total": len(mine),
                   "first_failure": csv_cell(comment), "integrity": csv_cell(notes),
                   "isolation": integrity.get("isolation", "none")}  # fmt: skip
            rows.append(row)
            score = f"{passed}/{len(mine)}"
            shown = " ".join(comment.split())
            shown = shown if len(shown) <= 100 else shown[:97] + "..."
            shown = shown or "all passed"
            if notes:
                shown += f"  [integrity: {notes}]"
            name = " ".join(student.name.split())
            print(f"{name:<{width}}  {chapter_title(number):<22}  {score:>7}  {shown}", file=out, flush=True)
    if csv_path is not None:
        table = io.StringIO()
        writer = csv.DictWriter(table, fieldnames=CSV_FIELDS)
        writer.writeheader()
        writer.writerows(rows)
        write_fresh(Path(csv_path).expanduser(), table.getvalue())
        print(f"Wrote {len(rows)} rows to {csv_path}.", file=out)
    return 0
