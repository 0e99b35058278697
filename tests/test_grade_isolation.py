"""Grading a class that cannot be cheated: submissions that import the reference, forge or delete the grader's log,
patch the harness, pytest or NumPy's testing functions, exit early, fork, hog memory or the disk, or read another
student's folder score no more than the untouched stubs, or are flagged in the integrity column; honest ones keep
their full score. Also the CSV's cells, Gradescope's results.json and the autograder zip."""

from __future__ import annotations

import csv
import json
import os
import site
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest

from minippo.grading import chapters, reports, sandbox
from minippo.grading.gradescope import autograder_zip, gradescope_results
from minippo.grading.integrity import scan_source
from minippo.grading.supervisor import Result, run_tests

ROOT = Path(__file__).resolve().parents[1]
SOLUTION = (ROOT / "solutions" / "ch05_clipping.py").read_text(encoding="utf-8")
STUB = (ROOT / "exercises" / "ch05_clipping.py").read_text(encoding="utf-8")
# every cheat below keeps the stubs' functions, so the points can only come from the cheat
CHEAT_TAIL = STUB.replace("from __future__ import annotations\n", "")

# each: the code a submission runs on import, before the stubs (or in place of them)
CHEATS = {
    "imports_the_reference": "from solutions.ch05_clipping import *\n",
    "puts_the_repository_on_its_path": f"import sys\nsys.path.insert(0, {str(ROOT)!r})\n"
    "from solutions.ch05_clipping import *\n",
    "reads_the_reference_and_runs_it": f"exec(open({str(ROOT / 'solutions' / 'ch05_clipping.py')!r}).read())\n",
    "reads_another_student": "import glob\n"
    "exec(open(sorted(glob.glob(__CLASS__ + '/honest*/ch05_clipping.py'))[0]).read())\n",
    "forges_the_log": "import glob, json, os\n"
    "for path in glob.glob('/tmp/minippo-grade-*/results-*.jsonl') + [os.environ.get('MINIPPO_GRADE_LOG', '')]:\n"
    "    try:\n"
    "        lines = open(path).read().splitlines()\n"
    "        names = json.loads(json.loads(lines[0])['record'])['collected']\n"
    "        with open(path, 'a') as handle:\n"
    "            for name in names:\n"
    "                record = json.dumps({'nodeid': name, 'outcome': 'passed', 'message': ''})\n"
    "                handle.write(json.dumps({'record': record, 'mac': '0'}) + '\\n')\n"
    "    except Exception:\n"
    "        pass\n",
    "deletes_the_log_and_exits": "import glob, os\n"
    "for path in glob.glob('/tmp/minippo-grade-*/*'):\n"
    "    try:\n"
    "        os.remove(path)\n"
    "    except OSError:\n"
    "        pass\n"
    "os._exit(0)\n",
    "patches_the_checks": "import sys\n"
    "import numpy.testing\n"
    "numpy.testing.assert_allclose = lambda *a, **k: None\n"
    "try:\n"
    "    import _harness, pytest\n"
    "    _harness.check_close = _harness.check_array = _harness.check_scalar = lambda *a, **k: a[0]\n"
    "    pytest.fail = lambda *a, **k: None\n"
    "except Exception:\n"
    "    pass\n"
    "for module in list(sys.modules.values()):\n"
    "    if hasattr(module, 'check_close'):\n"
    "        module.check_close = lambda *a, **k: None\n",
    "forks": "import os, time\n"
    "def clip_fraction(logp, logp_old, epsilon):\n"
    "    for _ in range(32):  # bounded, in case the fork went through: 32 sleeping children\n"
    "        if os.fork() == 0:\n"
    "            time.sleep(60)\n"
    "    return 0.0\n",
    "starts_a_process": "import subprocess\n"
    "def clip_fraction(logp, logp_old, epsilon):\n"
    "    subprocess.run(['sh', '-c', 'cp -r /tmp/minippo-grade-* /tmp/stolen'])\n"
    "    return 0.0\n",
    "hogs_memory": "def clip_fraction(logp, logp_old, epsilon):\n"
    "    hog = bytearray(16 << 30)\n"
    "    return float(len(hog))\n",
    "fills_the_disk": "def clip_fraction(logp, logp_old, epsilon):\n"
    "    with open('filler', 'wb') as handle:\n"
    "        for _ in range(64):\n"
    "            handle.write(bytes(1 << 20))\n"
    "    return 0.0\n",
}
STUB_SCORE = 0  # the stubs pass no test (tests/exercises/test_grading_catches_mistakes.py holds them to that)


def write_class(folder: Path) -> None:
    for name, code in CHEATS.items():
        (folder / name).mkdir(parents=True)
        code = code.replace("__CLASS__", repr(str(folder)))
        # a cheat on import runs before the stubs; a cheating function replaces the stub's
        text = CHEAT_TAIL + "\n" + code if "def clip_fraction" in code else code + "\n" + CHEAT_TAIL
        (folder / name / "ch05_clipping.py").write_text(text, encoding="utf-8")
    (folder / "honest").mkdir()
    (folder / "honest" / "ch05_clipping.py").write_text(SOLUTION, encoding="utf-8")
    (folder / "library").mkdir()
    (folder / "library" / "ch05_clipping.py").write_text(
        SOLUTION.replace("import numpy as np", "import numpy as np\nfrom minippo.losses import clip_fraction  # noqa")
        .split("def clip_fraction")[0]
        .rstrip()
        + "\n",
        encoding="utf-8",
    )
    (folder / "=HYPERLINK(1)").mkdir()
    (folder / "=HYPERLINK(1)" / "ch05_clipping.py").write_text(STUB, encoding="utf-8")


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    folder = tmp_path_factory.mktemp("grading") / "class"
    write_class(folder)
    out = folder.parent / "grades.csv"
    result = subprocess.run(
        [sys.executable, "-m", "minippo", "grade", "5", "--class", str(folder), "--csv", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=900,
        env={k: v for k, v in os.environ.items() if k != "MINIPPO_IMPL"},
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Traceback" not in result.stdout + result.stderr
    with open(out, newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    return {row["student"]: row for row in rows}, result.stdout


@pytest.mark.slow
@pytest.mark.timeout(900)
@pytest.mark.parametrize("cheat", list(CHEATS))
def test_a_cheat_scores_no_more_than_the_stubs_or_is_flagged(graded, cheat):
    rows, _ = graded
    row = rows[cheat]
    assert int(row["total"]) > 0, row
    assert int(row["passed"]) <= STUB_SCORE or row["integrity"], row


@pytest.mark.slow  # grades a class of 14 in subprocesses (about 90 s)
@pytest.mark.timeout(900)
def test_the_cheats_that_reach_for_the_answers_are_flagged(graded):
    rows, _ = graded
    for cheat in ("imports_the_reference", "puts_the_repository_on_its_path", "reads_the_reference_and_runs_it"):
        assert rows[cheat]["integrity"], rows[cheat]
    assert "minippo.losses.clip_fraction" in rows["library"]["integrity"], rows["library"]


@pytest.mark.slow  # grades a class of 14 in subprocesses (about 90 s)
@pytest.mark.timeout(900)
def test_honest_work_keeps_its_full_score_and_a_clean_line(graded):
    rows, _ = graded
    honest = rows["honest"]
    assert honest["passed"] == honest["total"] != "0" and honest["first_failure"] == "", honest
    assert honest["integrity"] == "" and honest["isolation"] in ("namespaces", "process"), honest
    # the reference's own functions from the library pass too (it runs), but the line says so
    assert int(rows["library"]["passed"]) > 0, rows["library"]


@pytest.mark.slow  # grades a class of 14 in subprocesses (about 90 s)
@pytest.mark.timeout(900)
def test_a_formula_in_a_folder_name_stays_text(graded):
    rows, stdout = graded
    assert "'=HYPERLINK(1)" in rows, sorted(rows)
    assert all(not cell.startswith(("=", "+", "-", "@")) for row in rows.values() for cell in row.values())


def test_csv_cells_are_one_line_and_never_formulas():
    assert reports.csv_cell("=1+1") == "'=1+1"
    assert (
        reports.csv_cell("+cmd") == "'+cmd"
        and reports.csv_cell("-2") == "'-2"
        and reports.csv_cell("@SUM(A1)") == "'@SUM(A1)"
    )
    assert reports.csv_cell("two\nlines\r\n=x") == "two lines =x"
    assert reports.csv_cell("clip_fraction: fine") == "clip_fraction: fine"


# the worker itself: only data crosses, the judge's objects are reached through what their classes offer


def make_folder(tmp_path: Path, code: str, chapter: str = "ch05_clipping") -> Path:
    (tmp_path / f"{chapter}.py").write_text(textwrap.dedent(code), encoding="utf-8")
    return tmp_path


def test_arrays_and_scalars_cross_with_their_dtype_and_in_place_changes_come_back(tmp_path):
    folder = make_folder(
        tmp_path,
        """
        import numpy as np

        def f(x, y):
            x *= 2
            return x, np.float32(1.5), 3, (y, [y.astype(np.int8)])
        """,
    )
    box = sandbox.Sandbox(folder)
    try:
        assert box.load("ch05_clipping") is None
        x, y = np.arange(3.0), np.ones((2, 2))
        same_x, scalar, integer, (same_y, (small,)) = box.call("ch05_clipping", "f", (x, y), {})
        assert np.array_equal(x, [0.0, 2.0, 4.0])  # changed in place there, so here too
        assert same_x is x and same_y is y  # an input returned is the caller's own array, as in one process
        assert type(scalar) is np.float32 and scalar == 1.5 and type(integer) is int
        assert small.dtype == np.int8 and np.array_equal(small, np.ones((2, 2)))
    finally:
        box.close()


def test_the_worker_reaches_only_the_offered_attributes_of_the_judge_s_objects(tmp_path):
    folder = make_folder(
        tmp_path,
        """
        def peek(config, name):
            return getattr(config, name)

        def call(config):
            return config.validate()
        """,
    )
    from minippo.ppo import Config

    box = sandbox.Sandbox(folder)
    try:
        assert box.load("ch05_clipping") is None
        assert box.call("ch05_clipping", "peek", (Config(), "clip_epsilon"), {}) == 0.2
        # the proxy's own class, a handle of the worker's: nothing of the judge's Config
        assert isinstance(box.call("ch05_clipping", "peek", (Config(), "__class__"), {}), sandbox.StudentObject)
        for name in ("__dict__", "to_dict", "_private"):
            with pytest.raises(sandbox.StudentRaised) as raised:
                box.call("ch05_clipping", "peek", (Config(), name), {})
            assert raised.value.kind == "AttributeError"
        with pytest.raises(sandbox.StudentRaised):
            box.call("ch05_clipping", "call", (Config(),), {})
    finally:
        box.close()


def test_the_worker_calls_a_judge_object_itself_only_where_its_class_offers_call(tmp_path):
    folder = make_folder(
        tmp_path,
        """
        def call(thing, x):
            return thing(x)
        """,
        "ch10_ppo_update",
    )
    from minippo.ppo import Config

    class WatchedNormalizer:  # chapter 10's normaliser, called as a function
        offered_to_graded_code = ("__call__",)

        def __init__(self):
            self.seen = []

        def __call__(self, x):
            self.seen.append(x.copy())
            return 2.0 * x

    box = sandbox.Sandbox(folder)
    try:
        assert box.load("ch10_ppo_update") is None
        normalizer = WatchedNormalizer()
        assert np.array_equal(box.call("ch10_ppo_update", "call", (normalizer, np.ones(2)), {}), [2.0, 2.0])
        assert len(normalizer.seen) == 1  # the call ran here, in the judge's process
        with pytest.raises(sandbox.StudentRaised) as raised:
            box.call("ch10_ppo_update", "call", (Config(), np.ones(2)), {})
        assert "cannot be called" in str(raised.value)
    finally:
        box.close()


@pytest.fixture(params=["namespaces", "process"])
def isolation(request, monkeypatch):
    """Each way the grader keeps a worker apart: its own mount and PID namespaces (root with unshare), and a plain
    process with the worker's guard (an ordinary user; forced here with MINIPPO_GRADE_NO_NAMESPACES)."""
    if request.param == "namespaces":
        if not sandbox.namespaces_available():
            pytest.skip("no mount and PID namespaces on this machine (they need root, unshare and setpriv)")
        monkeypatch.delenv("MINIPPO_GRADE_NO_NAMESPACES", raising=False)
    else:
        monkeypatch.setenv("MINIPPO_GRADE_NO_NAMESPACES", "1")
    return request.param


def test_the_worker_cannot_import_the_reference_or_reach_the_repository(tmp_path, isolation):
    folder = make_folder(
        tmp_path,
        f"""
        import os, sys
        from pathlib import Path

        def where(kept):  # as paths: an environment in /x/course-venv beside /x/course is not inside it
            root = Path({str(ROOT)!r}).resolve()
            inside = [Path(p or ".").resolve() for p in sys.path if Path(p or ".").resolve().is_relative_to(root)]
            return [str(p) for p in inside if not any(p.is_relative_to(k) for k in kept)]

        def read():
            return open({str(ROOT / "README.md")!r}).read()

        def import_solutions():
            import solutions
        """,
    )
    # a class folder inside the clone (``--class submissions/`` run from it) is hidden with it
    box = sandbox.Sandbox(folder, hide=[ROOT / "tests" / "exercises"])
    try:
        assert box.isolation == isolation
        assert box.load("ch05_clipping") is None
        # nothing of the course on the worker's path but the interpreter's own packages (a .venv inside the clone)
        kept = [str(p) for p in sandbox.interpreter_paths()]
        assert box.call("ch05_clipping", "where", (kept,), {}) == []
        for name in ("read", "import_solutions"):
            with pytest.raises(sandbox.StudentRaised):
                box.call("ch05_clipping", name, (), {})
        assert any("README.md" in note or "solutions" in note for note in box.notes), box.notes
    finally:
        box.close()


def test_paths_are_compared_as_paths_not_as_strings(tmp_path):
    (tmp_path / "course").mkdir()
    (tmp_path / "course-venv").mkdir()
    assert sandbox.under(tmp_path / "course" / "x", tmp_path / "course")
    assert not sandbox.under(tmp_path / "course-venv", tmp_path / "course")
    hidden = worker_module().guarded([str(tmp_path / "course")], [str(tmp_path / "course" / ".venv")])
    assert hidden(str(tmp_path / "course" / "solutions")) and not hidden(str(tmp_path / "course-venv" / "lib"))
    assert not hidden(str(tmp_path / "course" / ".venv" / "lib")) and hidden(str(tmp_path / "course" / ".venv"), True)


def worker_module():
    from minippo.grading import worker

    return worker


@pytest.mark.skipif(os.path.realpath(sys.prefix) in ("/", "/usr", "/usr/local"), reason="a system-wide Python")
def test_an_interpreter_inside_a_hidden_folder_keeps_exactly_what_it_needs(tmp_path, isolation):
    """Hiding the interpreter's own prefix (as a .venv or a conda environment inside the clone is hidden with the
    course) leaves its executable, standard library and packages readable and nothing else of the prefix."""
    prefix = Path(sys.prefix).resolve()
    kept = sandbox.interpreter_paths()
    folders = {p.resolve() for p in prefix.iterdir() if p.is_dir()}  # a venv's lib64 is its lib
    others = sorted(p for p in folders if not any(p.is_relative_to(k) for k in kept))
    site_packages = next(p for p in map(Path, site.getsitepackages()) if p.resolve().is_relative_to(prefix))
    folder = make_folder(
        tmp_path,
        """
        import os
        import numpy as np

        def norm(x):
            return float(np.linalg.norm(x))

        def listing(path):
            return len(os.listdir(path))

        def write(path):
            with open(path, "w") as handle:
                handle.write("x")
        """,
    )
    box = sandbox.Sandbox(folder, hide=[prefix])
    try:
        assert box.load("ch05_clipping") is None
        assert box.call("ch05_clipping", "norm", (np.array([3.0, 4.0]),), {}) == 5.0
        assert box.call("ch05_clipping", "listing", (str(site_packages),), {}) > 0  # read-only, but there
        for other in others[:3]:  # the prefix's folders the interpreter does not need stay hidden
            with pytest.raises(sandbox.StudentRaised):
                box.call("ch05_clipping", "listing", (str(other),), {})
        with pytest.raises(sandbox.StudentRaised):
            box.call("ch05_clipping", "write", (str(site_packages / "minippo-written-by-a-worker.txt"),), {})
        assert not (site_packages / "minippo-written-by-a-worker.txt").exists()
    finally:
        (site_packages / "minippo-written-by-a-worker.txt").unlink(missing_ok=True)
        box.close()


LAYOUT_SCRIPT = """
import sys
from pathlib import Path
import numpy as np
from minippo.grading import sandbox
course, folder = Path(sys.argv[1]), Path(sys.argv[2])
box = sandbox.Sandbox(folder, hide=[course])
try:
    assert box.load("ch05_clipping") is None
    print(box.isolation, box.call("ch05_clipping", "norm", (np.array([3.0, 4.0]),), {}),
          box.call("ch05_clipping", "secret", (str(course / "secret.txt"),), {}))
finally:
    box.close()
"""


@pytest.mark.timeout(300)
@pytest.mark.parametrize("layout", ["venv_inside", "venv_beside_sharing_a_prefix"])
def test_a_virtual_environment_inside_or_beside_the_course_grades_the_same(tmp_path, isolation, layout):
    """The layouts students make: ``python -m venv .venv`` inside the clone (uv's, PDM's, VS Code's default), or an
    environment beside it whose name starts with the clone's (/x/course-venv). The worker starts, runs NumPy, and
    cannot read the course's files."""
    course = tmp_path / "course"
    course.mkdir()
    (course / "secret.txt").write_text("the course's own file")
    environment = course / ".venv" if layout == "venv_inside" else tmp_path / "course-venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", "--system-site-packages", str(environment)],
                   check=True, timeout=120)  # fmt: skip
    (tmp_path / "student").mkdir()
    folder = make_folder(
        tmp_path / "student",
        """
        import numpy as np

        def norm(x):
            return float(np.linalg.norm(x))

        def secret(path):
            try:
                return open(path).read()
            except OSError as error:
                return type(error).__name__
        """,
    )
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    python = str(environment / "bin" / "python")
    # the new environment sees the base interpreter's packages (not those of an environment this test runs in)
    ready = subprocess.run([python, "-c", "import numpy, minippo.grading.sandbox"], capture_output=True, env=env)
    if ready.returncode != 0:
        pytest.skip("the base interpreter has no NumPy or minippo's dependencies (.ci/grade-layouts covers this case)")
    done = subprocess.run([python, "-c", LAYOUT_SCRIPT, str(course), str(folder)],
                          capture_output=True, text=True, timeout=240, env=env)  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    shown, norm, secret = done.stdout.split()
    assert (shown, norm) == (isolation, "5.0") and secret in ("FileNotFoundError", "PermissionError"), done.stdout


def test_a_worker_that_cannot_start_is_the_grader_s_error_not_the_student_s(tmp_path, isolation, monkeypatch):
    from minippo.grading import plugin, supervisor

    log = tmp_path / "log.jsonl"
    monkeypatch.setenv(plugin.LOG_VARIABLE, str(log))
    (tmp_path / "student").mkdir()
    folder = make_folder(tmp_path / "student", "x = 1\n")
    monkeypatch.setattr(sys, "executable", str(tmp_path / "no-such-python"))  # an interpreter the worker cannot find
    box = sandbox.Sandbox(folder)
    try:
        with pytest.raises(sandbox.GraderError) as raised:
            box.load("ch05_clipping")
        text = str(raised.value)
        assert "the grader could not start" in text and "not the submission's" in text, text
        assert "sys.exit" not in text, text
        with pytest.raises(sandbox.GraderError):  # every later start says the same, without trying again
            box.start()
    finally:
        box.close()
    integrity: dict = {}
    supervisor._read_log(log, {}, plugin._key, integrity)
    assert supervisor.grader_error(integrity) == text  # the supervisor reads it from the grader's log


def test_the_source_scan_names_the_library_s_answer_and_the_reference(tmp_path):
    path = tmp_path / "ch05_clipping.py"
    path.write_text("from minippo import losses\nimport solutions\n\ndef f(x):\n    return losses.clip_fraction(x)\n")
    notes = scan_source(path, "ch05_clipping")
    assert any("imports solutions" in n for n in notes) and any("minippo.losses.clip_fraction" in n for n in notes)
    # chapter 8's reference uses chapter 6's clip_objective from the library: not chapter 8's answer
    assert scan_source(ROOT / "solutions" / "ch08_shared_network.py", "ch08_shared_network") == []


# Gradescope


def gradescope_problems(report: dict) -> list[str]:
    """What in ``report`` breaks Gradescope's documented results.json format (autograder specifications)."""
    problems = []
    top = {"score": (int, float), "execution_time": (int,), "output": (str,), "visibility": (str,),
           "stdout_visibility": (str,), "extra_data": (dict,), "tests": (list,), "leaderboard": (list,),
           "output_format": (str,), "test_output_format": (str,), "test_name_format": (str,)}  # fmt: skip
    per_test = {"score": (int, float), "max_score": (int, float), "status": (str,), "name": (str,), "number": (str,),
                "output": (str,), "tags": (list,), "visibility": (str,), "extra_data": (dict,),
                "name_format": (str,), "output_format": (str,)}  # fmt: skip
    visibilities = {"hidden", "after_due_date", "after_published", "visible"}
    for key, value in report.items():
        if key not in top or not isinstance(value, top[key]):
            problems.append(f"top-level {key}")
    if "score" not in report and not all("score" in t for t in report.get("tests", [])):
        problems.append("no score")
    for test in report.get("tests", []):
        for key, value in test.items():
            if key not in per_test or not isinstance(value, per_test[key]):
                problems.append(f"test {key}")
        if test.get("status", "passed") not in ("passed", "failed"):
            problems.append("status")
        if test.get("visibility", "visible") not in visibilities:
            problems.append("visibility")
    if report.get("stdout_visibility", "hidden") not in visibilities:
        problems.append("stdout_visibility")
    return problems


@pytest.mark.timeout(600)
def test_an_autograder_zip_grades_a_submission_laid_out_as_gradescope_does(tmp_path):
    archive = tmp_path / "autograder.zip"
    assert autograder_zip(str(archive), "https://example.org/course.git", "0123abc", "5", sys.executable) == 0
    autograder = tmp_path / "autograder"
    with zipfile.ZipFile(archive) as opened:
        assert sorted(opened.namelist()) == ["run_autograder", "setup.sh"]
        opened.extractall(autograder / "source")
        setup = opened.read("setup.sh").decode()
        assert "git clone https://example.org/course.git" in setup and "checkout 0123abc" in setup
        assert (opened.getinfo("run_autograder").external_attr >> 16) & 0o111
    script = (autograder / "source" / "run_autograder").read_text()
    # laid out as on Gradescope, under a temporary folder: the submission (uploaded as a folder), the results
    (autograder / "submission" / "my-ppo").mkdir(parents=True)
    (autograder / "submission" / "my-ppo" / "ch05_clipping.py").write_text(SOLUTION, encoding="utf-8")
    script = script.replace("/autograder", str(autograder)).replace(f"cd {autograder}/course", f"cd {ROOT}")
    env = {k: v for k, v in os.environ.items() if k != "MINIPPO_IMPL"}
    done = subprocess.run(["bash", "-c", script], capture_output=True, text=True, timeout=500, env=env)
    assert done.returncode == 0, done.stdout + done.stderr
    report = json.loads((autograder / "results" / "results.json").read_text())
    assert gradescope_problems(report) == [], report
    (test,) = report["tests"]
    assert test["score"] == test["max_score"] > 0 and test["status"] == "passed", test
    assert report["score"] == test["score"]


def test_gradescope_results_say_the_first_failure_and_the_integrity_notes():
    results = [
        Result("tests/exercises/test_ch05_clipping.py::test_a", "passed"),
        Result("tests/exercises/test_ch05_clipping.py::test_b", "failed", "clip_fraction: first"),
    ]
    report = gradescope_results(results, [5], {5: ["imports solutions"], "isolation": "process"}, 3.2)
    assert gradescope_problems(report) == []
    (test,) = report["tests"]
    assert (test["score"], test["max_score"], test["status"]) == (1.0, 2.0, "failed")
    assert test["output"].startswith("clip_fraction: first") and "imports solutions" in test["output"]


@pytest.mark.parametrize(
    "args, message",
    [
        (["--autograder-zip", "x.zip"], "needs --repo URL and --commit"),
        (["--autograder-zip", "x.zip", "--repo", "a b", "--commit", "abc1234"], "not a repository address"),
        (["--submission", "/no/such/folder"], "no submission folder"),
        (["--gradescope", "/no/such/folder/results.json"], "no folder for the results file"),
        (["--gradescope", "minippo"], "minippo is a folder"),  # before grading, not a traceback after it
    ],
)
def test_bad_gradescope_arguments_get_one_line_and_exit_code_2(args, message):
    result = subprocess.run(
        [sys.executable, "-m", "minippo", "grade", *args], cwd=ROOT, capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 2 and result.stdout == "", result.stdout + result.stderr
    assert result.stderr.startswith("minippo: error: ") and message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


# the limits: each abuse costs the call it is in, and the next call gets a working worker again

ABUSES = {
    "forks": ("import os\n\ndef f():\n    for _ in range(8):\n        os.fork()\n    return 1", "os.fork"),
    "runs_a_command": ("import subprocess\n\ndef f():\n    return subprocess.run(['true']).returncode", "subprocess"),
    "hogs_memory": ("def f():\n    return len(bytearray(16 << 30))", "MemoryError"),
    "fills_the_disk": (
        "def f():\n    with open('filler', 'wb') as out:\n        for _ in range(64):\n"
        "            out.write(bytes(1 << 20))\n    return 1",
        "File too large",
    ),
    "exits": ("import os\n\ndef f():\n    os._exit(3)", "exited with code 3"),
    "burns_the_cpu": ("def f():\n    while True:\n        pass", "SIGXCPU"),
    "calls_c": ("import ctypes\n\ndef f():\n    return ctypes.CDLL(None).getpid()", "ctypes"),
}


@pytest.mark.timeout(120)
@pytest.mark.parametrize("abuse", list(ABUSES))
def test_an_abuse_costs_its_own_call_only(tmp_path, abuse):
    code, words = ABUSES[abuse]
    folder = make_folder(tmp_path, code + "\n\ndef g(x):\n    return x + 1\n")
    box = sandbox.Sandbox(folder, limits={"cpu_s": 3})
    try:
        assert box.load("ch05_clipping") is None
        with pytest.raises((sandbox.StudentRaised, sandbox.WorkerDied)) as failed:
            box.call("ch05_clipping", "f", (), {})
        assert words in str(failed.value) + " ".join(box.notes), (str(failed.value), box.notes)
        if not box.alive():
            assert box.load("ch05_clipping") is None
        assert box.call("ch05_clipping", "g", (np.float64(1.0),), {}) == 2.0
    finally:
        box.close()


@pytest.mark.skipif(sandbox.isolation() != "namespaces", reason="no mount and PID namespaces on this machine")
def test_with_namespaces_the_repository_and_the_class_are_not_there_at_all(tmp_path):
    (tmp_path / "class" / "alice").mkdir(parents=True)
    (tmp_path / "class" / "alice" / "ch05_clipping.py").write_text(SOLUTION)
    (tmp_path / "class" / "bob").mkdir()
    # os.stat is below the worker's guard (it reports opening and listing): what it finds is what the namespace shows
    folder = make_folder(
        tmp_path / "class" / "bob",
        f"""
        import os

        def look():
            paths = [{str(ROOT / "solutions" / "ch05_clipping.py")!r}, {str(tmp_path / "class" / "alice")!r}]
            return [os.path.exists(path) for path in paths], sum(name.isdigit() for name in os.listdir("/proc"))
        """,
    )
    box = sandbox.Sandbox(folder, hide=[tmp_path / "class"])
    try:
        assert box.load("ch05_clipping") is None
        found, processes = box.call("ch05_clipping", "look", (), {})
        assert found == [False, False] and processes <= 3, (found, processes)  # the shell, the worker
    finally:
        box.close()


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_the_right_variants_keep_their_full_score_through_the_worker(tmp_path):
    """The first other correct way of writing each chapter's exercises (tests/exercises/right/), laid out as a
    student's folder: the reference module with the variant's functions swapped in, as load_wrong_variant swaps them
    in one process. (test_grading_catches_mistakes.py grades every right variant in one process; this is one per
    chapter, through the worker, each in its own pytest run.)"""
    right = ROOT / "tests" / "exercises" / "right"
    rejected, graded = [], 0
    for test_file in chapters.chapter_files().values():
        chapter = test_file.stem[5:]
        if not (right / f"{chapter}.py").exists():
            continue
        variants_text = (right / f"{chapter}.py").read_text(encoding="utf-8")
        names = subprocess.run(
            [sys.executable, "-c", f"import runpy; print(' '.join(runpy.run_path({str(right / f'{chapter}.py')!r})"
             "['VARIANTS']))"], cwd=ROOT, capture_output=True, text=True, check=True,
        ).stdout.split()  # fmt: skip
        for variant in names[:1]:
            folder = tmp_path / f"{chapter}-{variant}"
            folder.mkdir()
            # the variants' own import of the reference becomes an import of the student's module itself
            (folder / f"_right_{chapter}.py").write_text(variants_text.replace("from solutions.", "from "))
            swap = f"\nimport _right_{chapter}\n\nglobals().update(_right_{chapter}.VARIANTS[{variant!r}])\n"
            (folder / f"{chapter}.py").write_text((ROOT / "solutions" / f"{chapter}.py").read_text() + swap)
            collected, results, note = run_tests(str(folder), [test_file], limit_s=600)
            assert not note and collected, (chapter, variant, note)
            graded += 1
            rejected += [f"{chapter}:{variant}: {r.nodeid}: {r.message}" for r in results if r.outcome != "passed"]
    assert graded >= 10 and not rejected, "\n".join(rejected[:10])


def test_one_exercise_may_import_another_as_in_the_repository(tmp_path):
    make_folder(tmp_path, "def f(x):\n    return 2 * x\n")
    make_folder(tmp_path, "from exercises.ch05_clipping import f\n\ndef g(x):\n    return f(x) + 1\n", "ch06_the_min")
    box = sandbox.Sandbox(tmp_path)
    try:
        assert box.load("ch06_the_min") is None
        assert box.call("ch06_the_min", "g", (3,), {}) == 7
    finally:
        box.close()


def test_a_student_the_grader_could_not_run_is_not_graded_rather_than_given_zero(tmp_path, monkeypatch, capsys):
    """When the grader's worker does not start, the class's CSV says "not graded" with the grader's reason, the run
    exits 1, and a single student's ``minippo grade`` says the same in one line instead of a scoreboard of zeros."""
    from minippo.errors import MinippoError
    from minippo.grading import grade

    failure = "the grader could not start the process that runs the student's code: it was not found"

    def broken_run(impl, files, integrity=None, **kwargs):
        integrity["grader_error"] = [failure]
        nodeid = "tests/exercises/test_ch05_clipping.py::test_x"
        return [nodeid], [Result(nodeid, "failed", "the test crashed: " + failure)], ""

    monkeypatch.setattr(grade, "run_tests", broken_run)
    for name in ("alice", "bob"):
        (tmp_path / "class" / name).mkdir(parents=True)
        (tmp_path / "class" / name / "ch05_clipping.py").write_text(SOLUTION)
    out = tmp_path / "grades.csv"
    assert grade.grade_class(str(tmp_path / "class"), "5", csv_path=str(out)) == 1
    with open(out, newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    assert [(r["student"], r["passed"], r["first_failure"]) for r in rows] == [
        ("alice", "not graded", failure),
        ("bob", "not graded", failure),
    ]
    assert "2 of 2 students not graded" in capsys.readouterr().out
    with pytest.raises(MinippoError, match="^not graded: the grader could not start"):
        grade.grade("5", impl=str(tmp_path / "class" / "alice"))
