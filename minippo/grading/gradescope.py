"""Gradescope: its results.json, and the autograder zip it runs for every submission."""

from __future__ import annotations

import re
from pathlib import Path

from minippo.errors import MinippoError
from minippo.grading.chapters import chapter_title, chapters_to_grade
from minippo.grading.reports import chapter_score, integrity_notes
from minippo.records import write_atomically


def gradescope_results(results, numbers, integrity: dict, seconds: float) -> dict:
    """Gradescope's autograder results.json: one test entry per chapter (score = tests passed, max_score = tests),
    its output the first failure's message and any integrity note."""
    tests = []
    for number in numbers:
        score = chapter_score(results, number)
        output = score.summary
        notes = integrity_notes(integrity, number)
        if notes:
            output += "\nIntegrity: " + "; ".join(notes)
        tests.append(
            {
                "name": chapter_title(number),
                "number": str(number),
                "score": float(score.passed),
                "max_score": float(score.total),
                "status": "passed" if score.all_passed else "failed",
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
    run_autograder (grades /autograder/submission, ``chapter`` or every chapter). 0; MinippoError for bad input."""
    import zipfile

    if not re.fullmatch(r"[0-9a-fA-F]{7,40}|[\w./-]+", commit) or commit.startswith("-"):
        raise MinippoError(f"not a commit: {commit}")
    if not repo or any(c in repo for c in " '\"\n;&|$`") or repo.startswith("-"):
        raise MinippoError(f"not a repository address: {repo}")
    number = chapters_to_grade(chapter)[0] if chapter is not None else None
    target = Path(path).expanduser()
    if not target.resolve().parent.is_dir():
        raise MinippoError(f"no folder for {path}")
    run = RUN_AUTOGRADER.format(
        python=python or "/autograder/venv/bin/python", chapter=f"{number} " if number is not None else ""
    )

    def write(handle) -> None:
        with zipfile.ZipFile(handle, "w") as archive:
            for name, text in (("setup.sh", SETUP_SH.format(repo=repo, commit=commit)), ("run_autograder", run)):
                info = zipfile.ZipInfo(name)
                info.external_attr = 0o755 << 16
                archive.writestr(info, text)

    write_atomically(target, write)
    return 0
