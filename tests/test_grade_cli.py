"""``minippo grade``: chapter names, the scoreboard, exit codes, and student code that raises, returns NaN or the wrong
shape, has a syntax error or never finishes importing, each of which must become a failing line, never a crash."""

import csv
import importlib.util
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from minippo.errors import MinippoError
from minippo.grading import chapters, reports
from minippo.grading.supervisor import Result

ROOT = Path(__file__).resolve().parents[1]


def run_grade(*args, impl=None, timeout=300, course=None):
    env = dict(os.environ)
    env.pop("MINIPPO_IMPL", None)
    env.pop(chapters.COURSE_VARIABLE, None)
    if impl is not None:
        env["MINIPPO_IMPL"] = str(impl)
    if course is not None:
        env[chapters.COURSE_VARIABLE] = str(course)
    return subprocess.run(
        [sys.executable, "-m", "minippo", "grade", *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


@pytest.mark.parametrize(
    "text, number",
    [
        ("5", 5),
        ("05", 5),
        ("ch05", 5),
        ("clipping", 5),
        ("ch05_clipping", 5),
        ("the-min", 6),
        ("the_min", 6),
        ("vanilla-pg", 3),
        ("ppo_update", 10),
        ("everything-together", 10),
        ("CH07", 7),
        ("11", 11),
        ("pixels", 12),
        ("ch12", 12),
        ("ch12_pixels", 12),
        ("language-model", 13),
        ("ch13", 13),
        ("grpo-dpo", 14),
        ("the min", 6),  # as the scoreboard and the "unknown chapter" error print it
        ("the-min", 6),
        ("6", 6),
        ("ch06 the min", 6),
        ("everything together", 10),
        ("Vanilla PG", 3),
    ],
)
def test_chapter_names(text, number):
    assert chapters.resolve_chapter(text) == number


@pytest.mark.parametrize("text", ["foo", "", "ch", "network-x"])
def test_unknown_chapter_names(text):
    assert chapters.resolve_chapter(text) is None


def test_every_chapter_title_is_accepted_as_printed():
    for number in chapters.chapter_files():
        title = chapters.chapter_title(number)
        assert chapters.resolve_chapter(title[5:]) == number, title
        assert chapters.resolve_chapter(title) == number, title
    assert chapters.chapter_title(10) == "ch10 everything together"


def test_the_course_is_where_minippo_is_installed_from_unless_its_root_is_given(tmp_path, monkeypatch):
    monkeypatch.delenv(chapters.COURSE_VARIABLE, raising=False)
    assert chapters.course().root == ROOT
    (tmp_path / "tests" / "exercises").mkdir(parents=True)
    (tmp_path / "tests" / "exercises" / "test_ch03_returns.py").write_text("")
    (tmp_path / "book").mkdir()
    (tmp_path / "book" / "03-counting-returns.md").write_text("")
    assert chapters.course(tmp_path).root == tmp_path.resolve()
    monkeypatch.setenv(chapters.COURSE_VARIABLE, str(tmp_path))
    assert chapters.course().root == tmp_path.resolve()
    assert chapters.chapter_files() == {3: tmp_path.resolve() / "tests" / "exercises" / "test_ch03_returns.py"}
    assert chapters.chapter_title(3) == "ch03 counting returns" and chapters.resolve_chapter("counting-returns") == 3


def test_a_course_folder_without_grading_tests_gets_one_line_and_exit_code_2(tmp_path):
    with pytest.raises(MinippoError, match="is not a course"):
        chapters.course(tmp_path)
    result = run_grade("5", course=tmp_path)
    assert result.returncode == 2 and result.stdout == "", result.stdout + result.stderr
    assert result.stderr.startswith("minippo: error: ") and f"{tmp_path.resolve()} is not a course" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


@pytest.mark.timeout(120)
def test_solutions_get_a_full_score():
    result = run_grade("5", "--solutions")
    assert result.returncode == 0, result.stdout + result.stderr
    line = next(line for line in result.stdout.splitlines() if line.startswith("ch05 clipping"))
    passed, total = map(int, line.split()[2].split("/"))
    assert passed == total >= 20 and line.endswith("all passed"), result.stdout


@pytest.mark.timeout(120)
def test_the_stubs_score_zero_and_say_why(tmp_path):
    spec = importlib.util.spec_from_file_location("make_exercises", ROOT / "tests" / "exercises" / "make_exercises.py")
    make_exercises = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(make_exercises)
    (tmp_path / "ch06_the_min.py").write_text(make_exercises.expected_exercises()["ch06_the_min.py"])
    result = run_grade("ch06", impl=tmp_path)
    assert result.returncode == 1, result.stdout + result.stderr
    line = next(line for line in result.stdout.splitlines() if line.startswith("ch06 the min"))
    assert line.split()[3].startswith("0/") and "clip_objective is not written yet" in line, result.stdout
    assert "total" in result.stdout and result.stderr == ""


@pytest.mark.parametrize("chapter", ["foo", "ch99", "42"])  # chapter 11 has an exercise now (its transfer task)
def test_bad_chapters_get_one_line_and_exit_code_2(chapter):
    result = run_grade(chapter)
    assert result.returncode == 2
    assert result.stdout == ""
    assert len(result.stderr.strip().splitlines()) == 1 and result.stderr.startswith("minippo: error: ")
    assert "Traceback" not in result.stderr


BROKEN = {
    # clip_fraction returns an array, clipped_surrogate returns NaN where it should not
    "ch05_clipping.py": """
        import numpy as np

        def clipped_surrogate(logp, logp_old, advantages, epsilon):
            ratio = np.exp(logp - logp_old)
            return float("nan"), ratio * np.nan

        def clip_fraction(logp, logp_old, epsilon):
            return np.abs(np.exp(logp - logp_old) - 1) > epsilon
    """,
    # a syntax error
    "ch03_vanilla_pg.py": """
        def pg_objective(logp, advantages)
            return 0
    """,
    # stuck at import time
    "ch04_cpi.py": """
        while True:
            pass
    """,
    # raises
    "ch09_kl_penalty.py": """
        def categorical_kl(logits_old, logits):
            raise ValueError("shapes do not match")

        def categorical_kl_backward(logits_old, logits, grad_kl):
            return logits[0]

        def kl_penalty_objective(logp, logp_old, advantages, kl, beta):
            return 0.0

        def adaptive_beta(beta, kl, kl_target):
            return beta
    """,
}


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_broken_student_code_fails_its_tests_and_never_stops_the_grader(tmp_path):
    for name, source in BROKEN.items():
        (tmp_path / name).write_text(textwrap.dedent(source))
    result = run_grade(impl=tmp_path, timeout=250)  # every chapter; the ones without a file fail at once
    assert result.returncode == 1, result.stdout + result.stderr
    assert "Traceback" not in result.stdout + result.stderr
    scores = {c: next(line for line in result.stdout.splitlines() if line.startswith(f"ch0{c}")) for c in "3459"}
    assert "no such file" in next(line for line in result.stdout.splitlines() if line.startswith("ch01"))
    assert " 0/" in scores["3"] and "SyntaxError on line 2" in scores["3"], scores["3"]
    assert " 0/" in scores["4"] and "took longer than the time limit" in scores["4"], scores["4"]
    assert " 0/" in scores["5"] and "NaN" in scores["5"], scores["5"]
    assert (
        "categorical_kl(logits_old=array (6, 4), logits=array (6, 4)) raised ValueError: shapes do not match"
        in (scores["9"])
    ), scores["9"]


def test_grade_counts_every_test_and_reports_the_first_failure():
    results = [
        Result("tests/exercises/test_ch05_clipping.py::test_a", "passed"),
        Result("tests/exercises/test_ch05_clipping.py::test_b", "failed", "clip_fraction: first"),
        Result("tests/exercises/test_ch05_clipping.py::test_c", "failed", "clip_fraction: second"),
        Result("tests/exercises/test_ch06_the_min.py::test_a", "passed"),
    ]
    lines, all_passed = reports.scoreboard(results, [5, 6])
    assert not all_passed
    assert lines[0].startswith("ch05 clipping") and "1/3" in lines[0] and lines[0].endswith("clip_fraction: first")
    assert "1/1" in lines[1] and lines[1].endswith("all passed")
    assert lines[2].startswith("total") and lines[2].endswith("2/4")
    assert reports.scoreboard(results[3:], [6])[1]


CLASS = {
    # right: the reference solution itself
    "alice": (ROOT / "solutions" / "ch04_cpi.py").read_text(encoding="utf-8"),
    # wrong: the gradient without the ratio
    "bob": """
        import numpy as np

        def importance_ratio(logp, logp_old):
            return np.exp(logp - logp_old)

        def cpi_objective(logp, logp_old, advantages):
            ratio = np.exp(logp - logp_old)
            return float(np.mean(ratio * advantages)), advantages / len(logp)
    """,
    # an endless loop in one function, and a crash of the whole process in the other
    "carol": """
        import os

        def importance_ratio(logp, logp_old):
            while True:
                pass

        def cpi_objective(logp, logp_old, advantages):
            os._exit(3)
    """,
}


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_grade_a_class_to_one_csv(tmp_path):
    for name, source in CLASS.items():
        (tmp_path / "class" / name).mkdir(parents=True)
        (tmp_path / "class" / name / "ch04_cpi.py").write_text(textwrap.dedent(source))
    (tmp_path / "class" / "notes.txt").write_text("not a student")
    result = run_grade("4", "--class", str(tmp_path / "class"), "--csv", str(tmp_path / "grades.csv"), timeout=280)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Traceback" not in result.stdout + result.stderr
    with open(tmp_path / "grades.csv", newline="", encoding="utf-8") as handle:
        rows = {row["student"]: row for row in csv.DictReader(handle)}
    assert sorted(rows) == ["alice", "bob", "carol"]
    assert rows["alice"]["passed"] == rows["alice"]["total"] != "0" and rows["alice"]["first_failure"] == ""
    total = rows["alice"]["total"]
    assert rows["bob"]["total"] == total and 0 < int(rows["bob"]["passed"]) < int(total)
    assert "cpi_objective" in rows["bob"]["first_failure"]
    assert rows["carol"]["total"] == total and rows["carol"]["passed"] == "0"
    assert "took longer than" in rows["carol"]["first_failure"]
    lines = result.stdout.splitlines()
    table = {line.split()[0]: line for line in lines if line.split()[:1] in (["alice"], ["bob"], ["carol"])}
    assert f"{total}/{total}" in table["alice"] and "cpi_objective" in table["bob"], result.stdout
    assert "took longer than" in table["carol"], result.stdout


def test_a_test_process_that_dies_costs_one_test(tmp_path):
    (tmp_path / "ch04_cpi.py").write_text(
        textwrap.dedent(CLASS["carol"]).replace("while True:\n        pass", "return 1")
    )
    result = run_grade("4", "--verbose", impl=tmp_path, timeout=200)
    assert result.returncode == 1, result.stdout + result.stderr
    died = [line for line in result.stdout.splitlines() if "the test process died" in line]
    assert died and all("exited with code 3" in line for line in died), result.stdout
    assert "did not finish" not in result.stdout


def test_verbose_lists_every_failing_test(tmp_path):
    (tmp_path / "ch04_cpi.py").write_text(textwrap.dedent(CLASS["bob"]))
    result = run_grade("4", "--verbose", impl=tmp_path)
    assert result.returncode == 1, result.stdout + result.stderr
    line = next(line for line in result.stdout.splitlines() if line.startswith("ch04 cpi "))
    passed, total = map(int, line.split()[2].split("/"))
    detail = [line for line in result.stdout.splitlines() if line.startswith("  test_")]
    assert len(detail) == total - passed and all("cpi_objective" in line for line in detail), result.stdout


@pytest.mark.parametrize(
    "args, message",
    [
        (["--class", "/no/such/folder"], "no class folder"),
        (["--csv", "x.csv"], "--csv goes with --class"),
        (["--class", ".", "--solutions"], "leave out --solutions"),
    ],
)
def test_bad_class_arguments_get_one_line_and_exit_code_2(args, message):
    result = run_grade(*args)
    assert result.returncode == 2 and result.stdout == "", result.stdout + result.stderr
    assert result.stderr.startswith("minippo: error: ") and message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
