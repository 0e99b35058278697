"""The published site around the chapters: repository and launch links, downloads, footer, link previews, and the
notebooks branch that Colab and Binder open (book/_ext/, tools/notebooks_branch.py)."""

import json
import re
import sys
from html import unescape
from pathlib import Path
from types import SimpleNamespace

import pytest
import yaml
from conftest import ROOT

import minippo

sys.path.insert(0, str(ROOT / "book" / "_ext"))
sys.path.insert(0, str(ROOT / "tools"))

import build_info  # noqa: E402
import notebooks_branch  # noqa: E402
import repository  # noqa: E402
import social_meta  # noqa: E402

CONFIG = yaml.safe_load((ROOT / "book" / "_config.yml").read_text(encoding="utf-8"))
CHAPTERS = sorted(p.stem for p in (ROOT / "book").glob("[0-9][0-9]-*.md"))


def configured_repository() -> str:
    """The repository the built site links to: the build's environment, else _config.yml."""
    import os

    return (os.environ.get("BOOK_REPOSITORY_URL") or CONFIG["repository"]["url"]).rstrip("/")


# ---- the repository setting ----------------------------------------------------------------------------------------


def test_config_names_the_repository_and_the_launch_services():
    assert repository.repository_parts(CONFIG["repository"]["url"]) is not None
    assert CONFIG["repository"]["path_to_book"] == "book"
    assert CONFIG["launch_buttons"]["binderhub_url"].startswith("https://")
    assert CONFIG["launch_buttons"]["colab_url"].startswith("https://")
    for button in ("use_repository_button", "use_issues_button", "use_edit_page_button"):
        assert CONFIG["html"][button] is True


@pytest.mark.parametrize(
    "url, parts",
    [
        ("https://github.com/someone/minippo", ("someone", "minippo")),
        ("https://github.com/someone/minippo.git", ("someone", "minippo")),
        ("https://github.com/someone/minippo/", ("someone", "minippo")),
        ("https://gitlab.com/someone/minippo", None),
        ("https://github.com/someone", None),
    ],
)
def test_repository_parts(url, parts):
    assert repository.repository_parts(url) == parts


def test_the_environment_replaces_the_configured_repository(monkeypatch):
    config = SimpleNamespace(
        html_theme_options={"repository_url": "https://github.com/minippo/minippo", "repository_branch": "main"},
        html_baseurl="",
    )
    monkeypatch.setenv("BOOK_REPOSITORY_URL", "https://github.com/someone/fork.git")
    monkeypatch.setenv("BOOK_REPOSITORY_BRANCH", "trunk")
    monkeypatch.setenv("BOOK_SITE_URL", "https://someone.github.io/fork")
    repository._from_environment(None, config)
    assert config.html_theme_options["repository_url"] == "https://github.com/someone/fork"
    assert config.html_theme_options["repository_branch"] == "trunk"
    assert config.html_baseurl == "https://someone.github.io/fork/"


def test_without_the_environment_the_configuration_stands(monkeypatch):
    for name in ("BOOK_REPOSITORY_URL", "BOOK_REPOSITORY_BRANCH", "BOOK_SITE_URL"):
        monkeypatch.setenv(name, "")
    options = {"repository_url": "https://github.com/minippo/minippo", "repository_branch": "main"}
    config = SimpleNamespace(html_theme_options=dict(options), html_baseurl="")
    repository._from_environment(None, config)
    assert config.html_theme_options == options and config.html_baseurl == ""


# ---- footer and link previews ---------------------------------------------------------------------------------------


def test_footer_names_version_and_commit():
    commit = "0123456789abcdef0123456789abcdef01234567"
    html = build_info.footer_html("0.1.0", commit, False, "https://github.com/someone/minippo")
    assert "minippo 0.1.0" in html and ">0123456<" in html
    assert f'href="https://github.com/someone/minippo/commit/{commit}"' in html
    assert "local changes" not in html
    assert "with local changes" in build_info.footer_html("0.1.0", commit, True, "")
    assert "unknown commit" in build_info.footer_html("0.1.0", None, False, "")


def test_footer_version_is_minippos():
    assert build_info.minippo_version(ROOT) == minippo.__version__


def test_description_is_cut_at_a_word():
    text = "word " * 100
    short = social_meta.shorten(text.strip(), 50)
    assert len(short) <= 50 and short.endswith("word…")
    assert social_meta.shorten("short enough") == "short enough"


def test_description_writes_inline_math_plainly():
    assert social_meta.plain_math(r"\theta_{\text{old}}") == "θ_old"
    assert social_meta.plain_math(r"L^{CLIP}(\theta)") == "L^CLIP(θ)"
    assert social_meta.plain_math(r"\hat{A}_t") == "A_t"


# ---- the notebooks branch -------------------------------------------------------------------------------------------


def fake_site(tmp_path: Path) -> Path:
    sources = tmp_path / "html" / "_sources"
    sources.mkdir(parents=True)
    notebook = {
        "cells": [
            {
                "cell_type": "code",
                "execution_count": 1,
                "id": "a",
                "metadata": {},
                "outputs": [{"name": "stdout", "output_type": "stream", "text": ["2\n"]}],
                "source": ["print(1 + 1)"],
            }
        ],
        "metadata": {},
        "nbformat": 4,
        "nbformat_minor": 5,
    }
    (sources / "01-network.ipynb").write_text(json.dumps(notebook), encoding="utf-8")
    (sources / "01-network.md").write_text("# A network by hand\n", encoding="utf-8")
    return tmp_path / "html"


def test_notebooks_branch_adds_the_setup_cell_and_pins_the_commit(tmp_path):
    commit = "89abcdef" * 5
    out = tmp_path / "branch"
    names = notebooks_branch.write_branch(fake_site(tmp_path), out, "https://github.com/someone/minippo", commit)
    assert names == ["01-network.ipynb"]
    notebook = json.loads((out / "01-network.ipynb").read_text(encoding="utf-8"))
    setup, original = notebook["cells"]
    setup_source = "".join(setup["source"])
    assert "https://github.com/someone/minippo" in setup_source and commit in setup_source
    compile(setup_source, "setup", "exec")  # the cell is Python
    assert original["outputs"][0]["text"] == ["2\n"]  # the executed outputs stay
    assert (out / "requirements.txt").read_text().splitlines()[
        0
    ] == f"minippo @ git+https://github.com/someone/minippo@{commit}"
    assert sorted(p.name for p in out.iterdir()) == ["01-network.ipynb", "README.md", "requirements.txt", "runtime.txt"]


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--repository", "https://gitlab.com/a/b", "--commit", "a" * 40], "--repository must look like"),
        (["--repository", "https://github.com/a/b", "--commit", "abc123"], "--commit must be a full"),
    ],
)
def test_notebooks_branch_refuses_bad_input_in_one_line(tmp_path, capsys, argv, message):
    assert notebooks_branch.main([str(tmp_path), str(tmp_path / "out"), *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_notebooks_branch_needs_a_built_site(tmp_path):
    with pytest.raises(SystemExit, match="no executed chapters"):
        notebooks_branch.write_branch(tmp_path, tmp_path / "out", "https://github.com/a/b", "a" * 40)


# ---- the built site -------------------------------------------------------------------------------------------------


def hrefs(page: Path) -> list[str]:
    return [unescape(h) for h in re.findall(r'(?:href|src)="([^"]+)"', page.read_text(encoding="utf-8"))]


def test_every_local_link_of_the_built_site_exists(built_book):
    missing = []
    for page in sorted(built_book.glob("*.html")):
        for href in hrefs(page):
            if re.match(r"[a-z]+:", href) or href.startswith(("#", "//")):
                continue
            target = href.split("#")[0].split("?")[0]
            if target and not (page.parent / target).exists():
                missing.append(f"{page.name} -> {href}")
    assert missing == []


@pytest.mark.parametrize("name", CHAPTERS)
def test_chapter_offers_downloads_launches_and_repository_links(built_book, name):
    links = hrefs(built_book / f"{name}.html")
    repo = configured_repository()
    owner, project = repository.repository_parts(repo)
    assert f"_sources/{name}.ipynb" in links and f"_sources/{name}.md" in links
    assert (built_book / "_sources" / f"{name}.ipynb").exists() and (built_book / "_sources" / f"{name}.md").exists()
    assert repo in links
    assert any(link.startswith(f"{repo}/edit/") and link.endswith(f"book/{name}.md") for link in links)
    assert any(link.startswith(f"{repo}/issues/new") for link in links)
    assert any(
        re.fullmatch(rf"https://mybinder\.org/v2/gh/{owner}/{project}/notebooks\?urlpath=lab/tree/{name}\.ipynb", link)
        for link in links
    )
    assert f"https://colab.research.google.com/github/{owner}/{project}/blob/notebooks/{name}.ipynb" in links


def test_pages_carry_icon_logo_preview_and_build_footer(built_book):
    page = (built_book / "05-clipping.html").read_text(encoding="utf-8")
    assert re.search(r'<link rel="icon" href="_static/favicon\.svg"', page)
    assert '<link rel="apple-touch-icon" href="_static/apple-touch-icon.png" />' in page
    assert "_static/logo.svg" in page and "_static/logo-dark.svg" in page
    assert re.search(r'<meta property="og:title" content="(5\. )?Clipping the objective · [^"]+"', page)
    description = re.search(r'<meta property="og:description" content="([^"]{40,})"', page)
    assert description, "no og:description"
    footer = re.search(r"Built from minippo ([\w.]+) at (?:commit .*?<code>[0-9a-f]{7}</code>|an unknown commit)", page)
    assert footer and footer.group(1) == minippo.__version__
