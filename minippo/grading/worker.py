"""The worker of ``minippo grade``: the process in which a student's module runs, apart from the tests that judge it.

The judge (the grading tests, through minippo.sandbox) starts it as ``python -I worker.py`` from a private copy of
minippo, in a temporary working directory, with a ``sys.path`` that holds the student's folder (a copy) and the
installed packages but not the course's repository. Only data crosses the two pipes between them: NumPy arrays (their
raw bytes, with a numeric dtype and a shape), numbers, strings and plain containers, in a JSON frame; no pickle.
Anything else stays where it is and crosses as a reference: the judge's objects (an agent, an optimizer, a config)
become proxies here whose allowed attributes and methods are reached by asking the judge, and the student's own
objects become opaque handles there, which can only be passed back.

This file imports nothing of minippo, so that it runs as a script; the judge imports it for the wire format.
"""

from __future__ import annotations

import json
import os
import struct
import sys

import numpy as np

NUMERIC_KINDS = "biufc"
MAX_FRAME = 1 << 28  # a frame larger than this is a broken or hostile peer
MAX_DEPTH = 64


class WireError(Exception):
    """A frame that does not follow the format (or a value that cannot cross)."""


# the wire format: one JSON header, then the raw bytes of every array it refers to


def pack(value, refer, blobs: list, depth: int = 0):
    """``value`` as JSON-able data, its arrays' bytes appended to ``blobs``; ``refer(obj)`` gives the reference for
    anything that is not plain data."""
    if depth > MAX_DEPTH:
        raise WireError("a value nested too deeply to send")
    if value is None or isinstance(value, (bool, str)):
        return value
    if type(value) is int or type(value) is float:
        return value
    if isinstance(value, np.ndarray) and value.dtype.kind in NUMERIC_KINDS and not value.dtype.fields:
        blobs.append(np.ascontiguousarray(value).tobytes())
        return {"$a": [len(blobs) - 1, value.dtype.str, list(value.shape)]}
    if isinstance(value, np.generic) and value.dtype.kind in NUMERIC_KINDS:
        blobs.append(value.tobytes())
        return {"$s": [len(blobs) - 1, value.dtype.str]}
    if isinstance(value, tuple):
        return {"$t": [pack(item, refer, blobs, depth + 1) for item in value]}
    if isinstance(value, list):
        return [pack(item, refer, blobs, depth + 1) for item in value]
    if isinstance(value, dict):
        return {"$d": [[pack(k, refer, blobs, depth + 1), pack(v, refer, blobs, depth + 1)] for k, v in value.items()]}
    if isinstance(value, (int, float)):  # subclasses of int and float (not bool, handled above)
        return int(value) if isinstance(value, int) else float(value)
    return refer(value)


def unpack(node, blobs: list, resolve, depth: int = 0):
    """The value ``pack`` made; ``resolve(node)`` turns a reference back into an object."""
    if depth > MAX_DEPTH:
        raise WireError("a value nested too deeply")
    if node is None or isinstance(node, (bool, int, float, str)):
        return node
    if isinstance(node, list):
        return [unpack(item, blobs, resolve, depth + 1) for item in node]
    if not isinstance(node, dict) or len(node) != 1:
        return resolve(node)
    ((tag, body),) = node.items()
    if tag == "$a":
        index, dtype, shape = body
        dtype = _numeric_dtype(dtype)
        return np.frombuffer(_blob(blobs, index), dtype=dtype).reshape([int(s) for s in shape]).copy()
    if tag == "$s":
        index, dtype = body
        return np.frombuffer(_blob(blobs, index), dtype=_numeric_dtype(dtype))[0]
    if tag == "$t":
        return tuple(unpack(item, blobs, resolve, depth + 1) for item in body)
    if tag == "$d":
        return {_key(unpack(k, blobs, resolve, depth + 1)): unpack(v, blobs, resolve, depth + 1) for k, v in body}
    return resolve(node)


def _numeric_dtype(text) -> np.dtype:
    if not isinstance(text, str) or len(text) > 8:
        raise WireError("a bad dtype")
    dtype = np.dtype(text)
    if dtype.kind not in NUMERIC_KINDS or dtype.fields:
        raise WireError(f"an array of dtype {dtype} cannot cross")
    return dtype


def _blob(blobs: list, index) -> bytes:
    if not isinstance(index, int) or not 0 <= index < len(blobs):
        raise WireError("a reference to missing array bytes")
    return blobs[index]


def _key(key):
    try:
        hash(key)
    except TypeError as error:
        raise WireError("a dict key that cannot be hashed") from error
    return key


def write_frame(fd: int, header: dict, blobs=()) -> None:
    text = json.dumps(header).encode()
    parts = [struct.pack("<QQ", len(text), len(blobs)), text]
    for blob in blobs:
        parts += [struct.pack("<Q", len(blob)), blob]
    data = memoryview(b"".join(parts))
    while data:
        written = os.write(fd, data)
        data = data[written:]


def read_exactly(fd: int, size: int) -> bytes:
    if size > MAX_FRAME:
        raise WireError("a frame too large")
    chunks, left = [], size
    while left:
        chunk = os.read(fd, min(left, 1 << 20))
        if not chunk:
            raise EOFError("the other side closed the pipe")
        chunks.append(chunk)
        left -= len(chunk)
    return b"".join(chunks)


def read_frame(fd: int) -> tuple[dict, list]:
    size, count = struct.unpack("<QQ", read_exactly(fd, 16))
    if count > 1 << 20:
        raise WireError("too many arrays in one frame")
    try:
        header = json.loads(read_exactly(fd, size))
    except (ValueError, RecursionError) as error:
        raise WireError("a frame whose header is not JSON") from error
    if not isinstance(header, dict):
        raise WireError("a frame whose header is not an object")
    blobs = [read_exactly(fd, struct.unpack("<Q", read_exactly(fd, 8))[0]) for _ in range(count)]
    return header, blobs


def arrays_in(value):
    """Every array in a value, in a fixed order (the same walk on both sides of the pipe)."""
    if isinstance(value, np.ndarray):
        if value.dtype.kind in NUMERIC_KINDS and not value.dtype.fields:
            yield value
    elif isinstance(value, (list, tuple)):
        for item in value:
            yield from arrays_in(item)
    elif isinstance(value, dict):
        for item in value.values():
            yield from arrays_in(item)


def short_repr(value) -> str:
    try:
        text = " ".join(repr(value).split())
    except Exception:  # noqa: BLE001 - a student's __repr__ may raise
        text = f"<{type(value).__name__}>"
    return text if len(text) <= 80 else text[:77] + "..."


# the worker's side


class JudgeObject:
    """An object of the judge's (an agent, an optimizer, a config): its allowed attributes and methods are reached by
    asking the judge. Arrays read from it are kept here and sent back when changed in place (``agent.grads *= s``)."""

    __slots__ = ("_ref", "_worker")

    def __init__(self, ref: int, worker: Worker):
        object.__setattr__(self, "_ref", ref)
        object.__setattr__(self, "_worker", worker)

    def __getattr__(self, name):
        if name.startswith("_"):
            raise AttributeError(name)
        return self._worker.ask({"kind": "getattr", "ref": self._ref, "name": name})

    def __setattr__(self, name, value):
        if name.startswith("_"):
            raise AttributeError(f"cannot set {name}")
        self._worker.ask({"kind": "setattr", "ref": self._ref, "name": name}, value=value)

    def __call__(self, *args, **kwargs):
        return self._worker.ask({"kind": "call", "ref": self._ref}, args=args, kwargs=kwargs)

    def __repr__(self):
        return "<an object of the grader's>"


class Worker:
    def __init__(self, read_fd: int, write_fd: int):
        self.read_fd, self.write_fd = read_fd, write_fd
        self.mine: dict[int, object] = {}  # the student's objects the judge holds handles to
        self.proxies: dict[int, JudgeObject] = {}
        self.mirrors: dict[tuple[int, str], tuple[np.ndarray, np.ndarray]] = {}  # (ref, name) -> (array, as sent)
        self.modules: dict[str, object] = {}  # the student's modules loaded so far, by name (chNN_topic)
        self.answers: dict[str, list[str]] = {}  # minippo's own versions of the exercises: {module: [names]}
        self.watched: set[str] = set()
        self.used: set[str] = set()  # the watched functions used during the current call
        self.note = lambda text: None

    # references
    def refer(self, value):
        key = id(value)
        self.mine[key] = value
        return {"$w": key, "type": type(value).__name__, "repr": short_repr(value), "callable": callable(value)}

    def resolve(self, node):
        if "$j" in node:
            ref = int(node["$j"])
            if ref not in self.proxies:
                self.proxies[ref] = JudgeObject(ref, self)
            return self.proxies[ref]
        if "$w" in node and node["$w"] in self.mine:
            return self.mine[node["$w"]]
        raise WireError("a reference to an unknown object")

    def send(self, header: dict, **values) -> None:
        blobs: list = []
        for name, value in values.items():
            header[name] = pack(value, self.refer, blobs)
        header["pushes"] = self._pushes(blobs)
        write_frame(self.write_fd, header, blobs)

    def receive(self) -> tuple[dict, list]:
        header, blobs = read_frame(self.read_fd)
        if header.get("fresh"):  # a new call: the judge's objects of the earlier ones are gone
            self.proxies.clear()
            self.mirrors.clear()
        for ref, name, node in header.get("updates", []):
            value = unpack(node, blobs, self.resolve)
            mirror = self.mirrors.get((ref, name))
            if mirror and mirror[0].shape == value.shape and mirror[0].dtype == value.dtype:
                mirror[0][...] = value
                mirror[1][...] = value
            else:
                self.mirrors[(ref, name)] = (value, value.copy())
        return header, blobs

    def _pushes(self, blobs: list) -> list:
        changed = []
        for (ref, name), (array, sent) in self.mirrors.items():
            if array.shape != sent.shape or not np.array_equal(array, sent, equal_nan=array.dtype.kind in "fc"):
                changed.append([ref, name, pack(array, self.refer, blobs)])
                sent[...] = array
        return changed

    def ask(self, request: dict, args=(), kwargs=None, value=None):
        """Ask the judge about one of its objects; its answer is the value (or the error it raised)."""
        self.send(dict(request, op="ask"), args=list(args), kwargs=kwargs or {}, value=value)
        header, blobs = self.receive()
        if header.get("op") == "answer_error":
            raise _exception(header.get("type", ""), header.get("message", ""))
        result = unpack(header.get("value"), blobs, self.resolve)
        changed = unpack(header.get("changed"), blobs, self.resolve) or []
        for given, after in zip(arrays_in((list(args), kwargs or {})), changed):
            if isinstance(after, np.ndarray) and given.shape == after.shape and given.flags.writeable:
                given[...] = after  # what the judge's method did to the array in place
        if request["kind"] == "getattr" and isinstance(result, np.ndarray):
            key = (request["ref"], request["name"])
            mirror = self.mirrors.get(key)
            if mirror is not None and mirror[0].shape == result.shape and mirror[0].dtype == result.dtype:
                return mirror[0]  # the same array each time, so a change in place is seen by the next read
            self.mirrors[key] = (result, result.copy())
        return result

    # the student's module
    def load(self, header: dict) -> None:
        import importlib.util

        path, name = header["path"], header["module"]
        try:
            spec = importlib.util.spec_from_file_location(name, path)
            module = importlib.util.module_from_spec(spec)
            sys.modules[name] = module
            spec.loader.exec_module(module)
        except BaseException as error:  # noqa: BLE001 - a syntax error, sys.exit or anything else while importing
            self.send({"op": "loaded", "error": _describe(error)})
            return
        self.modules[name] = module
        self.watch_answers()
        functions = {}
        for key, value in vars(module).items():
            if callable(value) and not isinstance(value, type) and not key.startswith("__"):
                functions[key] = _signature(value)
        self.send({"op": "loaded", "error": None, "functions": functions})

    def serve(self) -> None:
        while True:
            header, blobs = self.receive()
            op = header.get("op")
            if op == "load":
                self.load(header)
            elif op == "call":
                self.call(header, blobs)
            elif op == "get":
                self.get(header)
            elif op == "stop":
                return

    def watch_answers(self) -> None:
        """Once the student's code has imported a minippo module that holds the exercise's answer, replace those
        functions and classes (there and in the student's module) by ones that report their first use."""
        for module_name, names in self.answers.items():
            module = sys.modules.get(module_name)
            if module is None or module_name in self.watched:
                continue
            self.watched.add(module_name)
            for name in names:
                original = getattr(module, name, None)
                if original is None:
                    continue
                watched = self._watched(original, f"{module_name}.{name}")
                setattr(module, name, watched)
                for student in self.modules.values():
                    for key, value in list(vars(student).items()):
                        if value is original:
                            setattr(student, key, watched)

    def _watched(self, original, where: str):
        def report():  # once per call: the judge keeps the notes that concern the chapter of that call
            if where not in self.used:
                self.used.add(where)
                self.note(f"calls {where}")

        if isinstance(original, type):
            init = original.__init__

            def watched_init(obj, *args, **kwargs):
                report()
                init(obj, *args, **kwargs)

            original.__init__ = watched_init
            return original

        def watched(*args, **kwargs):
            report()
            return original(*args, **kwargs)

        return watched

    def get(self, header: dict) -> None:
        module, name = self.modules.get(header.get("module")), header["name"]
        if module is None or not hasattr(module, name):
            self.send({"op": "value", "missing": True})
            return
        self.send({"op": "value", "missing": False}, value=getattr(module, name))

    def call(self, header: dict, blobs: list) -> None:
        self.used.clear()
        try:
            if header.get("ref") is None:
                function = getattr(self.modules[header["module"]], header["name"])
            else:
                function = self.mine[header["ref"]]
            args = unpack(header["args"], blobs, self.resolve)
            kwargs = unpack(header["kwargs"], blobs, self.resolve)
        except Exception as error:  # noqa: BLE001
            self.send({"op": "raised", "type": type(error).__name__, "message": str(error), "line": ""})
            return
        inputs = list(arrays_in((args, kwargs)))
        before = [array.copy() for array in inputs]
        try:
            result = function(*args, **kwargs)
        except BaseException as error:  # noqa: BLE001 - every failure of the student's code goes back as words
            text = str(error).strip().splitlines()[0] if str(error).strip() else ""
            self.send(
                {
                    "op": "raised",
                    "type": type(error).__name__,
                    "message": text,
                    "line": _line_of(error),
                    "not_implemented": isinstance(error, NotImplementedError),
                    "exit": isinstance(error, (SystemExit, KeyboardInterrupt)),
                },
                changed=_changed(inputs, before),
            )
            return
        self.watch_answers()
        aliases = []
        for i, array in enumerate(arrays_in(result)):
            for k, given in enumerate(inputs):
                if np.shares_memory(array, given):
                    aliases.append([i, k])
                    break
        self.send({"op": "done", "aliases": aliases}, value=result, changed=_changed(inputs, before))


def _changed(inputs: list, before: list) -> list:
    return [
        [k, array]
        for k, (array, old) in enumerate(zip(inputs, before))
        if array.shape != old.shape or not np.array_equal(array, old, equal_nan=array.dtype.kind in "fc")
    ]


def _exception(type_name: str, message: str) -> Exception:
    kinds = {"ValueError": ValueError, "TypeError": TypeError, "AttributeError": AttributeError,
             "IndexError": IndexError, "KeyError": KeyError, "ZeroDivisionError": ZeroDivisionError}  # fmt: skip
    return kinds.get(type_name, RuntimeError)(message)


def _signature(function) -> list | None:
    import inspect

    try:
        return [
            [p.name, int(p.kind), p.default is not p.empty] for p in inspect.signature(function).parameters.values()
        ]
    except (TypeError, ValueError):
        return None


def _line_of(error: BaseException) -> str:
    """' (at line 12 of ch07_advantages.py: `if terminated[t]:`)', the last line of the graded code in the traceback."""
    import linecache
    import traceback

    found = ""
    for frame, line_number in traceback.walk_tb(error.__traceback__):
        filename = frame.f_code.co_filename
        if os.path.basename(filename).startswith("ch") and "site-packages" not in filename:
            text = linecache.getline(filename, line_number).strip()
            found = f" (at line {line_number} of {os.path.basename(filename)}: `{text}`)" if text else ""
    return found


def _describe(error: BaseException) -> str:
    if isinstance(error, SyntaxError):
        return f"SyntaxError on line {error.lineno}: {error.msg}"
    text = str(error).strip().splitlines()[0] if str(error).strip() else ""
    return f"{type(error).__name__}: {text}".rstrip(": ")


# the worker's own protection: limits, and an audit hook that refuses what a graded function never needs


def apply_limits(limits: dict) -> None:
    import resource

    names = {"cpu_s": resource.RLIMIT_CPU, "memory_bytes": resource.RLIMIT_AS, "file_bytes": resource.RLIMIT_FSIZE,
             "processes": resource.RLIMIT_NPROC, "core_bytes": resource.RLIMIT_CORE}  # fmt: skip
    for key, value in limits.items():
        if key in names and value is not None:
            # CPU: SIGXCPU at the limit, SIGKILL a little later for code that catches it
            hard = int(value) + 5 if key == "cpu_s" else int(value)
            resource.setrlimit(names[key], (int(value), hard))


REFUSED_EVENTS = ("os.fork", "os.forkpty", "os.exec", "os.posix_spawn", "os.spawn", "os.system", "subprocess.Popen",
                  "os.kill", "os.killpg", "ctypes.dlopen", "ctypes.dlsym", "ctypes.call_function", "ctypes.cdata",
                  "socket.connect", "socket.bind", "sys.setprofile", "sys.settrace", "os.chdir")  # fmt: skip


WRITING = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_TRUNC | os.O_APPEND


def install_guard(forbidden: list[str], note, interpreter=()) -> None:
    """An audit hook that refuses (and reports) opening or listing anything under ``forbidden`` (the repository, the
    other students' folders, the grader's own files), other processes' /proc entries, starting processes and foreign
    calls. ``interpreter``: the interpreter's own folders, which stay readable wherever they are (a .venv inside the
    repository) but are never written. It is a second line behind the process boundary and the namespaces, not the
    only one."""
    hidden = guarded(forbidden, interpreter)
    own_proc = (f"/proc/{os.getpid()}", "/proc/self", "/proc/thread-self")
    reported = set()

    def refuse(what: str):
        if what not in reported:
            reported.add(what)
            note(what)
        raise PermissionError(f"the grader does not allow this: {what}")

    def refused(path, writes: bool) -> bool:
        if isinstance(path, int):
            return False
        try:
            real = os.path.realpath(os.fsdecode(path))
        except (TypeError, ValueError):
            return False
        if hidden(real, writes):
            return True
        parts = real.split(os.sep)
        return len(parts) > 2 and parts[1] == "proc" and parts[2].isdigit() and not real.startswith(own_proc)

    def hook(event, args):
        if event in ("open", "os.listdir", "os.scandir"):
            writes = event == "open" and len(args) > 2 and isinstance(args[2], int) and bool(args[2] & WRITING)
            if args and refused(args[0], writes):
                refuse(f"touched {os.fsdecode(args[0]) if not isinstance(args[0], int) else args[0]}")
        elif event in ("shutil.copyfile", "os.symlink", "os.link", "os.rename", "os.remove", "os.rmdir",
                       "os.truncate", "os.chmod", "os.utime"):  # fmt: skip
            # each changes its first path (copyfile and link: their second)
            changed = args[1] if event in ("shutil.copyfile", "os.symlink", "os.link") and len(args) > 1 else args[0]
            for path, writes in ((args[0], event not in ("shutil.copyfile", "os.symlink", "os.link")), (changed, True)):
                if args and refused(path, writes):
                    refuse(f"touched {os.fsdecode(path) if not isinstance(path, int) else path}")
        elif event == "import" and args and str(args[0]).split(".")[0] in ("solutions", "_harness"):
            refuse(f"imported {args[0]}")
        elif event.startswith(REFUSED_EVENTS):
            refuse(f"used {event}")

    sys.addaudithook(hook)


def guarded(forbidden, interpreter):
    """``hidden(path, writes)``: whether the worker may not reach the resolved ``path``: anything under a folder of
    ``forbidden`` but the interpreter's own folders inside it, which it may read and not write."""
    roots = [os.path.realpath(p) for p in forbidden]
    kept = [os.path.realpath(p) for p in interpreter]

    def hidden(real: str, writes: bool = False) -> bool:
        if not any(_under(real, root) for root in roots):
            return False
        return writes or not any(_under(real, path) for path in kept)

    return hidden


def _under(path: str, root: str) -> bool:
    """Whether the resolved ``path`` is ``root`` or inside it, as paths: /x/course-venv is not inside /x/course."""
    return os.path.commonpath([path, root]) == root


def check_interpreter(interpreter) -> str | None:
    """Whether this process can read the interpreter's folders it was told of (they are mounted back into the
    namespace where the course is hidden); what is wrong in words, or None."""
    for path in interpreter:
        if not os.access(path, os.R_OK):
            return f"the worker cannot read its interpreter's {path}"
    return None


def main() -> None:
    read_fd, write_fd = int(sys.argv[1]), int(sys.argv[2])
    header, _ = read_frame(read_fd)
    interpreter = [str(p) for p in header.get("interpreter", [])]
    for path in reversed(header["path"]):
        sys.path.insert(0, path)
    hidden = guarded(header["forbidden"], interpreter)
    sys.path[:] = [p for p in sys.path if not hidden(os.path.realpath(p or "."))]
    # the interpreter runs (NumPy imported, the frame read): the grader's part of starting is done, or says why not;
    # nothing of the student's has run yet
    problem = check_interpreter(interpreter)
    write_frame(write_fd, {"op": "grader_error", "text": problem} if problem else {"op": "ready"})
    if problem:
        os._exit(0)
    worker = Worker(read_fd, write_fd)

    def note(text: str) -> None:
        write_frame(write_fd, {"op": "note", "text": text})

    worker.note = note
    worker.answers = {str(k): [str(n) for n in v] for k, v in header.get("answers", {}).items()}

    for name in header.get("preload", []):
        try:
            __import__(str(name))
        except Exception:  # noqa: BLE001 - the student's own import will say what is wrong
            pass
    import inspect  # noqa: F401 - loaded before the guard, for signatures
    import linecache  # noqa: F401
    import traceback  # noqa: F401

    apply_limits(header["limits"])
    install_guard(header["forbidden"], note, interpreter)
    worker.serve()


if __name__ == "__main__":
    main()
