"""The built book, as a reader gets it: every chapter present, substantial, executed without errors, with figures."""

import re
from html.parser import HTMLParser

import pytest
from conftest import ROOT

TOC = ROOT / "book" / "_toc.yml"
CHAPTERS = re.findall(r"(?:root|file):\s*(\S+)", TOC.read_text())
NUMBERED = [name for name in CHAPTERS if re.match(r"\d\d-", name)]


class ArticleText(HTMLParser):
    """Collects the text of the page's main article, the classes of its elements and its images."""

    def __init__(self):
        super().__init__()
        self.depth, self.text, self.classes, self.images = 0, [], [], []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "article" or self.depth:
            self.depth += 1 if tag not in ("img", "br", "hr", "input", "meta", "link") else 0
            self.classes.extend((attrs.get("class") or "").split())
            if tag == "img":
                self.images.append(attrs.get("src", ""))

    def handle_endtag(self, tag):
        if self.depth and tag not in ("img", "br", "hr", "input", "meta", "link"):
            self.depth -= 1

    def handle_data(self, data):
        if self.depth:
            self.text.append(data)


def parse(path):
    parser = ArticleText()
    parser.feed(path.read_text(encoding="utf-8"))
    return " ".join(parser.text), parser.classes, parser.images


def test_the_toc_names_the_course():
    assert CHAPTERS[:2] == ["intro", "notation"]
    assert len(NUMBERED) >= 12


@pytest.mark.timeout(1800)
@pytest.mark.parametrize("name", CHAPTERS)
def test_every_page_is_built_and_substantial(built_book, name):
    page = built_book / f"{name}.html"
    assert page.exists(), f"{name}.html is missing from the built book"
    text, classes, _ = parse(page)
    words = len(text.split())
    assert words > (300 if name in ("intro", "notation", "references") else 1200), f"{name} has only {words} words"


@pytest.mark.timeout(1800)
@pytest.mark.parametrize("name", NUMBERED)
def test_every_chapter_ran_its_code_and_drew_a_figure(built_book, name):
    text, classes, images = parse(built_book / f"{name}.html")
    assert "cell_output" in classes, f"{name} shows no executed output"
    assert "Traceback" not in text and "Error" not in " ".join(c for c in classes if "error" in c.lower()), name
    assert not any(c in ("output_error", "traceback") for c in classes), f"{name} has a cell that raised"
    computed = [src for src in images if "_images/" in src or src.startswith("data:image")]
    assert computed, f"{name} has no figure computed by the page"
    assert "Exercise" in text or name.startswith("11-"), f"{name} has no exercises section"
