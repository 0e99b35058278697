"""The pytest plugin of ``minippo grade``, loaded in the child pytest process with ``-p minippo.grading.plugin``.

Each result is written to the grader's log as soon as it is known, so even a run that has to be stopped still reports
what finished. Every record is signed with a key only the grader and its tests know, so a record the tests did not
write is ignored (minippo.grading.supervisor reads the log).
"""

from __future__ import annotations

import hashlib
import hmac
import json
import os
import re

LOG_VARIABLE = "MINIPPO_GRADE_LOG"
STOP_VARIABLE = "MINIPPO_GRADE_STOP_AT_FIRST_FAILURE"
KEY_VARIABLE = "MINIPPO_GRADE_KEY"  # signs every record of the log, so that a record the tests did not write is ignored
TIME_FACTOR_VARIABLE = "MINIPPO_GRADE_TIME_FACTOR"

_variant_of_test: dict[str, str] = {}
_rejected_variants: set[str] = set()
_key = ""  # the log's signing key, once pytest_configure has taken it out of the environment


def pytest_configure(config) -> None:
    """Take the signing key out of the environment before any test runs, so that nothing the tests run finds it."""
    global _key
    _key = os.environ.pop(KEY_VARIABLE, "")


def signature(text: str, key: str) -> str:
    return hmac.new(key.encode(), text.encode(), hashlib.sha256).hexdigest()


def _log(record: dict) -> None:
    path = os.environ.get(LOG_VARIABLE)
    if path:
        text = json.dumps(record)
        with open(path, "a", encoding="utf-8") as handle:
            handle.write(json.dumps({"record": text, "mac": signature(text, _key)}) + "\n")


def log_integrity(chapter: str, note: str | None, isolation: str | None = None) -> None:
    """Record what a submission was seen doing that the instructor should know of (``note``), or how its worker was
    isolated; both go to the CSV's integrity and isolation columns."""
    _log({"integrity": chapter, "note": note, "isolation": isolation})


def log_grader_error(text: str) -> None:
    """Record that the grader itself could not run the student's code (its worker did not start): the student is
    not graded, rather than given 0 (minippo.grading.supervisor reads it)."""
    _log({"grader_error": text})


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


# the exceptions whose class says nothing to a student, named as a failure's first line names them (pytest.fail's is
# Failed); the tests add theirs with plain_exception
_plain_exceptions = {"AssertionError", "Failed"}


def plain_exception(kind: type) -> type:
    """Class decorator for an exception of the tests' whose message is written for the student: the scoreboard shows
    the message without the class's name."""
    module = kind.__module__
    _plain_exceptions.add(kind.__qualname__ if module in ("builtins", "__main__") else f"{module}.{kind.__qualname__}")
    return kind


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
    kind, colon, message = first.partition(": ")
    if colon and kind in _plain_exceptions:
        return message
    if first == "AssertionError":
        return "a check failed"
    return f"the test crashed: {first}"
