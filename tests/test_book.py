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
    # the "why" page, the basics of reinforcement learning, then PPO on one page, come before chapter 1
    assert CHAPTERS[:5] == ["intro", "why-ppo", "rl-basics", "ppo-on-one-page", "notation"]
    assert {"pytorch-bridge", "glossary"} <= set(CHAPTERS)
    assert "references" in CHAPTERS
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


def section_titles(path):
    """The titles of a page's level-2 sections, in order."""
    return [
        re.sub(r"<[^>]+>|#", "", title).strip()
        for title in re.findall(r"<h2>(.*?)</h2>", path.read_text(encoding="utf-8"), re.S)
    ]


@pytest.mark.timeout(1800)
@pytest.mark.parametrize("name", NUMBERED)
def test_every_chapter_ends_with_a_summary_and_further_reading(built_book, name):
    titles = section_titles(built_book / f"{name}.html")
    assert "Summary" in titles and "Further reading" in titles, f"{name}: sections {titles}"
    summary, further = titles.index("Summary"), titles.index("Further reading")
    assert further == summary + 1, f"{name}: Further reading should follow the Summary"
    if "What goes wrong" in titles:
        assert titles.index("What goes wrong") < summary, f"{name}: the Summary comes after What goes wrong"
    exercises = [i for i, title in enumerate(titles) if title.startswith("Exercise")]
    assert exercises and exercises[0] > further, f"{name}: the exercises come last"


@pytest.mark.timeout(1800)
def test_the_bibliography_lists_only_what_the_chapters_cite(built_book):
    keys = re.findall(r"^@\w+\{(\w+),", (ROOT / "book" / "references.bib").read_text(), re.M)
    sources = {path.stem: path.read_text(encoding="utf-8") for path in (ROOT / "book").glob("*.md")}
    cited = set()
    for text in sources.values():
        for group in re.findall(r"\{cite(?::t|:p)?\}`([^`]+)`", text):
            cited.update(key.strip() for key in group.split(","))
    assert len(keys) >= 12
    assert not set(keys) - cited, f"in references.bib but never cited: {set(keys) - cited}"
    assert not cited - set(keys), f"cited but not in references.bib: {cited - set(keys)}"
    page = (built_book / "references.html").read_text(encoding="utf-8")
    entries = re.findall(r'<div class="citation" id="id\d+"|<dt class="label" id="', page)
    assert len(entries) >= len(keys), f"the bibliography page shows {len(entries)} of {len(keys)} entries"


@pytest.mark.timeout(1800)
def test_the_glossary_defines_its_terms_and_every_term_is_linked_from_a_page(built_book):
    glossary = (built_book / "glossary.html").read_text(encoding="utf-8")
    terms = re.findall(r'<dt id="(term-[^"]+)"', glossary)
    assert len(terms) >= 25, f"the glossary defines {len(terms)} terms"
    linked = set()
    for page in built_book.glob("*.html"):
        if page.name != "glossary.html":
            linked.update(re.findall(r'href="glossary\.html#(term-[^"]+)"', page.read_text(encoding="utf-8")))
    assert not set(terms) - linked, f"glossary terms no page links to: {sorted(set(terms) - linked)}"
    chapters_linking = [name for name in NUMBERED if "glossary.html#term-" in (built_book / f"{name}.html").read_text()]
    assert len(chapters_linking) >= 8, chapters_linking
