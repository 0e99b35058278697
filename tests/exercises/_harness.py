"""What every grading test shares: which implementation it grades, and plain-English checks.

The implementation is chosen by the environment variable MINIPPO_IMPL:
- ``solutions`` (the default): the reference solutions in solutions/, so a plain ``pytest`` is green;
- ``exercises``: the student's modules in exercises/;
- ``wrong``: the deliberately wrong variants in tests/exercises/wrong/ (each test runs once per variant of its
  chapter); the instructors' proof that the tests reject them;
- ``right``: other correct ways to write the exercises, in tests/exercises/right/ (once per variant); the proof that
  the tests accept any correct implementation, not only the reference's way;
- a folder path: a folder holding chNN_*.py modules with the same functions (a copy of exercises/ elsewhere).

A student's code (``exercises`` or a folder) never runs in this process: ``load_student`` starts a worker process for it
(minippo.grading.sandbox), and RemoteStudent sends each call there and brings back only the result, so the tests, their
verdict and the grader's log stay out of its reach. The course's own code runs here: the variants always, the reference
unless MINIPPO_GRADE_ISOLATION=worker (``none`` runs a student's code here too, to debug the tests).

Test modules import the ``student`` fixture and ``pytest_generate_tests`` from here. (A conftest.py in this folder
would take the module name ``conftest`` from tests/conftest.py, which other tests import helpers from.)
"""

from __future__ import annotations

import copy
import functools
import importlib
import importlib.util
import inspect
import linecache
import os
import sys
import traceback
from pathlib import Path

import numpy as np
import pytest

from minippo.gradcheck import central_differences
from minippo.grading.chapters import VARIANT_FOLDERS
from minippo.grading.plugin import plain_exception

ROOT = Path(__file__).resolve().parents[2]
IMPL_VARIABLE = "MINIPPO_IMPL"
ISOLATION_VARIABLE = "MINIPPO_GRADE_ISOLATION"
HIDE_VARIABLE = "MINIPPO_GRADE_HIDE"  # more folders the worker must not see (the class folder), os.pathsep-separated
if str(ROOT) not in sys.path:  # exercises/ and solutions/ are packages at the repository root
    sys.path.insert(0, str(ROOT))


def implementation() -> str:
    return os.environ.get(IMPL_VARIABLE, "").strip() or "solutions"


def chapter_of(module_name: str) -> str:
    """'test_ch05_clipping' -> 'ch05_clipping'."""
    return module_name.rsplit(".", 1)[-1].removeprefix("test_")


@plain_exception
class StudentError(Exception):
    """A function under test raised; the message says which one and what it raised."""


class Broken:
    """Stands in for a module that could not be imported: every use fails the test with the reason."""

    def __init__(self, where: str, reason: str):
        self._where, self._reason = where, reason

    def __getattr__(self, name):
        pytest.fail(f"{self._where} could not be imported, so {name} cannot be graded: {self._reason}", pytrace=False)


class Student:
    """The module under test. Its functions are wrapped so that an exception names the call that raised it: the
    function, the shapes of its inputs, and the line of the student's code."""

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
                what = f"{type(error).__name__}: {first_line}".rstrip(": ")
                raise StudentError(
                    f"{describe_call(value, name, args, kwargs)} raised {what}{_line_of(error)}{_hint(what)}"
                ) from error

        return call


def describe_value(value) -> str:
    """An input as a student would want to see it in an error: arrays by shape (and dtype when not float64)."""
    if isinstance(value, np.ndarray):
        dtype = "" if value.dtype == np.float64 else f" {value.dtype}"
        return f"array {value.shape}{dtype}"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{key!r}: {describe_value(item)}" for key, item in value.items()) + "}"
    if isinstance(value, (list, tuple)):
        inner = ", ".join(describe_value(item) for item in value[:4]) + (", ..." if len(value) > 4 else "")
        return f"[{inner}]" if isinstance(value, list) else f"({inner})"
    if value is None or isinstance(value, (bool, int, float, np.number)):
        return repr(value.item() if isinstance(value, np.number) else value)
    return type(value).__name__


def describe_call(function, name: str, args, kwargs) -> str:
    """'gae(rewards=array (24, 3), ..., gamma=0.9)': which call, with which input shapes."""
    try:
        bound = inspect.signature(function).bind(*args, **kwargs)
        parts = [f"{key}={describe_value(item)}" for key, item in bound.arguments.items()]
    except (TypeError, ValueError):
        parts = [describe_value(item) for item in args] + [f"{k}={describe_value(v)}" for k, v in kwargs.items()]
    return f"{name}({', '.join(parts)})"


def _line_of(error: BaseException) -> str:
    """' (at line 12 of ch07_advantages.py: `if terminated[t]:`)', the last line of the graded code in the traceback."""
    found = ""
    for frame, line_number in traceback.walk_tb(error.__traceback__):
        filename = frame.f_code.co_filename
        if Path(filename).name.startswith("ch") and "site-packages" not in filename:
            text = linecache.getline(filename, line_number).strip()
            found = f" (at line {line_number} of {Path(filename).name}: `{text}`)" if text else ""
    return found


HINTS = {
    "truth value of an array": "a Python if, and, or, not or while on an array; use np.where, &, | and ~, which work "
    "element by element on (T,) and (T, N) alike",
    "operands could not be broadcast": "two arrays of different shapes met; check the shapes in the contract",
    "only integer scalar arrays can be converted": "an index or a size that is an array; use len(...) or .shape",
}


def _hint(what: str) -> str:
    for key, hint in HINTS.items():
        if key in what:
            return f"; {hint}"
    return ""


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


def load_wrong_variant(chapter: str, variant: str, folder: str = "wrong"):
    """A fresh copy of the reference solution of ``chapter`` with the functions of one variant (from tests/exercises/
    wrong/ or right/) swapped in.

    The swap is made in the copy's globals, so the solution's other functions call the wrong one too (as a student's
    ppo_update would call their own loss_and_grad).
    """
    module = _import_file(ROOT / "solutions" / f"{chapter}.py", f"_solution_{chapter}_{folder}_{variant}")
    wrong = _import_file(ROOT / "tests" / "exercises" / folder / f"{chapter}.py", f"_{folder}_{chapter}")
    for name, function in wrong.VARIANTS[variant].items():
        setattr(module, name, function)
    return module


def wrong_variants(chapter: str, folder: str = "wrong") -> list[str]:
    path = ROOT / "tests" / "exercises" / folder / f"{chapter}.py"
    return list(_import_file(path, f"_{folder}_{chapter}").VARIANTS) if path.exists() else []


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
    if impl in VARIANT_FOLDERS:
        return Student(load_wrong_variant(chapter, variant, impl), f"{impl} variant {chapter}:{variant}")
    if impl in ("solutions", "exercises"):
        where = f"{impl}/{chapter}.py"
        path = ROOT / impl / f"{chapter}.py"
    else:
        path = Path(impl).expanduser() / f"{chapter}.py"
        where = str(path)
    if not path.exists():
        return Broken(where, "there is no such file")
    if isolated(impl):
        try:
            return _load_isolated(chapter, path.parent, where)
        except KeyboardInterrupt:
            raise
        except BaseException as error:  # noqa: BLE001 - a time-out while the worker imports the module
            return Broken(where, _describe(error))
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


class RemoteStudent:
    """The module under test, loaded in a worker process: each call sends its arguments there and brings back the
    result (and the arguments' in-place changes). Errors read as Student's do: the call with its input shapes, the
    line of the student's code, a hint."""

    def __init__(self, sandbox, chapter: str, where: str):
        self._sandbox, self._chapter, self._where = sandbox, chapter, where

    def _report(self) -> None:
        """Pass the worker's new integrity notes to the grader's log, as notes of this chapter."""
        from minippo.grading.integrity import answer_note
        from minippo.grading.plugin import log_integrity

        for note in self._sandbox.take_notes():
            note = answer_note(note, self._chapter)
            if note:
                log_integrity(self._chapter, note)

    def _ready(self):
        """The sandbox with this module loaded (again, after a time limit or a crash ended the last worker)."""
        if not self._sandbox.loaded(self._chapter):
            try:
                error = self._sandbox.load(self._chapter)
            finally:
                self._report()
            if error:
                pytest.fail(f"{self._where} could not be imported: {error}", pytrace=False)
        return self._sandbox

    def __getattr__(self, name):
        if name.startswith("__"):
            raise AttributeError(name)
        from minippo.grading.sandbox import StudentRaised, WorkerDied

        try:
            sandbox = self._ready()
        except WorkerDied as error:
            raise StudentError(str(error)) from None
        if name not in sandbox.functions[self._chapter]:
            try:
                return sandbox.get(self._chapter, name)
            except AttributeError:
                pytest.fail(f"{self._where} has no function {name}: keep the names of the exercise", pytrace=False)
            except WorkerDied as error:
                raise StudentError(str(error)) from None

        def call(*args, **kwargs):
            try:
                return self._ready().call(self._chapter, name, args, kwargs)
            except StudentRaised as error:
                if error.not_implemented:
                    raise StudentError(f"{name} is not written yet (it raises NotImplementedError)") from None
                what = str(error)
                raise StudentError(f"{describe_call(call, name, args, kwargs)} raised {what}{error.line}{_hint(what)}")
            except WorkerDied as error:
                raise StudentError(str(error)) from None
            finally:
                self._report()

        call.__name__ = call.__qualname__ = name
        signature = sandbox.signature(self._chapter, name)
        if signature is not None:
            call.__signature__ = signature
        return call


def isolated(impl: str) -> bool:
    """Whether ``impl`` is graded through a worker process: a student's code always is, the course's own on request."""
    chosen = os.environ.get(ISOLATION_VARIABLE, "").strip()
    if chosen == "none":
        return False
    return chosen == "worker" or impl not in ("solutions", *VARIANT_FOLDERS)


_sandboxes: dict[Path, object] = {}  # one worker per student folder, for all its chapters


def _load_isolated(chapter: str, folder: Path, where: str):
    from minippo.grading.integrity import scan_source
    from minippo.grading.plugin import LOG_VARIABLE, log_integrity
    from minippo.grading.sandbox import Sandbox, WorkerDied

    if folder not in _sandboxes:
        hide = [p for p in os.environ.get(HIDE_VARIABLE, "").split(os.pathsep) if p]
        if os.environ.get(LOG_VARIABLE):
            hide.append(str(Path(os.environ[LOG_VARIABLE]).parent))
        _sandboxes[folder] = Sandbox(folder, hide=hide)
    sandbox = _sandboxes[folder]
    log_integrity(chapter, None, isolation=sandbox.isolation)
    for path in [folder / f"{chapter}.py", *sorted(folder.glob("*.py"))]:
        if path.name == f"{chapter}.py" or not path.name.startswith("ch"):
            for note in scan_source(path, chapter):
                log_integrity(chapter, f"{path.name} {note}")
    student = RemoteStudent(sandbox, chapter, where)
    try:
        error = sandbox.load(chapter)
    except WorkerDied as died:
        error = str(died)
    finally:
        student._report()
    return Broken(where, error) if error else student


def pytest_generate_tests(metafunc):
    """Under MINIPPO_IMPL=wrong (or right), run every test once per wrong (or right) variant of its chapter."""
    impl = implementation()
    if "student" in metafunc.fixturenames and impl in VARIANT_FOLDERS:
        variants = wrong_variants(chapter_of(metafunc.module.__name__), impl)
        metafunc.parametrize("student", variants or [None], indirect=True, ids=lambda v: f"{impl}_{v}")


@pytest.fixture
def student(request):
    chapter = chapter_of(request.module.__name__)
    impl = implementation()
    if impl in VARIANT_FOLDERS:
        if request.param is None:
            pytest.skip(f"{chapter} has no {impl} variants")
        return load_student(chapter, impl, request.param)
    return load_student(chapter, impl)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


# checks with messages in plain words


def check_array(value, name: str, shape: tuple, what: str = "the result") -> np.ndarray:
    """``value`` is a finite float64 array of ``shape``, or the test fails saying what is wrong."""
    assert isinstance(value, np.ndarray), (
        f"{name}: {what} should be a NumPy array of shape {tuple(shape)}, not {type(value).__name__} "
        f"(returned: {_short(value)})"
    )
    assert value.shape == tuple(shape), f"{name}: {what} should have shape {tuple(shape)}, not {value.shape}"
    assert value.dtype == np.float64, (
        f"{name}: {what} should be a float64 array (the contract's dtype), not {value.dtype}"
        + (" (an integer or boolean array: start from np.zeros(shape) or cast to float)" if value.dtype.kind in "biu"
           else " (arithmetic on float32 inputs stays float32, and np.zeros_like(x) copies x's dtype: convert the "
           "inputs with np.asarray(x, dtype=np.float64), or build the result with dtype=np.float64)")
    )  # fmt: skip
    assert np.all(np.isfinite(value)), f"{name}: {what} holds NaN or infinite numbers: {_short(value)}"
    return value


def check_scalar(value, name: str, what: str = "the value") -> float:
    """``value`` is one finite float64 number (a Python float, np.float64, or a 0-d float64 array)."""
    assert np.ndim(value) == 0, (
        f"{name}: {what} should be a single number, not {type(value).__name__} of shape {np.shape(value)} "
        f"(returned: {_short(value)})"
    )
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (float, int, np.number, np.ndarray)):
        raise AssertionError(f"{name}: {what} should be a float, not {type(value).__name__} ({_short(value)})")
    dtype = np.asarray(value).dtype
    assert dtype.kind != "f" or dtype == np.float64, (
        f"{name}: {what} should be a float64 number (a Python float), not {dtype}: use float(...)"
    )
    assert dtype.kind == "f", f"{name}: {what} should be a float, not the integer {value!r} (a count, not a mean?)"
    number = float(value)
    assert np.isfinite(number), f"{name}: {what} is NaN or infinite"
    return number


def _short(value) -> str:
    text = np.array2string(value, precision=4, threshold=8) if isinstance(value, np.ndarray) else repr(value)
    text = " ".join(text.split())
    return text if len(text) <= 80 else text[:77] + "..."


def _number(x: float, digits: int = 6) -> str:
    return f"{x:.{digits}g}"


def expect_number(
    got, expected: float, name: str, what: str, why: str = "", rtol=1e-6, atol=1e-9, alternatives=None
) -> None:
    """One number: "name: what should be expected (why), not got", with enough digits to see the difference.
    ``alternatives``: {what a plausible mistake is: the number it gives}; the message names the one ``got`` equals."""
    got = check_scalar(got, name, what) if np.ndim(got) == 0 else check_array(got, name, (1,), what)[0]
    if abs(got - expected) <= atol + rtol * abs(expected):
        return
    digits = 6
    while digits < 17 and _number(got, digits) == _number(expected, digits):
        digits += 3
    because = f" ({why})" if why else ""
    mistakes = [
        words
        for words, value in (alternatives or {}).items()
        if value is not None and abs(got - value) <= atol + rtol * abs(value)
    ]
    named = ": " + " Or ".join(f"{words}?" for words in mistakes) if mistakes else ""
    raise AssertionError(
        f"{name}: {what} should be {_number(expected, digits)}{because}, not {_number(got, digits)}{named}"
    )


def check_close(
    actual, expected, name: str, what: str, rtol: float = 1e-6, atol: float = 1e-9, where=None, n: int | None = None
) -> None:
    """``actual`` equals ``expected`` to the tolerance, or the test fails showing the worst entry: its index, the inputs
    there (``where``: a dict of name -> array of the result's shape or a number, or a function of the index giving
    text), and as many digits as it takes to see the difference. ``n``: the batch size, where the result sums over a
    batch without having one row per sample (a bias's or a shared log σ's gradient), so that a mean in place of the
    sum is named (otherwise the result's first dimension counts as n)."""
    dtype = getattr(actual, "dtype", None)
    actual, expected = np.asarray(actual, dtype=np.float64), np.asarray(expected, dtype=np.float64)
    assert actual.shape == expected.shape, f"{name}: {what} should have shape {expected.shape}, not {actual.shape}"
    error = np.abs(actual - expected)
    bound = atol + rtol * np.abs(expected)
    if np.all(error <= bound):
        return
    worst = np.unravel_index(int(np.nanargmax(np.where(np.isnan(error), np.inf, error - bound))), error.shape)
    worst = worst if error.ndim else ()
    got, want = float(actual[worst]), float(expected[worst])
    at = f" at index {tuple(int(i) for i in worst) if len(worst) > 1 else int(worst[0])}" if error.size > 1 else ""
    context = _context(where, worst)
    digits = 6
    while digits < 17 and _number(got, digits) == _number(want, digits):
        digits += 3
    detail = ""
    if digits > 6:
        detail = f" (they differ by {abs(got - want):.3g}, more than the tolerance {bound[worst]:.3g}"
        if dtype is not None and dtype != np.float64:
            detail += f"; the result is {dtype}, not float64"
        detail += ")"
    raise AssertionError(
        f"{name}: {what} is wrong{at}{context}: got {_number(got, digits)}, expected {_number(want, digits)}{detail}"
        + _pattern(actual, expected, n)
    )


def _pattern(actual: np.ndarray, expected: np.ndarray, n: int | None = None) -> str:
    """A hint when the whole result is off by one factor: the sign, n (a sum for a mean), 2 or ½."""
    if actual.size < 2:
        got, want = float(actual.reshape(-1)[0]), float(expected.reshape(-1)[0])
        if want == 0 or not np.isfinite(got):
            return ""
        factor = got / want
        if abs(factor + 1) < 1e-6:
            return " (the opposite sign)"
        if abs(factor - 2) < 1e-6 or abs(factor - 0.5) < 1e-6:
            return f" ({'twice' if factor > 1 else 'half'} the expected: a factor ½ or 2?)"
        if factor > 1.5 and abs(factor - round(factor)) < 1e-6:
            return f" ({round(factor)} times the expected: a sum over the batch where the mean belongs?)"
        return ""
    top = float(np.max(np.abs(expected)))
    scale = np.abs(expected) > 1e-4 * top
    if top == 0 or scale.sum() < 2 or not np.all(np.abs(actual[~scale]) < 1e-3 * top):
        return ""
    factors = actual[scale] / expected[scale]
    factor = float(np.median(factors))
    if not np.allclose(factors, factor, rtol=1e-4) or abs(factor - 1) < 1e-6 or abs(factor) < 1e-9:
        return ""
    n = actual.shape[0] if n is None else n
    for value, words in [
        (-1.0, "the sign is flipped everywhere"),
        (float(n), f"{n} = n times too large everywhere: a sum where the mean belongs?"),
        (1 / n, f"n = {n} times too small everywhere: a mean where the sum belongs?"),
        (2.0, "twice the expected everywhere: a factor ½ or 2?"),
        (0.5, "half the expected everywhere: a factor ½ or 2?"),
    ]:
        if abs(factor - value) < 1e-4 * abs(value):
            return f" ({words})"
    return f" (got = {factor:.4g} × expected everywhere: one constant factor off)"


def _context(where, index) -> str:
    if where is None:
        return ""
    if callable(where):
        return f" ({where(index)})"
    parts = []
    for key, value in where.items():
        value = np.asarray(value)
        if value.ndim and index:
            value = value[index] if value.ndim == len(index) else value[index[0]]
        parts.append(f"{key} = {_number(float(value), 4) if value.dtype.kind in 'fiu' else value}")
    return f" (where {', '.join(parts)})"


def call_checking_inputs(function, name: str, *args, may_alias=(), **kwargs):
    """Call ``function``; fail if it changed any of its array arguments in place, or returned one of them (or a view
    of one) where the contract asks for new arrays. ``may_alias``: positions in the result (a tuple) exempt from the
    second check, where the contract returns an input itself."""
    before = copy.deepcopy((args, kwargs))
    result = function(*args, **kwargs)
    for position, (old, new) in enumerate(zip(before[0], args)):
        _check_unchanged(old, new, name, f"argument {position + 1}")
    for key in kwargs:
        _check_unchanged(before[1][key], kwargs[key], name, f"argument {key}")
    inputs = list(_arrays(args)) + list(_arrays(kwargs))
    outputs = result if isinstance(result, tuple) else (result,)
    for position, output in enumerate(outputs):
        if position in may_alias:
            continue
        for array in _arrays(output):
            if any(np.shares_memory(array, given) for given in inputs):
                raise AssertionError(
                    f"{name} returned one of its inputs (or a view of it) instead of a new array: the caller's array "
                    "and the result would change together; return a copy"
                )
    return result


def _arrays(value):
    if isinstance(value, np.ndarray):
        yield value
    elif isinstance(value, (list, tuple)):
        for item in value:
            yield from _arrays(item)
    elif isinstance(value, dict):
        for item in value.values():
            yield from _arrays(item)


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


numerical_gradient = central_differences  # (f, x, step): ∂f/∂x, x changed in place and restored


def where_is_ratio(r: float, epsilon: float) -> str:
    """Where r lies relative to the band 1 − ε < r < 1 + ε, and, in the windows between 1 ± ε and e^±ε, how a band
    on |log r| would place it instead."""
    low, high = 1 - epsilon, 1 + epsilon
    side = "above the band" if r > high else "below the band" if r < low else "inside the band"
    text = f"{side} [{low:g}, {high:g}]: |r − 1| = {abs(r - 1):.3g} {'>' if abs(r - 1) > epsilon else '≤'} ε"
    if (abs(r - 1) > epsilon) != (abs(np.log(r)) > epsilon):
        log_side = ">" if abs(np.log(r)) > epsilon else "<"
        text += f", although |log r| = {abs(np.log(r)):.3g} {log_side} ε: the band is on r, not on log r"
    return text
