import importlib.util
import os
import secrets
import subprocess
from pathlib import Path

import numpy as np
import pytest

from minippo.gradcheck import central_differences

numerical_gradient = central_differences  # (f, x, step): ∂f/∂x, x changed in place and restored


def assert_close(analytic, numeric, rtol=1e-6, atol=1e-8):
    analytic, numeric = np.asarray(analytic), np.asarray(numeric)
    assert analytic.shape == numeric.shape
    scale = max(1.0, float(np.abs(numeric).max()))
    assert np.abs(analytic - numeric).max() <= atol + rtol * scale, (analytic, numeric)


@pytest.fixture
def rng():
    return np.random.default_rng(0)


ROOT = Path(__file__).resolve().parents[1]
BOOK_HTML = ROOT / "book" / "_build" / "html"


def _newest_source_mtime() -> float:
    sources = [p for p in (ROOT / "book").rglob("*") if "_build" not in p.parts and p.is_file()]
    sources += list((ROOT / "minippo").rglob("*.py"))
    return max(p.stat().st_mtime for p in sources)


@pytest.fixture(scope="session")
def built_book() -> Path:
    """The book's HTML, built with ``jupyter-book build book/ -W -n --keep-going`` if it is missing or older than its
    sources."""
    # searchindex.js is written by every build; index.html (a redirect written once) keeps its first build's time
    stamp = BOOK_HTML / "searchindex.js"
    if not stamp.exists() or stamp.stat().st_mtime < _newest_source_mtime():
        result = subprocess.run(
            ["jupyter-book", "build", str(ROOT / "book"), "-W", "-n", "--keep-going"],
            capture_output=True,
            text=True,
            timeout=1800,
        )
        if result.returncode != 0:
            pytest.fail("jupyter-book build failed:\n" + (result.stdout + result.stderr)[-4000:])
    return BOOK_HTML


@pytest.fixture(scope="session")
def ray_environment():
    """Ray on loopback, no usage reports, and one token of this test session's own, so that nothing is written to the
    home folder and the nodes and drivers of every test trust each other. Ray reads these variables when it is first
    imported in a process, so every test that starts Ray (the sweep's and the side-by-side runner's) takes this one
    fixture: two modules with settings of their own would leave the second with a Ray configured by the first."""
    if importlib.util.find_spec("ray") is None:  # do not import Ray here: it reads the variables when imported
        pytest.skip("Ray is not installed (pip install -e '.[sweep]')")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
        patch.setenv("RAY_USAGE_STATS_ENABLED", "0")
        patch.setenv("RAY_AUTH_MODE", "token")
        patch.setenv("RAY_AUTH_TOKEN", secrets.token_hex(32))
        patch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
        patch.delenv("RAY_ADDRESS", raising=False)
        yield


# Tiers. A plain ``pytest`` runs the quick tier, what a contributor runs after every change (about two minutes on two
# cores); the others are named by markers, registered in pyproject.toml: ``slow`` (learning runs and long
# end-to-end runs), ``book`` (tests of the built book: the first builds it), ``browser`` (headless Chromium on the
# built pages), ``ray`` (sweeps on a local Ray). ``pytest --all`` runs every tier (CI does); ``pytest -m book`` one;
# naming files or tests (``pytest tests/test_book.py``) runs every test named, whatever its tier.
TIERS = ("slow", "book", "browser", "ray")
BY_FIXTURE = {"built_book": "book", "ray_environment": "ray"}  # a test that takes the fixture is in the tier


def pytest_addoption(parser):
    parser.addoption("--all", action="store_true", help="run every tier (slow, book, browser, ray), as CI does")


def pytest_collection_modifyitems(config, items):
    for item in items:
        for fixture, tier in BY_FIXTURE.items():
            if fixture in item.fixturenames:
                item.add_marker(tier)
        if item.path.name.endswith("_browser.py"):
            item.add_marker("browser")
    named = config.args_source != pytest.Config.ArgsSource.TESTPATHS  # files or tests named on the command line
    if config.getoption("--all") or config.getoption("-m") or named:
        return
    tiered = [any(item.get_closest_marker(tier) for tier in TIERS) for item in items]
    if any(tiered):
        config.hook.pytest_deselected(items=[item for item, t in zip(items, tiered) if t])
        items[:] = [item for item, t in zip(items, tiered) if not t]
