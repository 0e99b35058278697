"""The built book shows no LaTeX source as text: every formula is rendered by MathJax, none leaks as a raw `\\frac`,
`\\beta` or `$...$` (as when a line of a paragraph that begins with `+ ` turns inline math into a list item).

Reads the HTML that ``jupyter-book build book/`` wrote; skips when the book has not been built."""

import re
from html.parser import HTMLParser

import pytest
from conftest import BOOK_HTML

# text that only LaTeX source has: a backslash command, or a dollar sign that opens or closes math
LATEX = re.compile(r"\\[A-Za-z]{2,}|\\[{}(),;!|]|\$[^\s$]|[^\s$]\$")
# elements whose text is not prose: MathJax's own containers and what it leaves as source, code, scripts
SKIPPED_TAGS = {"script", "style", "pre", "code", "textarea", "mjx-container", "math"}
SKIPPED_CLASSES = {"math", "MathJax", "MathJax_Preview", "highlight", "cell_output", "output"}
VOID = {"img", "br", "hr", "input", "meta", "link", "wbr", "source", "col", "area", "base", "embed", "param"}


class LeakedLatex(HTMLParser):
    """Collects the article's prose text nodes that look like LaTeX source, outside every math container."""

    def __init__(self):
        super().__init__()
        self.stack: list[bool] = []  # for each open element of the article: is it (or an ancestor) skipped?
        self.in_article = 0
        self.leaks: list[str] = []

    def handle_starttag(self, tag, attrs):
        if tag in VOID:
            return
        if tag == "article":
            self.in_article += 1
        classes = set((dict(attrs).get("class") or "").split())
        skipped = tag in SKIPPED_TAGS or bool(classes & SKIPPED_CLASSES) or (bool(self.stack) and self.stack[-1])
        self.stack.append(skipped)

    def handle_endtag(self, tag):
        if tag in VOID or not self.stack:
            return
        self.stack.pop()
        if tag == "article":
            self.in_article -= 1

    def handle_data(self, data):
        if self.in_article and not (self.stack and self.stack[-1]) and LATEX.search(data):
            self.leaks.append(" ".join(data.split())[:120])


def leaks_in(html: str) -> list[str]:
    parser = LeakedLatex()
    parser.feed(html)
    return parser.leaks


def test_the_detector_sees_a_leak_and_passes_rendered_math():
    leaked = "<article><ul><li><p>+ \\beta\\log Z(x)$. In the model</p></li></ul></article>"
    rendered = '<article><p>a <span class="math notranslate nohighlight">\\(\\beta\\log Z(x)\\)</span></p></article>'
    code = '<article><div class="highlight"><pre>ax.set_ylabel(r"$\\beta$")</pre></div></article>'
    assert leaks_in(leaked) and not leaks_in(rendered) and not leaks_in(code)
    assert leaks_in("<article><p>where $R(x, y) = 1</p></article>")
    assert not leaks_in("<article><p>costs 5 $ or \\ alone</p></article>")


def test_no_page_shows_latex_outside_rendered_math():
    pages = sorted(BOOK_HTML.glob("*.html")) if (BOOK_HTML / "searchindex.js").exists() else []
    if not pages:
        pytest.skip("the book is not built (jupyter-book build book/ -W -n --keep-going)")
    found = {page.name: leaks for page in pages if (leaks := leaks_in(page.read_text(encoding="utf-8")))}
    assert not found, "LaTeX shown as text, outside rendered math:\n" + "\n".join(
        f"{name}: {leaks[:3]}" for name, leaks in found.items()
    )
