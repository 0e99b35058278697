"""The book executes its pages several at a time (book/_ext/execute_ahead.py), with the result myst-nb's own execution
would give: a tiny book of three pages built with the book's extension."""

import json
import os
import shutil
import subprocess
import textwrap
from pathlib import Path

import pytest
from conftest import ROOT

pytestmark = pytest.mark.book  # small books built with jupyter-book

PAGE = """\
---
jupytext:
  text_representation:
    extension: .md
    format_name: myst
kernelspec:
  display_name: Python 3
  language: python
  name: python3
---
# Page {name}

```{{code-cell}} ipython3
import json, time
started = time.time()
time.sleep(4)
{body}
with open("{name}.json", "w") as handle:
    json.dump([started, time.time()], handle)
print("page {name} ran")
```
"""


def make_book(folder: Path, failing: bool = False) -> Path:
    book = folder / "book"
    (book / "_ext").mkdir(parents=True)
    shutil.copy(ROOT / "book" / "_ext" / "execute_ahead.py", book / "_ext")
    (book / "_config.yml").write_text(
        textwrap.dedent("""\
            title: tiny
            execute:
              execute_notebooks: cache
            sphinx:
              local_extensions:
                execute_ahead: _ext
            """),
        encoding="utf-8",
    )
    toc = "format: jb-book\nroot: intro\nchapters:\n  - file: a\n  - file: b\n"
    (book / "_toc.yml").write_text(toc, encoding="utf-8")
    (book / "intro.md").write_text("# Tiny\n\nNo code here.\n", encoding="utf-8")
    (book / "a.md").write_text(PAGE.format(name="a", body=""), encoding="utf-8")
    body = 'raise RuntimeError("page b is broken")' if failing else ""
    (book / "b.md").write_text(PAGE.format(name="b", body=body), encoding="utf-8")
    return book


def build(book: Path) -> subprocess.CompletedProcess:
    jupyter_book = shutil.which("jupyter-book") or pytest.skip("jupyter-book is not installed (pip install '.[book]')")
    env = {**os.environ, "BOOK_EXECUTION_WORKERS": "2", "PYTHONPATH": str(ROOT)}
    command = [jupyter_book, "build", str(book), "-W", "-n", "--keep-going"]
    return subprocess.run(command, capture_output=True, text=True, timeout=600, env=env, cwd=book)


def test_pages_run_at_the_same_time_and_the_build_reads_them_from_the_cache(tmp_path):
    book = make_book(tmp_path)
    first = build(book)
    assert first.returncode == 0, (first.stdout + first.stderr)[-3000:]
    assert "executing 2 pages, 2 at a time" in first.stdout
    assert first.stdout.count("Using cached notebook") == 2  # myst-nb executed nothing itself
    (a_start, a_end), (b_start, b_end) = (json.loads((book / f"{page}.json").read_text()) for page in "ab")
    assert a_start < b_end and b_start < a_end, "the two pages did not run at the same time"
    for page in "ab":
        assert f"page {page} ran" in (book / "_build" / "html" / f"{page}.html").read_text(encoding="utf-8")

    # a second build finds everything in the cache: nothing is executed, ahead or otherwise
    (book / "a.json").unlink()
    second = build(book)
    assert second.returncode == 0, (second.stdout + second.stderr)[-3000:]
    assert "executing" not in second.stdout and not (book / "a.json").exists()


def test_a_page_that_fails_ahead_fails_the_build_as_myst_nb_reports_it(tmp_path):
    book = make_book(tmp_path, failing=True)
    result = build(book)
    assert result.returncode != 0
    output = result.stdout + result.stderr
    assert "b.md: failed ahead (CellExecutionError)" in output
    report = book / "_build" / "html" / "reports" / "b.err.log"  # myst-nb ran the page again and kept its error
    assert "b.err.log" in output and "page b is broken" in report.read_text(encoding="utf-8")
    assert "a.md: executed in" in output
