"""What every grading test shares: which implementation it grades, and plain-English checks.

The implementation is chosen by the environment variable MINIPPO_IMPL:
- ``solutions`` (the default): the reference solutions in solutions/, so a plain ``pytest`` is green;
- ``exercises``: the student's modules in exercises/;
- ``wrong``: the deliberately wrong variants in tests/exercises/wrong/ (each test runs once per variant of its
  chapter); the instructors' proof that the tests reject them;
- a folder path: a folder holding chNN_*.py modules with the same functions (a copy of exercises/ elsewhere).

Test modules import the ``student`` fixture and ``pytest_generate_tests`` from here. (A conftest.py in this folder
would take the module name ``conftest`` from tests/conftest.py, which other tests import helpers from.)
"""

from __future__ import annotations

import copy
import functools
import importlib
import importlib.util
import os
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
IMPL_VARIABLE = "MINIPPO_IMPL"
if str(ROOT) not in sys.path:  # exercises/ and solutions/ are packages at the repository root
    sys.path.insert(0, str(ROOT))


def implementation() -> str:
    return os.environ.get(IMPL_VARIABLE, "").strip() or "solutions"


def chapter_of(module_name: str) -> str:
    """'test_ch05_clipping' -> 'ch05_clipping'."""
    return module_name.rsplit(".", 1)[-1].removeprefix("test_")


class StudentError(Exception):
    """A function under test raised; the message says which one and what it raised."""


class Broken:
    """Stands in for a module that could not be imported: every use fails the test with the reason."""

    def __init__(self, where: str, reason: str):
        self._where, self._reason = where, reason

    def __getattr__(self, name):
        pytest.fail(f"{self._where} could not be imported, so {name} cannot be graded: {self._reason}", pytrace=False)


class Student:
    """The module under test. Its functions are wrapped so that an exception names the function that raised it."""

    def __init__(self, module, where: str):
        self._module, self._where = module, where

    def __getattr__(self, name):
        try:
            value = getattr(self._module, name)
        except AttributeError:
            pytest.fail(f"{self._where} has no function {name}: keep the names of the exercise", pytrace=False)
        if not callable(value) or isinstance(value, type):
            return value

        @functools.wraps(value)
        def call(*args, **kwargs):
            try:
                return value(*args, **kwargs)
            except NotImplementedError as error:
                raise StudentError(f"{name} is not written yet (it raises NotImplementedError)") from error
            except Exception as error:  # noqa: BLE001 - any mistake in the student's code becomes a plain message
                first_line = str(error).strip().splitlines()[0] if str(error).strip() else ""
                raise StudentError(f"{name} raised {type(error).__name__}: {first_line}".rstrip(": ")) from error

        return call


def _describe(error: BaseException) -> str:
    if isinstance(error, SyntaxError):
        return f"SyntaxError on line {error.lineno}: {error.msg}"
    if "Timeout" in str(error):
        return "importing it took longer than the time limit (does it run an endless loop when imported?)"
    text = str(error).strip().splitlines()[0] if str(error).strip() else ""
    return f"{type(error).__name__}: {text}".rstrip(": ")


def _import_file(path: Path, name: str):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def load_wrong_variant(chapter: str, variant: str):
    """A fresh copy of the reference solution of ``chapter`` with the functions of one wrong variant swapped in.

    The swap is made in the copy's globals, so the solution's other functions call the wrong one too (as a student's
    ppo_update would call their own loss_and_grad).
    """
    module = _import_file(ROOT / "solutions" / f"{chapter}.py", f"_solution_{chapter}_{variant}")
    wrong = _import_file(ROOT / "tests" / "exercises" / "wrong" / f"{chapter}.py", f"_wrong_{chapter}")
    for name, function in wrong.VARIANTS[variant].items():
        setattr(module, name, function)
    return module


def wrong_variants(chapter: str) -> list[str]:
    path = ROOT / "tests" / "exercises" / "wrong" / f"{chapter}.py"
    return list(_import_file(path, f"_wrong_{chapter}").VARIANTS) if path.exists() else []


_loaded: dict[tuple, object] = {}


def load_student(chapter: str, impl: str, variant: str | None = None):
    """The module under test for ``chapter``, wrapped in Student, or a Broken stand-in that fails every test.

    The outcome is kept, so a module that fails to import (or hangs while importing) costs one test's time only.
    """
    key = (chapter, impl, variant)
    if key not in _loaded:
        _loaded[key] = _load(chapter, impl, variant)
    return _loaded[key]


def _load(chapter: str, impl: str, variant: str | None):
    if impl == "wrong":
        return Student(load_wrong_variant(chapter, variant), f"wrong variant {chapter}:{variant}")
    if impl in ("solutions", "exercises"):
        where = f"{impl}/{chapter}.py"
        path = ROOT / impl / f"{chapter}.py"
    else:
        path = Path(impl).expanduser() / f"{chapter}.py"
        where = str(path)
    if not path.exists():
        return Broken(where, "there is no such file")
    try:
        if impl in ("solutions", "exercises"):
            module = importlib.import_module(f"{impl}.{chapter}")
        else:
            module = _import_file(path, f"_graded_{chapter}")
    except KeyboardInterrupt:
        raise
    except BaseException as error:  # noqa: BLE001 - a syntax error, sys.exit or a time-out while importing
        return Broken(where, _describe(error))
    return Student(module, where)


def pytest_generate_tests(metafunc):
    """Under MINIPPO_IMPL=wrong, run every test once per wrong variant of its chapter."""
    if "student" in metafunc.fixturenames and implementation() == "wrong":
        variants = wrong_variants(chapter_of(metafunc.module.__name__))
        metafunc.parametrize("student", variants or [None], indirect=True, ids=lambda v: f"wrong_{v}")


@pytest.fixture
def student(request):
    chapter = chapter_of(request.module.__name__)
    impl = implementation()
    if impl == "wrong":
        if request.param is None:
            pytest.skip(f"{chapter} has no wrong variants")
        return load_student(chapter, impl, request.param)
    return load_student(chapter, impl)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


# checks with messages in plain words


def check_array(value, name: str, shape: tuple, what: str = "the result") -> np.ndarray:
    """``value`` is a finite float array of ``shape``, or the test fails saying what is wrong."""
    assert isinstance(value, np.ndarray), f"{name}: {what} should be a NumPy array, not {type(value).__name__}"
    assert value.shape == tuple(shape), f"{name}: {what} should have shape {tuple(shape)}, not {value.shape}"
    assert np.issubdtype(value.dtype, np.floating), f"{name}: {what} should hold floats, not {value.dtype}"
    assert np.all(np.isfinite(value)), f"{name}: {what} holds NaN or infinite numbers"
    return value


def check_scalar(value, name: str, what: str = "the value") -> float:
    assert np.ndim(value) == 0, f"{name}: {what} should be a single number, not an array of shape {np.shape(value)}"
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise AssertionError(f"{name}: {what} should be a number, not {type(value).__name__}") from None
    assert np.isfinite(number), f"{name}: {what} is NaN or infinite"
    return number


def check_close(actual, expected, name: str, what: str, rtol: float = 1e-6, atol: float = 1e-9) -> None:
    actual, expected = np.asarray(actual, dtype=np.float64), np.asarray(expected, dtype=np.float64)
    assert actual.shape == expected.shape, f"{name}: {what} should have shape {expected.shape}, not {actual.shape}"
    error = np.abs(actual - expected)
    bound = atol + rtol * np.abs(expected)
    if not np.all(error <= bound):
        worst = np.unravel_index(int(np.argmax(error - bound)), error.shape) if error.ndim else ()
        at = f" at index {tuple(int(i) for i in worst)}" if worst else ""
        raise AssertionError(
            f"{name}: {what} is wrong{at}: got {float(actual[worst]):.6g}, expected {float(expected[worst]):.6g}"
        )


def call_checking_inputs(function, name: str, *args, **kwargs):
    """Call ``function`` and fail if it changed any of its array arguments in place."""
    before = copy.deepcopy((args, kwargs))
    result = function(*args, **kwargs)
    for position, (old, new) in enumerate(zip(before[0], args)):
        _check_unchanged(old, new, name, f"argument {position + 1}")
    for key in kwargs:
        _check_unchanged(before[1][key], kwargs[key], name, f"argument {key}")
    return result


def _check_unchanged(old, new, name: str, which: str) -> None:
    if isinstance(new, np.ndarray):
        same = old.shape == new.shape and np.array_equal(old, new, equal_nan=new.dtype.kind == "f")
        assert same, f"{name} changed its input ({which}) in place: work on a copy and return new arrays"
    elif isinstance(new, (list, tuple)):
        for old_item, new_item in zip(old, new):
            _check_unchanged(old_item, new_item, name, which)
    elif isinstance(new, dict):
        for key in new:
            _check_unchanged(old[key], new[key], name, f"{which}[{key!r}]")


def numerical_gradient(f, x: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central differences (f(x + h e_i) − f(x − h e_i)) / 2h of the scalar f() for every entry of x (x is restored)."""
    grad = np.zeros(x.shape)
    flat, out = x.reshape(-1), grad.reshape(-1)
    for i in range(flat.size):
        saved = flat[i]
        flat[i] = saved + h
        up = f()
        flat[i] = saved - h
        down = f()
        flat[i] = saved
        out[i] = (up - down) / (2 * h)
    return grad
