"""Execute the pages that need it several at a time, before Sphinx reads them one by one.

With ``execute_notebooks: cache`` myst-nb executes a page when Sphinx reads it, so the pages run one after another
and a build on a machine with two cores uses one. The pages are independent of each other (each runs in its own
kernel and writes nothing another page reads), so this extension runs the ones whose code is not in the
execution cache in a pool of processes, one kernel each, and puts the executed notebooks into the cache. When
Sphinx then reads a page, myst-nb finds its outputs there, exactly as it would after an earlier build.

A page is read and hashed by myst-nb's own reader, so the cache entry is the one myst-nb looks for. A page that
fails here is left out of the cache: myst-nb executes it again and reports the error as it always does. The number
of kernels at a time is the number of CPUs this process may use, or ``BOOK_EXECUTION_WORKERS`` when set (1 turns
the extension off).
"""

from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from jupyter_cache import get_cache
from jupyter_cache.base import CacheBundleIn
from jupyter_cache.executors.utils import single_nb_execution
from myst_nb.core.read import create_nb_reader
from sphinx.util import logging

logger = logging.getLogger(__name__)


def workers() -> int:
    setting = os.environ.get("BOOK_EXECUTION_WORKERS", "").strip()
    if setting:
        return max(1, int(setting))
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def _execute(notebook, cwd: str, allow_errors: bool, timeout: int | None):
    result = single_nb_execution(notebook, cwd=cwd, allow_errors=allow_errors, timeout=timeout, meta_override=True)
    return notebook, result.time, None if result.err is None else type(result.err).__name__


def pending_pages(env, docnames) -> list[tuple[Path, object, float]]:
    """(path, notebook, an estimate of its run time) for each page to be read whose code is not in the cache."""
    cache = get_cache(env.mystnb_config.execution_cache_path or ".jupyter_cache")
    previous = {record.uri: record.data.get("execution_seconds", 0.0) for record in cache.list_cache_records()}
    pending = []
    for docname in sorted(docnames):
        path = Path(env.doc2path(docname))
        if path.suffix not in (".md", ".ipynb"):
            continue
        text = path.read_text(encoding="utf-8")
        reader = create_nb_reader(str(path), env.myst_config, env.mystnb_config, text)
        if reader is None:
            continue
        notebook = reader.read(text)
        if not any(cell.cell_type == "code" for cell in notebook.cells):
            continue
        try:
            cache.match_cache_notebook(notebook)
        except KeyError:
            pending.append((path, notebook, previous.get(str(path), float(len(text)))))
    return pending


def execute_ahead(app, env, docnames) -> None:
    config = env.mystnb_config
    if config.execution_mode != "cache" or workers() < 2:
        return
    pending = pending_pages(env, docnames)
    if len(pending) < 2:
        return
    pending.sort(key=lambda page: -page[2])  # the longest first, so that the last to finish is a short one
    cache = get_cache(config.execution_cache_path or ".jupyter_cache")
    count = min(workers(), len(pending))
    logger.info(f"executing {len(pending)} pages, {count} at a time")
    with ProcessPoolExecutor(max_workers=count) as pool:
        options = (config.execution_allow_errors, config.execution_timeout)
        futures = {pool.submit(_execute, notebook, str(path.parent), *options): path for path, notebook, _ in pending}
        for future, path in futures.items():
            notebook, seconds, error = future.result()
            if error is not None:
                logger.info(f"{path.name}: failed ahead ({error}); it runs again when read")
                continue
            bundle = CacheBundleIn(notebook, str(path), data={"execution_seconds": seconds})
            cache.cache_notebook_bundle(bundle, check_validity=False, overwrite=True)
            logger.info(f"{path.name}: executed in {seconds:.1f} s")


def setup(app):
    app.connect("env-before-read-docs", execute_ahead)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
