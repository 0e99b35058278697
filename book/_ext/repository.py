"""The repository and address the site is built for, taken from the environment when the build sets them.

``_config.yml``'s ``repository`` (url, branch, path_to_book) names the repository the book comes from; jupyter-book
passes it to the theme, which builds the repository, issues, edit-this-page and launch buttons from it. The Pages
workflow (``.github/workflows/book.yml``) builds with these variables set from the repository it runs in, so a fork
links to itself with no edit:

- ``BOOK_REPOSITORY_URL``: the repository's address, e.g. ``https://github.com/someone/minippo``;
- ``BOOK_REPOSITORY_BRANCH``: the branch that edit links and launch links name;
- ``BOOK_SITE_URL``: the address the site is published at (``html_baseurl``: canonical links and ``og:url``).

Unset or empty, the values in ``_config.yml`` stand. Launch links go to the ``notebooks`` branch, which the workflow
fills with the executed chapters (``tools/notebooks_branch.py``): Colab and Binder need a notebook in the
repository, and the chapters are MyST Markdown.
"""

import os

NOTEBOOKS_BRANCH = "notebooks"


def repository_parts(url: str) -> tuple[str, str] | None:
    """``(owner, name)`` of a GitHub repository address, or None for another host."""
    url = url.strip().removesuffix("/").removesuffix(".git")
    if not url.startswith("https://github.com/"):
        return None
    parts = url.removeprefix("https://github.com/").split("/")
    return (parts[0], parts[1]) if len(parts) == 2 and all(parts) else None


def _from_environment(app, config):
    options = config.html_theme_options
    url = os.environ.get("BOOK_REPOSITORY_URL", "").strip()
    branch = os.environ.get("BOOK_REPOSITORY_BRANCH", "").strip()
    site = os.environ.get("BOOK_SITE_URL", "").strip()
    if url:
        options["repository_url"] = url.removesuffix("/").removesuffix(".git")
    if branch:
        options["repository_branch"] = branch
    if site:
        config.html_baseurl = site.removesuffix("/") + "/"


def _launch_from_notebooks_branch(app, pagename, templatename, context, doctree):
    """Points the theme's Binder and Colab links at the executed chapter on the notebooks branch."""
    parts = repository_parts(app.config.html_theme_options.get("repository_url", ""))
    if parts is None:
        return
    owner, name = parts
    launch = app.config.html_theme_options.get("launch_buttons", {})
    binderhub = launch.get("binderhub_url", "").strip("/")
    colab = launch.get("colab_url", "").strip("/")
    for group in context.get("header_buttons", []):
        if group.get("label") != "launch-buttons":
            continue
        for button in group["buttons"]:
            if button.get("text") == "Binder":
                button["url"] = f"{binderhub}/v2/gh/{owner}/{name}/{NOTEBOOKS_BRANCH}?urlpath=lab/tree/{pagename}.ipynb"
            elif button.get("text") == "Colab":
                button["url"] = f"{colab}/github/{owner}/{name}/blob/{NOTEBOOKS_BRANCH}/{pagename}.ipynb"


def setup(app):
    app.connect("config-inited", _from_environment)
    # after sphinx-book-theme's add_launch_buttons (priority 501), before the page is written
    app.connect("html-page-context", _launch_from_notebooks_branch, priority=502)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
