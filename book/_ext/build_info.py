"""The minippo version and the git commit the site was built from, shown in every page's footer.

The version is read from ``minippo/__init__.py`` beside the book; the commit from git (or ``GITHUB_SHA`` where there
is no git), marked "with local changes" when tracked files differ from it. The commit links to the repository's
page for it when the repository is on GitHub.
"""

import os
import re
import subprocess
from html import escape
from pathlib import Path


def minippo_version(root: Path) -> str:
    text = (root / "minippo" / "__init__.py").read_text(encoding="utf-8")
    match = re.search(r'^__version__ = "([^"]+)"', text, flags=re.MULTILINE)
    return match.group(1) if match else "unknown"


def _git(root: Path, *args: str) -> str | None:
    try:
        done = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def built_commit(root: Path) -> tuple[str | None, bool]:
    """The commit checked out at ``root`` and whether tracked files have changed since."""
    commit = _git(root, "rev-parse", "HEAD") or os.environ.get("GITHUB_SHA") or None
    changed = bool(_git(root, "status", "--porcelain", "--untracked-files=no"))
    return commit, changed


def footer_html(version: str, commit: str | None, changed: bool, repository_url: str) -> str:
    if commit is None:
        where = "an unknown commit"
    else:
        short = escape(commit[:7])
        if repository_url.startswith("https://github.com/"):
            link = escape(f"{repository_url.rstrip('/')}/commit/{commit}", quote=True)
            where = f'commit <a href="{link}"><code>{short}</code></a>'
        else:
            where = f"commit <code>{short}</code>"
        if changed:
            where += " with local changes"
    return f'<p class="build-info">Built from minippo {escape(version)} at {where}.</p>'


def _set_footer(app, config):
    root = Path(app.srcdir).resolve().parent
    commit, changed = built_commit(root)
    options = config.html_theme_options
    info = footer_html(minippo_version(root), commit, changed, options.get("repository_url", ""))
    options["extra_footer"] = (options.get("extra_footer") or "") + info


def setup(app):
    app.connect("config-inited", _set_footer, priority=600)  # after repository.py has set the repository's address
    return {"parallel_read_safe": True, "parallel_write_safe": True}
