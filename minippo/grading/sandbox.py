"""The judge's side of grading a student's module in a worker process (minippo/grading/worker.py).

``Sandbox(folder, chapter)`` copies the student's folder and minippo into a private temporary folder and starts
``python -I worker.py`` there, with the process limits below (CPU seconds, address space, file size, processes) and,
where Linux namespaces are available (``unshare`` as root), its own mount and PID namespaces in which the course's
repository, the class folder and the grader's files are covered by empty file systems and every capability is
dropped. The running interpreter is never hidden: where its folders (a ``.venv`` inside the clone, a conda prefix)
lie inside a hidden folder, exactly those (``interpreter_paths``) are mounted back, read-only. A worker that cannot
start is the grader's failure (``GraderError``), never the student's.

``call(name, args, kwargs)`` runs one of the module's functions there and returns its result; the tests that
judge it, their verdict and the grader's log never leave this process.

What the worker may reach of the judge's objects (an agent, an optimizer, a config) is what their classes offer (see
``offers``), nothing that starts with ``_``. Arrays it reads from them are mirrored: a change it makes in
place (``agent.grads *= s``) is written back here before the judge acts on its next request, and a change made here
(``agent.backward`` writing ``agent.grads``) is sent to it with every answer.
"""

from __future__ import annotations

import atexit
import dataclasses
import functools
import inspect
import os
import select
import shutil
import signal
import site
import subprocess
import sys
import sysconfig
import tempfile
from pathlib import Path

import numpy as np

from minippo.agent import ActorCritic
from minippo.config import Config
from minippo.distributions import Categorical, DiagGaussian
from minippo.grading.chapters import course
from minippo.grading.integrity import all_answers
from minippo.grading.plugin import log_grader_error, plain_exception
from minippo.grading.worker import WireError, arrays_in, pack, read_frame, unpack, write_frame
from minippo.network import MLP
from minippo.optimizer import Adam

PACKAGE = Path(__file__).resolve().parents[1]  # minippo, copied whole for the worker
LIMITS = {
    "cpu_s": 900,  # the whole worker (one chapter), far above what the per-test time limits allow
    "memory_bytes": 4 << 30,  # address space
    "file_bytes": 16 << 20,  # the largest file it may write
    "processes": 0 if os.getuid() != 0 else None,  # no new process or thread (root is exempt from this limit)
    "core_bytes": 0,
}
STUDENT_FOLDER_BYTES = 20 << 20  # a student's folder larger than this is not copied whole
MAX_NOTES = 50

# the judge's objects whose classes offer graded code every public attribute and method they have (a dataclass, a
# config: its data, no method): minippo's agent, networks, distributions, optimizer and config, and NumPy's generator
OPEN_TYPES = (ActorCritic, MLP, Categorical, DiagGaussian, Adam, Config, np.random.Generator)
# any other class offers what it lists under this name (the tests' stand-ins do), "__call__" for the object itself
OFFERED = "offered_to_graded_code"


class StudentRaised(Exception):
    """The student's function raised; ``kind`` and ``text`` say what, ``line`` where in their code."""

    def __init__(self, kind: str, text: str, line: str, not_implemented: bool):
        super().__init__(f"{kind}: {text}".rstrip(": "))
        self.kind, self.text, self.line, self.not_implemented = kind, text, line, not_implemented


class WorkerDied(Exception):
    """The worker ended (or broke the protocol) during a call."""


@plain_exception
class GraderError(Exception):
    """The grader could not run the student's code at all (the worker did not start, or cannot read its own
    interpreter): the grader's failure, not the student's. Its message says what to do."""


STARTUP_S = 120  # how long a worker may take to say it is running before the grader gives up on it
WHAT_TO_DO = (
    "this is the grader's fault, not the submission's: run `minippo grade` again with MINIPPO_GRADE_NO_NAMESPACES=1, "
    "and report this line with `python -c \"import sys; print(sys.executable, sys.prefix)\"` to the course"
)


class StudentObject:
    """Stands in for an object of the student's that stays in the worker (it can only be passed back)."""

    def __init__(self, ref: int, text: str):
        self._ref, self._text = ref, text

    def __repr__(self):
        return self._text


@functools.cache
def _stand_in_class(name: str) -> type:
    """A class named as the student's, so that a message reads 'not Foo' as it would have in one process."""
    return type(name if name.isidentifier() else "object", (StudentObject,), {})


@functools.cache
def namespaces_available() -> bool:
    """Whether this machine lets the grader give each worker its own mount and PID namespaces (root and unshare)."""
    if os.getuid() != 0 or not (shutil.which("unshare") and shutil.which("setpriv")):
        return False
    try:
        probe = subprocess.run(
            ["unshare", "--mount", "--pid", "--fork", "--kill-child", "--mount-proc", "sh", "-c",
             "mount -t tmpfs none /mnt && exec setpriv --bounding-set=-all --inh-caps=-all --no-new-privs true"],
            capture_output=True, timeout=20,
        )  # fmt: skip
    except (OSError, subprocess.TimeoutExpired):
        return False
    return probe.returncode == 0


def isolation() -> str:
    """The words for the CSV: how far a worker is kept from the grader."""
    if os.environ.get("MINIPPO_GRADE_NO_NAMESPACES") or not namespaces_available():
        return "process"
    return "namespaces"


def under(path, root) -> bool:
    """Whether ``path`` is ``root`` or inside it, both resolved (as paths: /x/course-venv is not inside /x/course)."""
    return Path(os.path.realpath(path)).is_relative_to(os.path.realpath(root))


def interpreter_paths() -> list[Path]:
    """What the running interpreter needs to start and import its packages, resolved and none inside another: the
    folder of its executable (as called and as resolved), its venv's pyvenv.cfg, its standard library, its package
    folders (site-packages, where the editable install's finder lives) and its prefixes' lib folders (shared
    libraries), for its prefix and base prefix. A worker is started with the same interpreter, so none of these may be
    hidden from it; nothing else of a prefix is kept (its include, share, etc)."""
    found = [os.path.dirname(sys.executable), os.path.dirname(os.path.realpath(sys.executable))]
    prefixes = dict.fromkeys([sys.prefix, sys.exec_prefix, sys.base_prefix, sys.base_exec_prefix])
    found += [os.path.join(prefix, "pyvenv.cfg") for prefix in prefixes]
    names = ("stdlib", "platstdlib", "purelib", "platlib")
    for variables in ({}, {"base": sys.base_prefix, "platbase": sys.base_exec_prefix}):
        paths = sysconfig.get_paths(vars=variables)
        found += [paths[name] for name in names if name in paths]
    found += [sysconfig.get_config_var("LIBDIR") or "", *site.getsitepackages()]
    # a conda prefix's shared libraries (libpython, the BLAS NumPy links to) sit in its lib folder, which the build's
    # LIBDIR names only once conda has rewritten it
    found += [os.path.join(prefix, lib) for prefix in prefixes for lib in ("lib", "lib64")]
    resolved = []
    for path in found:
        if path and os.path.exists(path):
            real = Path(os.path.realpath(path))
            if real not in resolved:
                resolved.append(real)
    return [p for p in resolved if not any(p != q and p.is_relative_to(q) for q in resolved)]


# the mounts, in the worker's own namespaces: each folder to hide gets an empty read-only file system over it, and the
# interpreter's own paths inside it (kept) are mounted back read-only. A kept path is first bound to a place in the
# worker's own folder (stage), since it cannot be reached once its hidden folder is covered.
HIDE_SCRIPT = r"""
stage=$1; n=$2; k=$3; shift 3
i=1; while [ "$i" -le "$k" ]; do
    eval "kept=\${$((n + i))}"
    if [ -d "$kept" ]; then mkdir "$stage/$i"; else : > "$stage/$i"; fi
    mount --bind "$kept" "$stage/$i" || exit 97
    i=$((i + 1))
done
i=1; while [ "$i" -le "$n" ]; do
    eval "hidden=\${$i}"
    mount -t tmpfs -o size=64k,mode=0555 minippo-hidden "$hidden" || exit 97
    i=$((i + 1))
done
i=1; while [ "$i" -le "$k" ]; do
    eval "kept=\${$((n + i))}"
    if [ -d "$stage/$i" ]; then mkdir -p "$kept"; else mkdir -p "$(dirname "$kept")" && : > "$kept"; fi || exit 97
    mount --bind "$stage/$i" "$kept" && mount -o remount,bind,ro "$kept" || exit 97
    umount "$stage/$i" && rm -d "$stage/$i" || exit 97
    i=$((i + 1))
done
i=1; while [ "$i" -le "$n" ]; do
    eval "hidden=\${$i}"
    mount -o remount,ro "$hidden" || exit 97
    i=$((i + 1))
done
rmdir "$stage" || exit 97
shift $((n + k))
setpriv --bounding-set=-all --inh-caps=-all --no-new-privs "$@"
exit $?
"""  # not exec: the shell stays as the namespace's first process and says how the worker ended (128 + a signal)


def _copy_folder(source: Path, target: Path) -> None:
    """The student's regular files (no links, which could point at someone else's), up to STUDENT_FOLDER_BYTES."""
    target.mkdir(parents=True)
    total = 0
    for path in sorted(source.rglob("*")):
        relative = path.relative_to(source)
        if any(part.startswith(".") or part == "__pycache__" for part in relative.parts) or path.is_symlink():
            continue
        if path.is_dir():
            (target / relative).mkdir(parents=True, exist_ok=True)
        elif path.is_file():
            total += path.stat().st_size
            if total > STUDENT_FOLDER_BYTES:
                break
            (target / relative).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, target / relative)


class Sandbox:
    """One student's folder: its chapter modules loaded in one worker process, which is started again (and loads
    each module again when first used) after it dies."""

    def __init__(self, folder: Path, hide=(), limits: dict | None = None):
        self.folder = Path(folder)
        self.limits = dict(LIMITS, **(limits or {}))
        self.hide = [Path(p) for p in (course().root, *hide)]
        self.isolation = isolation()
        self.notes: list[str] = []  # what the worker reported, in order; take_notes() hands out the new ones
        self._taken = 0
        self.functions: dict[str, dict[str, list | None]] = {}  # {module: {function: its parameters}}
        self.process = None
        self.workdir = None
        self._read = self._write = None
        self._objects: dict[int, object] = {}
        self._callable: set[int] = set()
        self._mirrored: dict[tuple[int, str], np.ndarray] = {}
        self._fresh = False
        self.broken: str | None = None  # the grader's own failure to start a worker, once seen (every start repeats it)
        _ALL.append(self)

    # the process
    def start(self) -> None:
        """Start a worker and wait until it runs. Raises GraderError if it cannot: the grader's failure (its interpreter
        cannot be reached, the namespaces cannot be set up), reported as such and never blamed on the student's code,
        which has not run yet."""
        if self.broken:
            raise GraderError(self.broken)
        self.close()
        self.functions = {}
        self.workdir = Path(tempfile.mkdtemp(prefix="minippo-worker-"))
        student, lib, run = self.workdir / "student", self.workdir / "lib", self.workdir / "run"
        _copy_folder(self.folder, student)
        shutil.copytree(PACKAGE, lib / "minippo", ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        # ``from exercises.ch06_the_min import ...`` (one exercise using another, as in the repository) finds the
        # student's own modules
        (lib / "exercises").mkdir()
        (lib / "exercises" / "__init__.py").write_text(f"__path__ = [{str(student)!r}]\n", encoding="utf-8")
        run.mkdir()
        hidden = self._hidden()
        kept = [p for p in interpreter_paths() if any(under(p, h) for h in hidden)]
        from_judge, to_worker = os.pipe()  # (read end, write end)
        from_worker, to_judge = os.pipe()
        # -B: no bytecode written into the interpreter's folders, which the worker may only read
        command = [sys.executable, "-I", "-B", str(lib / "minippo" / "grading" / "worker.py"), str(from_judge),
                   str(to_judge)]  # fmt: skip
        if self.isolation == "namespaces":
            stage = self.workdir / "stage"
            stage.mkdir()
            command = ["unshare", "--mount", "--pid", "--fork", "--kill-child", "--mount-proc", "sh", "-c",
                       HIDE_SCRIPT, "sh", str(stage), str(len(hidden)), str(len(kept)), *map(str, hidden),
                       *map(str, kept), *command]  # fmt: skip
        elif os.getuid() == 0 and shutil.which("setpriv"):
            # root without its capabilities: it cannot read another process's memory or environment
            command = ["setpriv", "--bounding-set=-all", "--inh-caps=-all", "--no-new-privs", *command]
        env = {"PATH": os.environ.get("PATH", os.defpath), "HOME": str(run), "LANG": "C.UTF-8", "TMPDIR": str(run),
               "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}  # fmt: skip
        # what the worker says before it reads its first frame (an interpreter that cannot start says why here); its
        # size is bounded by the worker's file-size limit once the student's code runs
        errors = open(self.workdir / "stderr", "wb")  # noqa: SIM115 - closed below, once the worker has it
        try:
            self.process = subprocess.Popen(
                command, cwd=run, env=env, pass_fds=(from_judge, to_judge), stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL, stderr=errors, start_new_session=True,
            )  # fmt: skip
        except OSError as error:
            os.close(to_worker)
            os.close(from_worker)
            self._fail_to_start(f"{command[0]} could not be run ({error.strerror or error})")
        finally:
            errors.close()
            os.close(from_judge)
            os.close(to_judge)
        self._write, self._read = to_worker, from_worker
        # minippo itself loads native libraries (threadpoolctl) that the worker's guard refuses once the student's
        # code runs: a submission that mentions minippo gets it imported first
        mentions = any("minippo" in p.read_text(errors="replace") for p in student.rglob("*.py"))
        start = {
            "path": [str(student), str(lib)],
            "forbidden": [str(p) for p in self.hide],
            "interpreter": [str(p) for p in interpreter_paths()],
            "limits": self.limits,
            "answers": all_answers(),
            "preload": ["minippo"] if mentions else [],
        }
        try:
            write_frame(self._write, start)
            ready, _, _ = select.select([self._read], [], [], STARTUP_S)
            header, _ = read_frame(self._read) if ready else ({"op": "silent"}, [])
        except (OSError, EOFError, WireError, ValueError):
            header = {"op": "died"}
        if header.get("op") != "ready":
            self._fail_to_start(self._startup_failure(header))

    def _fail_to_start(self, reason: str) -> None:
        """Record the grader's failure to start a worker (in the grader's log too) and raise it as GraderError."""
        self.close()
        self.broken = f"the grader could not start the process that runs the student's code: {reason}; {WHAT_TO_DO}"
        log_grader_error(self.broken)
        raise GraderError(self.broken)

    def _startup_failure(self, header: dict) -> str:
        """Why a worker did not say it was running: the worker's own words, how it ended, and what it printed."""
        if header.get("op") == "grader_error":
            return str(header.get("text", "it could not read its own interpreter"))[:500]
        if header.get("op") == "silent":
            return f"it did not answer within {STARTUP_S} s"
        process = self.process
        try:
            code = process.wait(timeout=10) if process is not None else None
        except subprocess.TimeoutExpired:
            code = None
        try:
            said = (self.workdir / "stderr").read_bytes()[-4000:].decode("utf-8", "replace").strip().splitlines()
        except OSError:
            said = []
        last = said[-1].strip() if said else ""
        how = {None: "it stopped answering", 97: "the course's files could not be hidden from it",
               126: f"{sys.executable} could not be run (exit code 126)",
               127: f"{sys.executable} was not found (exit code 127)"}  # fmt: skip
        reason = how.get(code) or f"it exited with code {code}"
        return f"{reason} before it ran anything ({last[:300]})" if last else f"{reason} before it ran anything"

    def load(self, chapter: str) -> str | None:
        """Import the student's ``chapter`` module in the worker (starting one if needed); the import's error in
        words, or None."""
        if not self.alive():
            self.start()
        try:
            path = self.workdir / "student" / f"{chapter}.py"
            self._send({"op": "load", "module": chapter, "path": str(path)})
            header, _ = self._receive(("loaded",))
        except BaseException:
            self.close()
            raise
        if header.get("error"):
            return str(header["error"])
        self.functions[chapter] = header.get("functions") or {}
        return None

    def loaded(self, chapter: str) -> bool:
        return self.alive() and chapter in self.functions

    def take_notes(self) -> list[str]:
        new = self.notes[self._taken :]
        self._taken = len(self.notes)
        return new

    def _hidden(self) -> list[Path]:
        """The folders to cover in the worker's mount namespace, resolved: those that exist, do not hold the worker's
        own folder and are not inside another one (covered with it)."""
        found: list[Path] = []
        for path in self.hide:
            real = Path(os.path.realpath(path))
            if real.is_dir() and real != Path("/") and real not in found and not under(self.workdir, real):
                found.append(real)
        return [p for p in found if not any(p != q and under(p, q) for q in found)]

    def alive(self) -> bool:
        return self.process is not None and self.process.poll() is None

    def close(self) -> None:
        if self.process is not None:
            if self.process.poll() is None:
                try:
                    os.killpg(self.process.pid, signal.SIGKILL)
                except (ProcessLookupError, PermissionError):
                    pass
            try:
                self.process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                pass
            self.process = None
        for fd in (self._write, self._read):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._read = self._write = None
        if self.workdir is not None:
            shutil.rmtree(self.workdir, ignore_errors=True)
            self.workdir = None

    def _death(self) -> str:
        process = self.process
        try:
            code = process.wait(timeout=5) if process is not None else None
        except subprocess.TimeoutExpired:
            code = None
        self.close()
        if code is None:
            return "the process running it stopped answering"
        if code < 0:
            return self._death_by_signal(code)
        if code == 97:  # only the namespace's shell exits with it, before the worker starts
            return "the grader could not hide the course's files from it (the grader's fault, not the code's)"
        if self.isolation == "namespaces" and 128 < code < 128 + 65:
            code = 128 - code  # the shell's way of saying "killed by signal code - 128"
            return self._death_by_signal(code)
        return f"it exited with code {code}: does the code call sys.exit or os._exit?"

    @staticmethod
    def _death_by_signal(code: int) -> str:
        try:
            name = signal.Signals(-code).name
            return f"killed by signal {name}" + (": it used up its CPU time" if name == "SIGXCPU" else "")
        except ValueError:
            return f"killed by signal {-code}"

    # talking to the worker
    def _send(self, header: dict, **values) -> None:
        blobs: list = []
        for name, value in values.items():
            header[name] = pack(value, self._refer, blobs)
        if self._fresh:
            header["fresh"], self._fresh = True, False
        header["updates"] = self._updates(blobs)
        write_frame(self._write, header, blobs)

    def _receive(self, ends: tuple) -> tuple[dict, list]:
        """Read frames (answering the worker's questions about the judge's objects) until one whose op is in
        ``ends``; raises WorkerDied if the worker ends or breaks the protocol."""
        while True:
            try:
                if self._read is None:
                    raise EOFError
                select.select([self._read], [], [])
                header, blobs = read_frame(self._read)
            except (EOFError, OSError, WireError, ValueError) as error:
                reason = self._death()
                if isinstance(error, WireError):
                    reason = f"it broke the grader's protocol ({error})"
                raise WorkerDied(f"the test process died while running it ({reason})") from None
            op = header.get("op")
            if op == "note":
                text = str(header.get("text", ""))[:300]
                if text not in self.notes and len(self.notes) < MAX_NOTES:
                    self.notes.append(text)
                continue
            try:
                self._apply_pushes(header.get("pushes") or [], blobs)
            except (WireError, ValueError, TypeError, KeyError) as error:
                self.close()
                raise WorkerDied(f"the test process died while running it (it broke the grader's protocol: {error})")
            if op in ends:
                return header, blobs
            if op == "ask":
                self._answer(header, blobs)
                continue
            self.close()
            raise WorkerDied("the test process died while running it (it broke the grader's protocol)")

    # the judge's objects, as the worker sees them
    def _refer(self, value):
        if isinstance(value, StudentObject):
            return {"$w": value._ref}
        ref = id(value)
        self._objects[ref] = value
        return {"$j": ref}

    def _resolve(self, node):
        if "$w" in node:
            return _stand_in_class(str(node.get("type", "object")))(node["$w"], str(node.get("repr", ""))[:200])
        if "$j" in node and node["$j"] in self._objects:
            return self._objects[node["$j"]]
        raise WireError("a reference to an object the grader does not know")

    @staticmethod
    def _allowed(value, name: str) -> bool:
        return not name.startswith("_") and offers(value, name)

    @staticmethod
    def _allowed_call(value) -> bool:
        """Whether the worker may call the judge's object itself (an observation normaliser)."""
        return offers(value, "__call__")

    def _answer(self, header: dict, blobs: list) -> None:
        try:
            ref, kind = header.get("ref"), header.get("kind")
            if ref not in self._objects:
                raise AttributeError("that object of the grader's is no longer there")
            target = self._objects[ref]
            if kind in ("getattr", "setattr"):
                name = str(header.get("name"))
                if not self._allowed(target, name):
                    raise AttributeError(f"the grader's {type(target).__name__} does not offer {name} to graded code")
                if kind == "setattr":  # only an array for an array (agent.params = new values, say)
                    value = unpack(header.get("value"), blobs, self._resolve)
                    if not (isinstance(getattr(target, name, None), np.ndarray) and isinstance(value, np.ndarray)):
                        raise AttributeError(f"graded code may not set {name} of the grader's {type(target).__name__}")
                    setattr(target, name, value)
                    self._mirrored.pop((ref, name), None)
                value = getattr(target, name)
                if isinstance(value, np.ndarray):
                    self._mirrored[(ref, name)] = value.copy()
                elif callable(value) and not isinstance(value, type):
                    self._callable.add(id(value))
            elif kind == "call":
                if ref not in self._callable and not self._allowed_call(target):
                    raise TypeError("that object of the grader's cannot be called")
                args = unpack(header.get("args"), blobs, self._resolve)
                kwargs = unpack(header.get("kwargs"), blobs, self._resolve)
                if not isinstance(args, list) or not isinstance(kwargs, dict):
                    raise TypeError("bad arguments")
                value = target(*args, **{str(k): v for k, v in kwargs.items()})
                # the arguments as the method left them (rng.shuffle(order) works in place), for the worker's copies
                self._send({"op": "answer"}, value=value, changed=list(arrays_in((args, kwargs))))
                return
            else:
                raise TypeError("a question the grader does not answer")
        except Exception as error:  # noqa: BLE001 - the error goes back to the student's code, which may handle it
            self._send({"op": "answer_error", "type": type(error).__name__, "message": str(error)})
            return
        self._send({"op": "answer"}, value=value)

    def _updates(self, blobs: list) -> list:
        """The mirrored arrays that changed here since the worker last saw them."""
        changed = []
        for (ref, name), seen in self._mirrored.items():
            current = getattr(self._objects[ref], name, None)
            if not isinstance(current, np.ndarray):
                continue
            if current.shape != seen.shape or not np.array_equal(current, seen, equal_nan=current.dtype.kind in "fc"):
                changed.append([ref, name, pack(current, self._refer, blobs)])
                self._mirrored[(ref, name)] = current.copy()
        return changed

    def _apply_pushes(self, pushes: list, blobs: list) -> None:
        """Write the worker's in-place changes of mirrored arrays into the judge's own arrays."""
        for ref, name, node in pushes:
            if (ref, name) not in self._mirrored:
                continue
            value = unpack(node, blobs, self._resolve)
            current = getattr(self._objects[ref], name, None)
            if (
                isinstance(current, np.ndarray)
                and isinstance(value, np.ndarray)
                and current.shape == value.shape
                and current.flags.writeable
            ):
                current[...] = value
                self._mirrored[(ref, name)] = current.copy()

    # what the tests use
    def call(self, chapter: str, name: str, args: tuple, kwargs: dict):
        """Call the student's ``name`` with these arguments; its result, with every array argument it changed in place
        changed here too. Raises StudentRaised, or WorkerDied (after which the next call starts a new worker)."""
        self._objects.clear()
        self._callable.clear()
        self._mirrored.clear()
        self._fresh = True
        try:
            self._send({"op": "call", "module": chapter, "name": name}, args=list(args), kwargs=dict(kwargs))
            header, blobs = self._receive(("done", "raised"))
            inputs = list(arrays_in((list(args), kwargs)))
            changed = unpack(header.get("changed", []), blobs, self._resolve) or []
            for k, value in changed:
                target = inputs[int(k)] if 0 <= int(k) < len(inputs) else None
                if target is not None and target.shape == value.shape and target.flags.writeable:
                    target[...] = value
            if header["op"] == "raised":
                raise StudentRaised(
                    str(header.get("type", "Exception")),
                    str(header.get("message", "")),
                    str(header.get("line", "")),
                    bool(header.get("not_implemented")),
                )
            result = unpack(header.get("value"), blobs, self._resolve)
            aliases = {int(i): inputs[int(k)] for i, k in header.get("aliases", []) if 0 <= int(k) < len(inputs)}
            return _swap_arrays(result, aliases) if aliases else result
        except (StudentRaised, WorkerDied):
            raise
        except (WireError, ValueError, TypeError, KeyError, IndexError) as error:
            self.close()
            raise WorkerDied(f"the test process died while running it (it broke the grader's protocol: {error})")
        except BaseException:  # a time limit (or anything else) in the middle of a call: that worker is done
            self.close()
            raise
        finally:
            self._objects.clear()
            self._callable.clear()
            self._mirrored.clear()

    def get(self, chapter: str, name: str):
        """A module attribute that is not a function (a constant); raises AttributeError when there is none."""
        self._send({"op": "get", "module": chapter, "name": name})
        header, blobs = self._receive(("value",))
        if header.get("missing"):
            raise AttributeError(name)
        return unpack(header.get("value"), blobs, self._resolve)

    def signature(self, chapter: str, name: str) -> inspect.Signature | None:
        described = self.functions.get(chapter, {}).get(name)
        if not described:
            return None
        try:
            return inspect.Signature(
                [
                    inspect.Parameter(
                        str(p), inspect._ParameterKind(int(kind)), default=None if has else inspect._empty
                    )
                    for p, kind, has in described
                ]
            )
        except (ValueError, TypeError):
            return None


def offers(value, name: str) -> bool:
    """Whether the judge's object ``value`` offers graded code its attribute or method ``name`` ("__call__": the object
    itself, to call): an object of OPEN_TYPES, whatever it has; any other, what its class lists under OFFERED (a test's
    stand-in: ``offered_to_graded_code = ("step", "reset")``); nothing else crosses but as a handle."""
    listed = getattr(type(value), OFFERED, None)
    if listed is not None:
        return name in listed
    if not isinstance(value, OPEN_TYPES):
        return False
    if name == "__call__":
        return callable(value)
    if dataclasses.is_dataclass(value):
        return not callable(getattr(value, name, None))
    return hasattr(value, name)


def _swap_arrays(value, aliases: dict, counter=None):
    """``value`` with its i-th array (in arrays_in's order) replaced by aliases[i]: the judge's own input array (or a
    view of it), where the student's function returned one of its inputs."""
    counter = counter if counter is not None else [0]
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "biufc" or value.dtype.fields:
            return value
        i = counter[0]
        counter[0] += 1
        if i not in aliases:
            return value
        given = aliases[i]
        if given.shape == value.shape and given.dtype == value.dtype:
            return given
        return given.reshape(-1)[: value.size].reshape(value.shape) if given.size >= value.size else value
    if isinstance(value, tuple):
        return tuple(_swap_arrays(item, aliases, counter) for item in value)
    if isinstance(value, list):
        return [_swap_arrays(item, aliases, counter) for item in value]
    if isinstance(value, dict):
        return {key: _swap_arrays(item, aliases, counter) for key, item in value.items()}
    return value


_ALL: list[Sandbox] = []


@atexit.register
def _close_all() -> None:
    for sandbox in _ALL:
        sandbox.close()
