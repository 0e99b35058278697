"""What ``minippo grade`` prints and writes: the scoreboard, every failing test, and a class's CSV."""

from __future__ import annotations

from typing import NamedTuple

from minippo.grading.chapters import chapter_title


class Score(NamedTuple):
    """One chapter's tests: how many passed, how many ran, and the first failure's message (None if none failed)."""

    passed: int
    total: int
    first_failure: str | None

    @property
    def all_passed(self) -> bool:
        return self.total > 0 and self.first_failure is None

    @property
    def summary(self) -> str:
        """'no tests ran', 'all passed' or the first failure's message."""
        if not self.total:
            return "no tests ran"
        return "all passed" if self.first_failure is None else self.first_failure


def chapter_score(results, number: int) -> Score:
    """The score of chapter ``number`` in ``results`` (the supervisor's Results, in the order the tests ran)."""
    mine = [r for r in results if r.chapter == number]
    first_failure = next((r.message for r in mine if r.outcome != "passed"), None)
    return Score(sum(r.outcome == "passed" for r in mine), len(mine), first_failure)


def scoreboard(results, numbers) -> tuple[list[str], bool]:
    """One line per chapter (tests passed/run and the first failure) and a total; and whether every test passed."""
    lines, all_passed = [], True
    width = max(len(chapter_title(n)) for n in numbers)
    total_passed = total = 0
    for number in numbers:
        score = chapter_score(results, number)
        total_passed, total = total_passed + score.passed, total + score.total
        all_passed = all_passed and score.all_passed
        lines.append(f"{chapter_title(number):<{width}}  {f'{score.passed}/{score.total}':>7}  {score.summary}")
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


def integrity_notes(integrity: dict, number: int) -> list[str]:
    """What the instructor should know of one chapter's submission: its own notes and the log's."""
    return integrity.get(number, []) + integrity.get("log", [])


def csv_cell(value) -> str:
    """A CSV cell that a spreadsheet shows as text: one line, and a leading = + - @ (a formula) quoted with '."""
    text = " ".join(str(value).split())
    if text[:1] in ("=", "+", "-", "@", "\t", "\r", "|", "%"):
        text = "'" + text
    return text


CSV_FIELDS = ["student", "chapter", "passed", "total", "first_failure", "integrity", "isolation"]
