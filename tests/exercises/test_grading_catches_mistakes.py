"""The grading tests themselves, checked: no test passes against the untouched stubs, every deliberately wrong variant
fails at least one test and its first failure names the mistake, every other correct way of writing an exercise
(tests/exercises/right/) passes every test, every exercise function is graded, and exercises/ is what solutions/
generates.

Each check runs the grading tests in a child pytest process, the way ``minippo grade`` does.
"""

from __future__ import annotations

import ast
import importlib.util
import os
import re
from collections import defaultdict

import _harness
import numpy as np
import pytest
from make_exercises import SOLUTIONS, exercise_names, expected_exercises, transfer_names

from minippo.grading.chapters import chapter_files
from minippo.grading.supervisor import run_tests

pytestmark = pytest.mark.skipif(
    _harness.implementation() != "solutions", reason="checks the grading tests themselves, not an implementation"
)
WRONG = _harness.ROOT / "tests" / "exercises" / "wrong"


def wrong_module(chapter: str):
    spec = importlib.util.spec_from_file_location(f"_variants_{chapter}", WRONG / f"{chapter}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def variants_of(chapter: str) -> dict:
    return wrong_module(chapter).VARIANTS


def exercises_by_chapter() -> dict[str, list[str]]:
    return {
        path.stem: exercise_names(ast.parse(path.read_text(encoding="utf-8")))
        for path in sorted(SOLUTIONS.glob("ch*.py"))
    }


def test_there_are_at_least_twelve_graded_exercises_in_ten_chapters():
    chapters = exercises_by_chapter()
    functions = [name for names in chapters.values() for name in names]
    assert len(chapters) >= 10 and len(functions) >= 12, (len(chapters), functions)
    assert sorted(chapters) == sorted(path.stem[5:] for path in chapter_files().values())


def transfers_by_chapter() -> dict[str, list[str]]:
    return {
        path.stem: transfer_names(ast.parse(path.read_text(encoding="utf-8")))
        for path in sorted(SOLUTIONS.glob("ch*.py"))
    }


def test_every_chapter_from_1_to_14_has_a_transfer_task():
    chapters = {int(name[2:4]): names for name, names in transfers_by_chapter().items()}
    assert sorted(chapters) == list(range(1, 15)), (
        f"chapters without a solution module: {set(range(1, 15)) - set(chapters)}"
    )
    assert all(len(names) >= 1 for names in chapters.values()), [n for n, names in chapters.items() if not names]


def test_no_transfer_task_is_answered_in_the_book_or_in_minippo():
    """A transfer task asks for what the course never printed: the book may pose it by name, but defines it nowhere,
    and minippo's code does not name it (its solution lives in solutions/ only)."""
    pages = [path.read_text(encoding="utf-8") for path in (_harness.ROOT / "book").glob("*.md")]
    code = [path.read_text(encoding="utf-8") for path in (_harness.ROOT / "minippo").rglob("*.py")]
    for chapter, names in transfers_by_chapter().items():
        for name in names:
            assert not any(f"def {name}(" in page for page in pages), f"the book defines {chapter}.{name}"
            assert not any(name in text for text in code), f"minippo's code names {chapter}.{name}"


def test_every_transfer_task_has_wrong_and_right_variants():
    """At least three wrong variants and one right variant for each transfer task, as the grader's proof."""
    for chapter, names in transfers_by_chapter().items():
        right_path = _harness.ROOT / "tests" / "exercises" / "right" / f"{chapter}.py"
        spec = importlib.util.spec_from_file_location(f"_right_transfer_{chapter}", right_path)
        right = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(right)
        for name in names:
            wrong = [variant for variant in variants_of(chapter).values() if name in variant]
            assert len(wrong) >= 3, f"{chapter}.{name} has {len(wrong)} wrong variant(s)"
            assert any(name in variant for variant in right.VARIANTS.values()), f"{chapter}.{name} has no right variant"


def test_every_exercise_function_is_called_by_its_grading_tests():
    files = {path.stem[5:]: path.read_text(encoding="utf-8") for path in chapter_files().values()}
    for chapter, names in exercises_by_chapter().items():
        for name in names:
            assert f"student.{name}(" in files[chapter] or f"student.{name}," in files[chapter], (
                f"{chapter}.{name} is never called by test_{chapter}.py"
            )


def test_exercises_are_generated_from_the_solutions():
    """exercises/ is what solutions/ generates, byte for byte. On a student's machine (not in CI), where exercises/
    holds their work, the exercise functions must still have the solutions' signatures and contracts."""
    for name, expected in expected_exercises().items():
        text = (_harness.ROOT / "exercises" / name).read_text(encoding="utf-8")
        if os.environ.get("CI") or text == expected:
            assert text == expected, (
                f"exercises/{name} is not what solutions/{name} generates: run python tests/exercises/make_exercises.py"
            )
        else:
            assert _contracts(text) == _contracts(expected), (
                f"exercises/{name}: the exercise functions' signatures or docstrings differ from solutions/{name}"
            )


def _contracts(text: str) -> dict:
    tree = ast.parse(text)
    names = set(exercise_names(tree))
    return {
        node.name: (ast.unparse(node.args), ast.get_docstring(node))
        for node in tree.body
        if isinstance(node, ast.FunctionDef) and node.name in names
    }


@pytest.mark.timeout(600)
def test_every_grading_test_fails_against_the_untouched_stubs(tmp_path):
    # the stubs exactly as exercises/ ships them, written afresh (a student's exercises/ may hold real work by now)
    for name, text in expected_exercises().items():
        (tmp_path / name).write_text(text, encoding="utf-8")
    files = [chapter_files()[n] for n in sorted(chapter_files())]
    collected, results, note = run_tests(str(tmp_path), files, limit_s=500)
    assert not note, note
    assert len(collected) >= 100 and len(results) == len(collected), (len(collected), len(results))
    passed = [r.nodeid for r in results if r.outcome == "passed"]
    assert not passed, f"{len(passed)} grading test(s) pass without any code written: {passed[:5]}"
    skipped = [r.nodeid for r in results if r.outcome == "skipped"]
    assert not skipped, f"grading tests skipped against the stubs: {skipped[:5]}"
    unclear = [r for r in results if "is not written yet" not in r.message]
    assert not unclear, (
        f"these failures do not say that the exercise is unwritten: {[(r.nodeid, r.message) for r in unclear[:3]]}"
    )


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_every_wrong_variant_fails_at_least_one_grading_test():
    expected = {(chapter, name) for chapter in exercises_by_chapter() for name in variants_of(chapter)}
    for chapter in exercises_by_chapter():
        # two or more plausible mistakes per exercise function, where the function has room for them
        touched = defaultdict(int)
        for replaced in variants_of(chapter).values():
            for function in replaced:
                touched[function] += 1
        for function in exercise_names(ast.parse((SOLUTIONS / f"{chapter}.py").read_text(encoding="utf-8"))):
            assert touched[function] >= 2, f"{chapter}.{function} has {touched[function]} wrong variant(s)"

    files = [chapter_files()[n] for n in sorted(chapter_files())]
    # a variant skips the rest of its tests once one has failed, so each costs little beyond its first failure
    collected, results, note = run_tests("wrong", files, stop_at_first_failure=True, limit_s=800)
    assert not note, note
    outcomes = defaultdict(list)
    for result in results:
        match = re.search(r"test_(ch\d\d_\w+?)\.py::.*\[.*?wrong_([A-Za-z0-9_]+)", result.nodeid)
        assert match, f"a grading test ran without a variant: {result.nodeid}"
        outcomes[(match.group(1), match.group(2))].append(result)
    assert set(outcomes) == expected, f"variants that did not run: {sorted(expected - set(outcomes))}"
    accepted = [variant for variant, rs in outcomes.items() if not any(r.outcome == "failed" for r in rs)]
    assert not accepted, f"wrong variants that pass every grading test: {accepted}"
    # the first failure, the one the scoreboard shows, names the mistake where the variant says what it must say
    unnamed = []
    for (chapter, variant), rs in sorted(outcomes.items()):
        pattern = getattr(wrong_module(chapter), "FIRST_FAILURE", {}).get(variant)
        first = next(r for r in rs if r.outcome == "failed")
        if pattern and not re.search(pattern, first.message):
            unnamed.append(f"{chapter}:{variant}: {first.message!r} does not match {pattern!r}")
    assert not unnamed, "first failures that do not name the mistake:\n" + "\n".join(unnamed)


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_no_right_variant_is_rejected():
    files = [chapter_files()[n] for n in sorted(chapter_files())]
    collected, results, note = run_tests("right", files, limit_s=500)
    assert not note, note
    ran = {
        re.search(r"\[.*?right_([A-Za-z0-9_]+)", r.nodeid).group(1)
        for r in results
        if "right_" in r.nodeid and r.outcome != "skipped"  # a chapter without right variants skips its tests
    }
    expected = set()
    for chapter in exercises_by_chapter():
        path = _harness.ROOT / "tests" / "exercises" / "right" / f"{chapter}.py"
        if not path.exists():  # a chapter may have no other way worth showing
            continue
        spec = importlib.util.spec_from_file_location(f"_right_{chapter}", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        expected |= set(module.VARIANTS)
    assert ran == expected, f"right variants that did not run: {sorted(expected - ran)}"
    rejected = [f"{r.nodeid}: {r.message}" for r in results if r.outcome == "failed"]
    assert not rejected, "correct variants rejected by a grading test:\n" + "\n".join(rejected[:10])


# the harness's messages themselves


def _message(check, *args, **kwargs) -> str:
    with pytest.raises(AssertionError) as caught:
        check(*args, **kwargs)
    return str(caught.value)


def test_check_close_shows_more_digits_and_what_differs_when_six_agree():
    got = np.array([1.0, 2.0000002], dtype=np.float32)
    text = _message(_harness.check_close, got, [1.0, 2.0000000001], "f", "the result", 1e-9, 1e-12)
    assert "at index 1" in text and "got 2.00000024, expected 2 " in text, text
    assert "more than the tolerance" in text and "the result is float32, not float64" in text, text


def test_check_close_names_a_whole_result_off_by_one_factor():
    expected = np.array([1.0, -2.0, 3.0, 0.5])
    assert "the sign is flipped everywhere" in _message(_harness.check_close, -expected, expected, "f", "x")
    assert "n times too large" in _message(_harness.check_close, 4 * expected, expected, "f", "x")
    assert "twice the expected" in _message(_harness.check_close, 2 * expected, expected, "f", "x")
    # a gradient summed over a batch of 5 without one row per sample: the mean in its place is named with that n
    text = _message(_harness.check_close, expected / 5, expected, "f", "grad_b", n=5)
    assert "n = 5 times too small everywhere: a mean where the sum belongs" in text, text


def test_check_close_shows_the_inputs_at_the_failing_entry():
    text = _message(_harness.check_close, [0.0, 1.0], [0.0, 2.0], "f", "x", where={"r_t": [0.9, 1.21], "ε": 0.2})
    assert "at index 1 (where r_t = 1.21, ε = 0.2)" in text, text


def test_a_raising_call_is_named_with_its_input_shapes_and_line():
    module = type("module", (), {})()

    def gae(rewards, terminated):
        if terminated[0]:
            return rewards
        return rewards

    module.gae = gae
    student = _harness.Student(module, "test")
    with pytest.raises(_harness.StudentError) as caught:
        student.gae(np.zeros((3, 2)), np.zeros((3, 2), bool))
    text = str(caught.value)
    assert "gae(rewards=array (3, 2), terminated=array (3, 2) bool) raised ValueError" in text, text
    assert "np.where" in text, text


def test_check_array_and_check_scalar_want_float64():
    assert "not float32" in _message(_harness.check_array, np.zeros(2, np.float32), "f", (2,))
    assert "not int64" in _message(_harness.check_array, np.zeros(2, np.int64), "f", (2,))
    assert "not float32" in _message(_harness.check_scalar, np.float32(1.0), "f")
    assert "returned: None" in _message(_harness.check_array, None, "f", (2,))
    assert _harness.check_scalar(np.float64(2.0), "f") == 2.0 and _harness.check_scalar(2.0, "f") == 2.0
