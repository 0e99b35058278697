"""``minippo grade [CHAPTER] [--solutions] [--verbose] [--class FOLDER --csv FILE]``: run the grading tests and print
a scoreboard, chapter by chapter (or one line per student and chapter for a whole class).

Which code is graded: exercises/ by default; solutions/ with --solutions; a folder with --submission FOLDER or the
environment variable MINIPPO_IMPL (``exercises``, ``solutions``, or a folder holding chNN_*.py modules). With --class,
every sub-folder of FOLDER is one student's folder of chNN_*.py modules, graded in its own process.

The tests run in a child pytest process (minippo.grading.supervisor). A student's code never runs there: the tests call
it through a worker process (minippo.grading.sandbox and minippo.grading.worker) that cannot see the repository, the
other students or the grader's log, under CPU, memory, file-size and process limits. What the worker or the source
scan saw a submission do that an instructor should know of (importing the reference, using minippo's own version of
the exercise, reaching for the grader's files) goes to the integrity column; how far the worker was isolated, to the
isolation column. ``--gradescope FILE`` writes the results in Gradescope's results.json format; ``--autograder-zip``
builds the zip Gradescope runs (minippo.grading.gradescope).

The course (its grading tests and the book's chapter names) is the repository minippo is installed from, or the folder
the environment variable MINIPPO_COURSE names (minippo.grading.chapters).
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

from minippo.errors import MinippoError
from minippo.grading.chapters import VARIANT_FOLDERS, chapter_files, chapter_title, chapters_to_grade
from minippo.grading.gradescope import gradescope_results
from minippo.grading.reports import CSV_FIELDS, chapter_score, csv_cell, failures_in_detail, integrity_notes, scoreboard
from minippo.grading.supervisor import IMPL_VARIABLE, RUN_LIMIT_S, grader_error, run_tests
from minippo.records import write_atomically, write_rows

NOT_GRADED = "not graded"  # a class's passed cell when the grader could not run the student's code


def _require_pytest_timeout() -> None:
    try:
        import pytest_timeout  # noqa: F401 - the per-test time limits need it
    except ImportError:
        raise MinippoError("grading needs pytest and pytest-timeout: pip install -e '.[grade]'") from None


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
    """Grade one chapter (or all), print the scoreboard; 0 if every test passed, 1 if not (MinippoError for bad input).
    ``verbose`` lists every failing test with its message below the scoreboard; ``gradescope`` also writes the
    results to that file in Gradescope's results.json format."""
    out = out or sys.stdout
    started = time.monotonic()
    numbers = chapters_to_grade(chapter)
    if gradescope is not None and not Path(gradescope).expanduser().resolve().parent.is_dir():
        raise MinippoError(f"no folder for the results file {gradescope}")
    if gradescope is not None and Path(gradescope).expanduser().is_dir():
        raise MinippoError(f"{gradescope} is a folder; --gradescope takes the results file's name")
    _require_pytest_timeout()
    files = chapter_files()
    if impl is None:
        impl = "solutions" if solutions else os.environ.get(IMPL_VARIABLE, "").strip() or "exercises"
    if impl not in ("exercises", "solutions", *VARIANT_FOLDERS):
        if not Path(impl).expanduser().is_dir():
            raise MinippoError(f"no submission folder {impl}")
        impl = str(find_submission(Path(impl).expanduser().resolve()))
    where = f"{impl}/" if impl in ("exercises", "solutions") else impl
    print(
        f"Grading {where} (chapter {', '.join(map(str, numbers))}); the time limit is per test.", file=out, flush=True
    )
    integrity: dict = {}
    hide = [Path(gradescope).expanduser().resolve()] if gradescope is not None else []
    _, results, note = run_tests(impl, [files[n] for n in numbers], integrity=integrity, hide=hide)
    failure = grader_error(integrity)
    if failure:  # nothing was graded: no scoreboard of zeros that blames the code
        raise MinippoError(f"not graded: {failure}")
    lines, all_passed = scoreboard(results, numbers)
    print("\n".join(lines), file=out)
    if note:
        print(f"note: {note}", file=out)
    for number in numbers:
        for text in integrity_notes(integrity, number):
            print(f"integrity: {chapter_title(number)}: {text}", file=out)
    if gradescope is not None:
        report = gradescope_results(results, numbers, integrity, time.monotonic() - started)
        text = json.dumps(report, indent=1)
        write_atomically(Path(gradescope).expanduser(), lambda handle: handle.write(text.encode("utf-8")))
        print(f"Wrote the results to {gradescope}.", file=out)
    if verbose and not all_passed:
        print("", file=out)
        print("\n".join(failures_in_detail(results, numbers)), file=out)
    elif not all_passed:
        again = f"minippo grade {numbers[0]} --verbose" if len(numbers) == 1 else "minippo grade N --verbose"
        print(f"Every failing test with its message: {again}", file=out)
    return 0 if all_passed else 1


def grade_class(
    folder: str, chapter: str | None = None, csv_path: str | None = None, out=None, limit_s: float = RUN_LIMIT_S
) -> int:
    """Grade every student of a class: each sub-folder of ``folder`` holds one student's chNN_*.py modules. Each
    student's code runs in its own child process under the same per-test time limits (and ``limit_s`` for the whole
    student), so an endless loop or a crash costs only that student's line. Writes one CSV row per student and
    chapter (student, chapter, passed, total, first_failure) to ``csv_path`` and prints the same as a table. A student
    whose code the grader could not run (its worker did not start: the grader's failure) is marked "not graded", with
    the reason, rather than 0. Returns 0 once every student is graded, 1 if one was not; raises MinippoError for bad
    input."""
    out = out or sys.stdout
    root = Path(folder).expanduser()
    if not root.is_dir():
        raise MinippoError(f"no class folder {folder}")
    students = sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith((".", "_")))
    if not students:
        raise MinippoError(f"{folder} holds no student folders (one folder of chNN_*.py files each)")
    numbers = chapters_to_grade(chapter)
    if csv_path is not None and not Path(csv_path).expanduser().resolve().parent.is_dir():
        raise MinippoError(f"no folder for the CSV file {csv_path}")
    _require_pytest_timeout()
    files = chapter_files()
    print(
        f"Grading {len(students)} students in {folder} (chapter {', '.join(map(str, numbers))}).", file=out, flush=True
    )
    rows, not_graded = [], []
    hidden = [root.resolve()] + ([Path(csv_path).expanduser().resolve()] if csv_path is not None else [])
    width = max(len(s.name) for s in students + [Path("student")])
    print(f"{'student':<{width}}  {'chapter':<22}  {'passed':>7}  first failure", file=out, flush=True)
    for student in students:
        integrity: dict = {}
        _, results, note = run_tests(
            str(student.resolve()), [files[n] for n in numbers], limit_s=limit_s, integrity=integrity, hide=hidden
        )
        failure = grader_error(integrity)
        if failure:
            not_graded.append(student.name)
        for number in numbers:
            score = chapter_score(results, number)
            comment = "" if score.all_passed else score.summary
            if note and not score.total:
                comment = note
            if failure:
                comment = failure
            notes = "; ".join(integrity_notes(integrity, number))
            passed = NOT_GRADED if failure else score.passed
            row = {"student": csv_cell(student.name), "chapter": number, "passed": passed, "total": score.total,
                   "first_failure": csv_cell(comment), "integrity": csv_cell(notes),
                   "isolation": integrity.get("isolation", "none")}  # fmt: skip
            rows.append(row)
            fraction = NOT_GRADED if failure else f"{score.passed}/{score.total}"
            shown = " ".join(comment.split())
            shown = shown if len(shown) <= 100 else shown[:97] + "..."
            shown = shown or "all passed"
            if notes:
                shown += f"  [integrity: {notes}]"
            name = " ".join(student.name.split())
            print(f"{name:<{width}}  {chapter_title(number):<22}  {fraction:>7}  {shown}", file=out, flush=True)
    if csv_path is not None:
        write_rows(Path(csv_path).expanduser(), CSV_FIELDS, rows)
        print(f"Wrote {len(rows)} rows to {csv_path}.", file=out)
    if not_graded:
        print(f"{len(not_graded)} of {len(students)} students not graded, by the grader's error above.", file=out)
        return 1
    return 0
