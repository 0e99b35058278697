import subprocess
from pathlib import Path

import numpy as np
import pytest


def numerical_gradient(f, x: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central finite differences of the scalar f() with respect to every entry of x (changed in place)."""
    grad = np.zeros_like(x, dtype=np.float64)
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
    sources += list((ROOT / "minippo").glob("*.py"))
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
