"""What a page executed by tools/check_claims.py calls where its asserts stood: each claim's verdict and slack.

check_claims rewrites ``assert a < b and np.all(c > d)`` into ``__book_claim__(lambda: __claim_compare__(...) and
np.all(__claim_compare__(...)), key)``. Every ordered comparison of the claim's conjunction (``<``, ``<=``, ``>``,
``>=``; inside ``and``, ``all``/``any`` and their NumPy spellings) is an *atom* with a number of its own, and records
its *slack*: how far the comparison was from flipping, as a pair: in the units of the compared values (``b - a`` for ``a
< b``), and on a log scale where both sides have one sign (``log(b / a)``), each the smallest over an array's elements
(the largest under ``any``) and over the times a loop evaluates it. Equalities, memberships, ``not`` and ``or`` are
taken as they are: they hold or fail, with no slack.

A claim's slack on one draw says little; its spread over draws says how far the next draw may move it, which is what
check_claims judges. The *margin* written beside each verdict is the tightest atom's slack relative to the larger of
its two sides (0.25: a quarter of the compared value's size was to spare), for a reader of one draw.

This file is executed as the first cell of the page's kernel (its source, with ``CLAIMS_LOG`` set), and imported by
the tests; it needs NumPy only. It also notes which of the course's files the page reads or imports (an audit hook on
``open``, and ``sys.modules``): check_claims fingerprints a page's rows with them, so that a row is known to come from
the code and data the page runs today.
"""

import json
import math
import operator
import os
import sys

CLAIMS_LOG = None  # the JSON-lines file a kernel appends its verdicts to; set by check_claims in the kernel's copy

_ORDERED = {"<": operator.lt, "<=": operator.le, ">": operator.gt, ">=": operator.ge}
_OTHER = {
    "==": operator.eq,
    "!=": operator.ne,
    "is": operator.is_,
    "is not": operator.is_not,
    "in": lambda a, b: a in b,
    "not in": lambda a, b: a not in b,
}
_evaluation: dict[int, tuple[str, list]] = {}  # atom → ("min" or "max", its _slack()s in this evaluation)


def _slack(op: str, left, right, reduce: str = "min") -> tuple[float, float, float | None] | None:
    """(slack, relative slack, log slack) of ``left op right``, each the smallest over elements (the largest when
    ``reduce`` is "max", under ``any``); None when the sides are not numbers. The log slack is the slack on a log
    scale, log(b / a) for 0 < a < b (log(a / b) when both are negative), and None unless the two sides have one sign
    everywhere: for such quantities (a KL, a ratio of two losses, a count) a threshold is a factor away, not a
    difference."""
    import numpy as np

    try:
        a = np.asarray(left, dtype=np.float64)
        b = np.asarray(right, dtype=np.float64)
    except (TypeError, ValueError):
        return None
    if a.dtype.kind != "f" or b.dtype.kind != "f":
        return None
    with np.errstate(invalid="ignore", divide="ignore"):
        gap = (b - a) if op in ("<", "<=") else (a - b)
        scale = np.maximum(np.abs(a), np.abs(b))
        relative = np.where(scale > 0, gap / np.where(scale > 0, scale, 1.0), 0.0)
    if gap.size == 0:
        return None
    pick = np.max if reduce == "max" else np.min
    low, high = (a, b) if op in ("<", "<=") else (b, a)
    logged = None
    if np.all(low > 0) and np.all(high > 0):
        logged = float(pick(np.log(high) - np.log(low)))
    elif np.all(low < 0) and np.all(high < 0):
        logged = float(pick(np.log(-low) - np.log(-high)))
    return float(pick(gap)), float(pick(relative)), logged


def __claim_compare__(first_atom: int, reduce: str, ops: tuple, *operands):
    """``operands[0] ops[0] operands[1] ops[1] …`` as Python evaluates it, recording each ordered pair's slack."""
    outcome = True
    for i, (op, left, right) in enumerate(zip(ops, operands, operands[1:])):
        if op in _ORDERED:
            result = _ORDERED[op](left, right)
            slack = _slack(op, left, right, reduce)
            if slack is not None:
                _evaluation.setdefault(first_atom + i, (reduce, []))[1].append(slack)
        else:
            result = _OTHER[op](left, right)
        if len(ops) == 1:
            return result  # an array stays an array, for np.all and .all()
        outcome = outcome and bool(result)
        if not outcome:
            return False
    return outcome


def __book_claim__(condition, key):
    """Evaluates one claim (a lambda of its instrumented condition) and appends its verdict, slacks and margin."""
    _evaluation.clear()
    try:
        verdict = "held" if bool(condition()) else "failed"
    except Exception as error:  # the condition raised: its verdict names the exception
        verdict = "error: " + type(error).__name__
    slacks, relatives = {}, []
    for atom, (reduce, values) in _evaluation.items():  # an atom evaluated several times (under all or any)
        pick = max if reduce == "max" else min
        logs = [logged for _, _, logged in values]
        slacks[atom] = [
            _number(pick(slack for slack, _, _ in values)),
            None if None in logs else _number(pick(logs)),
        ]
        relatives.append(pick(relative for _, relative, _ in values))
    margin = min(relatives) if relatives else None
    entry = {
        "key": key,
        "verdict": verdict,
        "slacks": {str(a): v for a, v in slacks.items()},
        "margin": _number(margin),
    }
    if CLAIMS_LOG is not None:
        with open(CLAIMS_LOG, "a", encoding="utf-8") as handle:
            handle.write(json.dumps(entry) + "\n")
    return entry


def _number(x):
    return None if x is None or not math.isfinite(x) else x


_read: set[str] = set()


def __claims_watch__(root: str) -> None:
    """Notes every file under ``root`` that the kernel opens for reading from now on."""
    prefix = os.path.join(os.path.realpath(root), "")

    def hook(event, args):
        if event == "open" and isinstance(args[0], (str, bytes, os.PathLike)):
            mode = args[1] if len(args) > 1 and isinstance(args[1], str) else "r"
            if not any(c in mode for c in "wax+"):
                path = os.path.realpath(os.fsdecode(args[0]))
                if path.startswith(prefix):
                    _read.add(path)

    sys.addaudithook(hook)


def __claims_files__(root: str) -> list[str]:
    """The files under ``root`` the page read or imported (a module by its source, not its cached bytecode), relative
    to ``root``, sorted; appended to CLAIMS_LOG."""
    root = os.path.realpath(root)
    paths = set(_read)
    for module in list(sys.modules.values()):
        file = getattr(module, "__file__", None)
        if file:
            paths.add(os.path.realpath(file))
    kept = sorted(
        os.path.relpath(p, root)
        for p in paths
        if p.startswith(os.path.join(root, "")) and "__pycache__" not in p and "_build" not in p and os.path.isfile(p)
    )
    if CLAIMS_LOG is not None:
        with open(CLAIMS_LOG, "a", encoding="utf-8") as handle:
            handle.write(json.dumps({"files": kept}) + "\n")
    return kept
