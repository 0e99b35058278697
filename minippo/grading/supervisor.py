"""Running the grading tests in a child pytest process and reading back their results.

The tests (tests/exercises/test_chNN_*.py) run with a time limit per test, so code that raises, returns NaN or never
returns fails its tests instead of stopping the grader. The child's plugin (minippo.grading.plugin) writes each result
to a signed log as soon as it is known; if student code kills the test process itself, the test that was running is
failed and the rest run in a new process.
"""

from __future__ import annotations

import hmac
import json
import os
import secrets
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from minippo.grading.chapters import COURSE_VARIABLE, VARIANT_FOLDERS, chapter_of_nodeid, course
from minippo.grading.plugin import KEY_VARIABLE, LOG_VARIABLE, STOP_VARIABLE, TIME_FACTOR_VARIABLE, signature

IMPL_VARIABLE = "MINIPPO_IMPL"
HIDE_VARIABLE = "MINIPPO_GRADE_HIDE"
WORKER_TIME_FACTOR = 2  # the per-test time limits, for code graded through a worker process
RUN_LIMIT_S = 1800  # the whole run; each test has its own, much shorter limit
RESTARTS = 5  # how many times a run whose test process died goes on with the tests that had not run


@dataclass
class Result:
    nodeid: str
    outcome: str  # passed | failed | skipped
    message: str = ""

    @property
    def chapter(self) -> int:
        return chapter_of_nodeid(self.nodeid)


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
    ``integrity``, if given, is filled with {chapter number: [notes]}, {"isolation": how the worker was kept apart}
    and, when the grader itself could not run the student's code (its worker did not start), {"grader_error":
    [why]}: then nothing was graded, whatever the results say (see ``grader_error``).
    ``hide``: folders the student's worker must not see besides the repository (the class folder).

    If the child process dies (student code that calls os._exit, crashes the interpreter or is killed), the test it
    was running fails with that reason and the tests that had not run yet run in a new child, so one crash costs one
    test. The whole run, restarts included, stops after ``limit_s`` seconds."""
    root = course().root
    env = dict(os.environ)
    env[COURSE_VARIABLE] = str(root)  # the tests' worker hides the same course from the student's code
    env[IMPL_VARIABLE] = impl
    if stop_at_first_failure:
        env[STOP_VARIABLE] = "1"
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env.setdefault(name, "1")  # small matrices: extra BLAS threads only spin
    key = secrets.token_hex(32)
    env[KEY_VARIABLE] = key
    if hide:
        env[HIDE_VARIABLE] = os.pathsep.join(str(p) for p in hide)
    if impl not in ("solutions", *VARIANT_FOLDERS) and not env.get(TIME_FACTOR_VARIABLE):
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
                sys.executable, "-m", "pytest", *targets, "-p", "minippo.grading.plugin", "-p", "no:cacheprovider",
                "-q", "--no-header", "-o", "addopts=", "--continue-on-collection-errors", "--tb=line", *extra_args,
            ]  # fmt: skip
            returncode = None
            try:
                left = max(1.0, deadline - time.monotonic())
                finished = subprocess.run(command, cwd=root, env=env, capture_output=True, text=True, timeout=left)
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
            if not hmac.compare_digest(str(signed["mac"]), signature(text, key)):
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
        if "grader_error" in record:
            errors = integrity.setdefault("grader_error", [])
            if record["grader_error"] not in errors:
                errors.append(str(record["grader_error"]))
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


def grader_error(integrity: dict) -> str | None:
    """The grader's own failure in a run (its worker could not start): the student was not graded. None if none."""
    errors = integrity.get("grader_error") or []
    return str(errors[0]) if errors else None


def _death(returncode: int) -> str:
    if returncode < 0:
        try:
            return f"killed by signal {signal.Signals(-returncode).name}"
        except ValueError:
            return f"killed by signal {-returncode}"
    return f"it exited with code {returncode}: does the code call sys.exit or os._exit?"
