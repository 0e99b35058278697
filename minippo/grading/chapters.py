"""The course ``minippo grade`` grades: where it is, its chapters and their names.

The chapters are found, not listed: a chapter is graded when tests/exercises/test_chNN_<topic>.py exists, and its
book name (``minippo grade the-min``) comes from book/NN-<name>.md. A new chapter needs only those two files. The
course is the repository minippo is installed from (``pip install -e .``), or the folder the environment variable
MINIPPO_COURSE names.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

from minippo.errors import MinippoError

COURSE_VARIABLE = "MINIPPO_COURSE"
INSTALLED_FROM = Path(__file__).resolve().parents[2]  # the repository holding this minippo, with ``pip install -e .``
# the course's own variants of the exercises, each graded by its folder's name (MINIPPO_IMPL=wrong): the deliberately
# wrong ones the tests must reject and the other right ones they must accept, in tests/exercises/<name>/
VARIANT_FOLDERS = ("wrong", "right")


@dataclass(frozen=True)
class Course:
    """Where the graded course's files are: its repository, the grading tests and the book's pages."""

    root: Path

    @property
    def tests(self) -> Path:
        return self.root / "tests" / "exercises"

    @property
    def book(self) -> Path:
        return self.root / "book"


def course(root: str | os.PathLike | None = None) -> Course:
    """The course at ``root``, the one place the grading tests and the book's pages are looked for; by default the
    folder MINIPPO_COURSE names, else the repository minippo is installed from. Raises MinippoError when it holds no
    grading tests (minippo from a wheel, say, or a folder that is not a course)."""
    if root is None:
        root = os.environ.get(COURSE_VARIABLE, "").strip() or INSTALLED_FROM
    found = Course(Path(root).expanduser().resolve())
    if not any(found.tests.glob("test_ch[0-9][0-9]_*.py")):
        raise MinippoError(
            f"{found.root} is not a course: no grading tests in {found.tests} (set {COURSE_VARIABLE} to the course's "
            "repository)"
        )
    return found


def chapter_files() -> dict[int, Path]:
    """{chapter number: its grading test file}."""
    files = {}
    for path in sorted(course().tests.glob("test_ch[0-9][0-9]_*.py")):
        files[int(path.name[7:9])] = path
    return files


def book_names() -> dict[int, str]:
    """{chapter number: the book page's name}, from book/NN-<name>.md, so that "minippo grade the-min" works as well as
    "minippo grade 6"."""
    return {int(page.name[:2]): page.stem[3:] for page in sorted(course().book.glob("[0-9][0-9]-*.md"))}


def chapter_title(number: int) -> str:
    """'ch06 the min': the chapter's one name, its book page's (the test file's topic where there is no page), with
    spaces; ``minippo grade`` accepts it as it is printed."""
    path = chapter_files().get(number)
    topic = book_names().get(number) or (path.stem[10:] if path else "")
    return f"ch{number:02d} {topic.replace('_', ' ').replace('-', ' ')}"


def chapter_of_nodeid(nodeid: str) -> int:
    match = re.search(r"test_ch(\d\d)_", nodeid)
    return int(match.group(1)) if match else 0


def resolve_chapter(text: str) -> int | None:
    """'5', '05', 'ch05', 'clipping', 'ch05_clipping' -> 5; 'the-min', 'the min', 'ch06 the min' -> 6; None if no
    chapter has that name."""
    key = re.sub(r"[\s_-]+", "_", text.strip().lower().removesuffix(".py"))
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


def chapters_to_grade(chapter) -> list[int]:
    """The chapter numbers to grade: ``chapter``'s, or every one if it is None; MinippoError for a bad name."""
    files = chapter_files()
    if chapter is None:
        return sorted(files)
    number = resolve_chapter(str(chapter))
    if number is None or number not in files:
        known = ", ".join(f"{n} ({chapter_title(n)[5:]})" for n in sorted(files))
        why = f"chapter {number} has no exercise" if number in book_names() else f"unknown chapter '{chapter}'"
        raise MinippoError(f"{why}; chapters with exercises: {known}")
    return [number]
