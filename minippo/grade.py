"""``minippo grade [CHAPTER] [--solutions]``: run the grading tests and print a scoreboard, chapter by chapter.

The tests (tests/exercises/test_chNN_*.py) run in a child pytest process with a time limit per test, so code that
raises, returns NaN or never returns fails its tests instead of stopping the grader. Each result is written to a
log as soon as it is known (this module is also the pytest plugin that writes it), so even a run that has to be
stopped still reports what finished.

Which code is graded: exercises/ by default; solutions/ with --solutions; or the environment variable MINIPPO_IMPL
(``exercises``, ``solutions``, or a folder holding chNN_*.py modules).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TESTS = ROOT / "tests" / "exercises"
IMPL_VARIABLE = "MINIPPO_IMPL"
LOG_VARIABLE = "MINIPPO_GRADE_LOG"
STOP_VARIABLE = "MINIPPO_GRADE_STOP_AT_FIRST_FAILURE"
RUN_LIMIT_S = 1800  # the whole run; each test has its own, much shorter limit
# the book's chapter names, so "minippo grade the-min" works as well as "minippo grade 6"
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
    12: "language-model",
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


def chapter_title(number: int) -> str:
    path = chapter_files().get(number)
    topic = path.stem[10:] if path else BOOK_NAMES.get(number, "")
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
    for number, name in BOOK_NAMES.items():
        if key == name.replace("-", "_"):
            return number
    return None


# the pytest plugin: loaded in the child process with ``-p minippo.grade``

_variant_of_test: dict[str, str] = {}
_rejected_variants: set[str] = set()


def _log(record: dict) -> None:
    path = os.environ.get(LOG_VARIABLE)
    if path:
        with open(path, "a", encoding="utf-8") as handle:
            handle.write(json.dumps(record) + "\n")


def pytest_collection_finish(session) -> None:
    _log({"collected": [item.nodeid for item in session.items]})


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


def run_tests(impl: str, files, stop_at_first_failure: bool = False, limit_s: float = RUN_LIMIT_S, extra_args=()):
    """Run pytest on ``files`` against ``impl`` in a child process; return (collected node ids, results, note)."""
    with tempfile.TemporaryDirectory(prefix="minippo-grade-") as folder:
        log = Path(folder) / "results.jsonl"
        env = dict(os.environ)
        env[IMPL_VARIABLE], env[LOG_VARIABLE] = impl, str(log)
        if stop_at_first_failure:
            env[STOP_VARIABLE] = "1"
        for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            env.setdefault(name, "1")  # small matrices: extra BLAS threads only spin
        command = [
            sys.executable, "-m", "pytest", *map(str, files), "-p", "minippo.grade", "-p", "no:cacheprovider",
            "-q", "--no-header", "-o", "addopts=", "--continue-on-collection-errors", *extra_args,
        ]  # fmt: skip
        note = ""
        try:
            finished = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, timeout=limit_s)
            if finished.returncode not in (0, 1):
                tail = (finished.stdout + finished.stderr).strip().splitlines()[-3:]
                note = f"pytest stopped with exit code {finished.returncode}: {' / '.join(tail)}"
        except subprocess.TimeoutExpired:
            note = f"the run was stopped after {limit_s:g} s"
        collected, results = [], {}
        if log.exists():
            for line in log.read_text(encoding="utf-8").splitlines():
                record = json.loads(line)
                if "collected" in record:
                    collected = record["collected"]
                    continue
                old = results.get(record["nodeid"])
                if old is None or old.outcome == "passed":  # a failing teardown spoils a passed call
                    results[record["nodeid"]] = Result(record["nodeid"], record["outcome"], record["message"])
    for nodeid in collected:
        if nodeid not in results:
            results[nodeid] = Result(nodeid, "failed", f"did not finish ({note or 'no result'})")
    return collected, list(results.values()), note


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


def grade(chapter: str | None = None, solutions: bool = False, impl: str | None = None, out=None) -> int:
    """Grade one chapter (or all), print the scoreboard; 0 if every test passed, 1 if not, 2 for bad input."""
    out = out or sys.stdout
    files = chapter_files()
    if not files:
        print(
            f"minippo: error: no grading tests found in {TESTS} (grade from the course's repository)", file=sys.stderr
        )
        return 2
    if chapter is None:
        numbers = sorted(files)
    else:
        number = resolve_chapter(str(chapter))
        if number is None or number not in files:
            known = ", ".join(f"{n} ({chapter_title(n)[5:]})" for n in sorted(files))
            why = f"chapter {number} has no exercise" if number in BOOK_NAMES else f"unknown chapter '{chapter}'"
            print(f"minippo: error: {why}; chapters with exercises: {known}", file=sys.stderr)
            return 2
        numbers = [number]
    try:
        import pytest_timeout  # noqa: F401 - the per-test time limits need it
    except ImportError:
        print("minippo: error: grading needs pytest and pytest-timeout: pip install -e '.[test]'", file=sys.stderr)
        return 2
    if impl is None:
        impl = "solutions" if solutions else os.environ.get(IMPL_VARIABLE, "").strip() or "exercises"
    where = f"{impl}/" if impl in ("exercises", "solutions") else impl
    print(
        f"Grading {where} (chapter {', '.join(map(str, numbers))}); the time limit is per test.", file=out, flush=True
    )
    _, results, note = run_tests(impl, [files[n] for n in numbers])
    lines, all_passed = scoreboard(results, numbers)
    print("\n".join(lines), file=out)
    if note:
        print(f"note: {note}", file=out)
    if not all_passed:
        only = f" -k ch{numbers[0]:02d}" if len(numbers) == 1 else ""
        print(f"Every test in detail: {IMPL_VARIABLE}={impl} pytest {TESTS.relative_to(ROOT)}{only}", file=out)
    return 0 if all_passed else 1
