"""The library and the lab apart: minippo imports nothing of the benchmarks and has no import cycle, no benchmark
file or page edits sys.path to reach another, and importing minippo changes nothing in the process."""

import ast
import importlib.util
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def imports_of(path: Path) -> set[str]:
    """The modules a file imports, as written (``from minippo import losses`` counts as minippo.losses)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names |= {f"{node.module}.{alias.name}" for alias in node.names}
    return names


def module_files() -> dict[str, Path]:
    """Every module of minippo, its subpackages' too, by its dotted name (minippo.lm.rlhf)."""
    return {
        ".".join(path.relative_to(ROOT).with_suffix("").parts): path
        for path in (ROOT / "minippo").rglob("*.py")
        if path.stem != "__init__"
    }


def test_minippo_has_no_import_cycle_and_imports_no_benchmark():
    modules = module_files()
    graph = {name: {other for other in imports_of(path) if other in modules} for name, path in modules.items()}
    assert not any(name.startswith("benchmarks") for path in modules.values() for name in imports_of(path))

    def visit(name, trail):
        assert name not in trail, "import cycle: " + " -> ".join([*trail, name])
        for other in graph[name]:
            visit(other, [*trail, name])

    for name in graph:
        visit(name, [])


def test_the_top_level_is_the_rl_library_and_imports_no_room():
    """The language-model family and the book's toys live in rooms of their own, which the RL core never reaches."""
    rooms = ("minippo.lm", "minippo.toys")

    def in_a_room(name: str) -> bool:
        return any(name == room or name.startswith(room + ".") for room in rooms)

    assert any(in_a_room(name) for name in module_files()), "the rooms moved: update this test"
    for path in (ROOT / "minippo").glob("*.py"):
        reached = sorted(name for name in imports_of(path) if in_a_room(name))
        assert reached == [], f"{path.name} imports {reached}"
    top = {path.stem for path in (ROOT / "minippo").glob("*.py")}
    assert not top & {"language", "reward_model", "rlhf", "grpo", "dpo", "corridor"}


def test_a_cycle_would_be_seen(tmp_path):
    (tmp_path / "a.py").write_text("from minippo import b\n")
    assert "minippo.b" in imports_of(tmp_path / "a.py")


def test_no_benchmark_file_or_page_edits_sys_path():
    files = [*(ROOT / "benchmarks").rglob("*.py"), *(ROOT / "book").glob("*.md"), ROOT / "book" / "_pages.py"]
    offenders = [str(path.relative_to(ROOT)) for path in files if "sys.path.insert" in path.read_text()]
    assert offenders == []


def test_importing_minippo_sets_no_environment_variable_and_no_thread_limit():
    probe = (
        "import os, numpy, gymnasium, mujoco, matplotlib.pyplot, tqdm, threadpoolctl;"  # what they set themselves
        "from threadpoolctl import threadpool_info; before = dict(os.environ);"
        "threads = [p['num_threads'] for p in threadpool_info()]; import minippo, minippo.envs, minippo.cli;"
        "import minippo.grading.grade, minippo.grading.plugin, minippo.grading.sandbox;"
        "assert dict(os.environ) == before, set(os.environ) ^ set(before);"
        "assert [p['num_threads'] for p in threadpool_info()] == threads"
    )
    # the grader's pytest plugin takes its key out of the environment when pytest configures it, not on import
    env = {"PATH": "/usr/bin:/bin", "PYTHONPATH": str(ROOT), "MINIPPO_GRADE_KEY": "a key"}
    result = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr


def test_one_version_string():
    import minippo

    text = (ROOT / "pyproject.toml").read_text()
    assert 'dynamic = ["version"]' in text and "minippo.__version__" in text
    assert minippo.__version__.count(".") == 2


def test_the_package_map_in_docs_is_the_package_as_it_is():
    result = subprocess.run([sys.executable, str(ROOT / "tools" / "package_map.py"), "--check"], capture_output=True)
    assert result.returncode == 0, result.stdout.decode() + result.stderr.decode()


def load_package_map():
    """tools/package_map.py, whose CORE names the core's modules and whose ``imports`` reads a module's imports."""
    spec = importlib.util.spec_from_file_location("package_map", ROOT / "tools" / "package_map.py")
    package_map = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(package_map)
    return package_map


def test_the_core_imports_nothing_of_the_grader_the_language_models_or_the_toys():
    package_map = load_package_map()
    modules = package_map.modules()
    for name, path in modules.items():
        if package_map.room(name) in ("core", "library") and name != "cli":  # the command line opens every room
            rooms = {package_map.room(target) for target in package_map.imports(path, set(modules))}
            assert rooms <= {"core", "library"}, (name, rooms)


# The core's imports from outside the core as the code stands, each one named: the only exceptions. The test fails on
# any import not listed here, and on a listed one that is gone (strike it from the list then).
KNOWN_EXCEPTIONS = {
    # the Trainer makes its environments and reads their spaces (envs.make_env, spaces_of, image_shape_of)
    ("ppo", "envs"),
    # train() keeps the run folder (run_folder.RunFolder)
    ("ppo", "run_folder"),
    # the rollout's state, which the checkpoint saves, holds the environments' own (envs.env_state, load_env_state)
    ("rollout", "envs"),
}


def test_the_core_imports_only_the_core_and_errors():
    package_map = load_package_map()
    modules = package_map.modules()
    core = {name for name in modules if package_map.room(name) == "core"}
    assert core == package_map.CORE, "a module of the core is missing: update tools/package_map.py"
    assert "errors" not in modules  # left out of the map: every room may import it
    outside = {(name, target) for name in core for target in package_map.imports(modules[name], set(modules)) - core}
    assert outside - KNOWN_EXCEPTIONS == set(), "the core imports from outside the core"
    assert KNOWN_EXCEPTIONS - outside == set(), "no longer imported: take it out of KNOWN_EXCEPTIONS"
