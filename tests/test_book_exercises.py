"""The built book poses each graded exercise before it shows minippo's answer: no graded function's ``def`` is in an
open code block of its chapter, or of an earlier one, before the "Your turn" block that asks for it; minippo's
version is folded (a ``<details>`` block, one click away). The graded functions are read from exercises/."""

import ast
import re
from html.parser import HTMLParser

import pytest
from conftest import ROOT

VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source", "track", "wbr"}


def graded_functions() -> list[tuple[int, str]]:
    """(chapter, name) for every name in the EXERCISES list of every exercises/chNN_*.py."""
    graded = []
    for module in sorted((ROOT / "exercises").glob("ch[0-9][0-9]_*.py")):
        tree = ast.parse(module.read_text(encoding="utf-8"))
        for node in tree.body:
            if isinstance(node, ast.Assign) and any(getattr(t, "id", "") == "EXERCISES" for t in node.targets):
                graded += [(int(module.name[2:4]), name) for name in ast.literal_eval(node.value)]
    return graded


GRADED = graded_functions()
PAGES = {int(path.name[:2]): path.stem for path in (ROOT / "book").glob("[0-9][0-9]-*.md")}


class PageBlocks(HTMLParser):
    """The page's code blocks and "Your turn" blocks, in document order.

    A code block is a ``div.highlight`` (literalincludes and code cells alike); it is folded when it sits inside a
    ``<details>`` without the ``open`` attribute (a dropdown, or a cell whose input is hidden). A "Your turn" block is
    a ``div.your-turn``; the names it poses are the leading identifiers of its inline code."""

    def __init__(self):
        super().__init__()
        self.stack = []  # (tag, role), role in {"folded", "code", "turn", "name", None}
        self.blocks = []  # {"kind": "code", "text", "folded"} or {"kind": "turn", "text", "names"}
        self.name = []

    def roles(self):
        return {role for _, role in self.stack}

    def handle_starttag(self, tag, attrs):
        if tag in VOID:
            return
        attrs = dict(attrs)
        classes = (attrs.get("class") or "").split()
        role = None
        if tag == "details" and "open" not in attrs:
            role = "folded"
        elif tag == "div" and "highlight" in classes:
            role = "code"
            self.blocks.append({"kind": "code", "text": "", "folded": "folded" in self.roles()})
        elif tag == "div" and "your-turn" in classes:
            role = "turn"
            self.blocks.append({"kind": "turn", "text": "", "names": set()})
        elif tag == "code" and "turn" in self.roles():
            role, self.name = "name", []
        self.stack.append((tag, role))

    def handle_startendtag(self, tag, attrs):
        pass  # <path/>, <br/>: nothing to open or close

    def handle_endtag(self, tag):
        if all(open_tag != tag for open_tag, _ in self.stack):
            return
        while self.stack:
            open_tag, role = self.stack.pop()
            if role == "name":
                identifier = re.match(r"[A-Za-z_]\w*", "".join(self.name).strip())
                if identifier:
                    self.blocks[-1]["names"].add(identifier.group())
            if open_tag == tag:
                break

    def handle_data(self, data):
        roles = self.roles()
        if "code" in roles or "turn" in roles:
            self.blocks[-1]["text"] += data
        if "name" in roles:
            self.name.append(data)


def blocks_of(html: str) -> list[dict]:
    parser = PageBlocks()
    parser.feed(html)
    return parser.blocks


def defines(block: dict, name: str) -> bool:
    return block["kind"] == "code" and re.search(rf"\bdef {name}\(", block["text"]) is not None


def shown_too_early(blocks: list[dict], name: str, chapter: int, own_chapter: bool) -> list[str]:
    """What is wrong with how a page shows the graded function ``name`` of chapter ``chapter``: a def of it in an
    open code block (on an earlier chapter's page, anywhere; on its own page, before the block that poses it), or a
    def on its own page with no "Your turn" block before it that names it and the command that grades it."""
    problems, posed = [], False
    for block in blocks:
        if block["kind"] == "turn" and name in block["names"]:
            if f"minippo grade {chapter}" not in block["text"]:
                problems.append(f"the Your turn block that poses {name} does not name `minippo grade {chapter}`")
            posed = True
        elif defines(block, name):
            if not block["folded"] and not (own_chapter and posed):
                problems.append(
                    f"def {name}( is in an open code block" + (" before it is posed" if own_chapter else "")
                )
            if own_chapter and not posed:
                problems.append(f"def {name}( is shown before a Your turn block poses {name}")
    return problems


@pytest.fixture(scope="module")
def page_blocks(built_book):
    return {
        number: blocks_of((built_book / f"{stem}.html").read_text(encoding="utf-8")) for number, stem in PAGES.items()
    }


def test_the_graded_functions_are_read_from_the_exercises():
    chapters = {chapter for chapter, _ in GRADED}
    assert len(GRADED) >= 30 and len(chapters) >= 10, GRADED
    assert (7, "gae") in GRADED and (6, "clip_objective") in GRADED
    assert chapters <= set(PAGES), f"exercise modules with no chapter page: {chapters - set(PAGES)}"


SAMPLE = """<article>
<div class="tip your-turn admonition"><p>Your turn: <code><span>td_residuals</span></code></p>
<ul><li><code>gae(rewards, values)</code> returns ...</li></ul>
<p>Grade them with <code>minippo grade 7</code>.</p></div>
<details class="sd-dropdown"><summary>minippo's <code>gae</code></summary>
<div class="highlight-python"><div class="highlight">
<pre><span class="k">def</span> <span>gae</span>(x):</pre></div></div>
</details>
<div class="highlight"><pre><span class="k">def</span> <span class="nf">td_residuals</span>(x):<br/></pre></div>
<details open><div class="highlight"><pre>def discounted_returns(x):</pre></div></details>
</article>"""


def test_the_page_reader_tells_folded_code_from_open_code_and_finds_what_is_posed():
    blocks = blocks_of(SAMPLE)
    assert [block["kind"] for block in blocks] == ["turn", "code", "code", "code"]
    assert blocks[0]["names"] == {"td_residuals", "gae", "minippo"}
    assert [block["folded"] for block in blocks[1:]] == [True, False, False]
    assert shown_too_early(blocks, "gae", 7, own_chapter=True) == []
    # shown open after it is posed: allowed on its own page, never on an earlier chapter's
    assert shown_too_early(blocks, "td_residuals", 7, own_chapter=True) == []
    assert shown_too_early(blocks, "td_residuals", 7, own_chapter=False) == [
        "def td_residuals( is in an open code block"
    ]
    # an open <details> is not folded, and discounted_returns is not posed on this page
    assert len(shown_too_early(blocks, "discounted_returns", 7, own_chapter=True)) == 2
    assert shown_too_early(blocks, "gae", 8, own_chapter=True) == [
        "the Your turn block that poses gae does not name `minippo grade 8`"
    ]
    # the answer above the question
    swapped = blocks_of(SAMPLE.replace("<details class", "<section class").replace("</details>", "</section>", 1))
    assert shown_too_early(swapped, "gae", 7, own_chapter=False) == ["def gae( is in an open code block"]


@pytest.mark.timeout(1800)
@pytest.mark.parametrize("chapter, name", GRADED, ids=[f"ch{chapter:02d}-{name}" for chapter, name in GRADED])
def test_no_graded_answer_is_printed_above_its_exercise(page_blocks, chapter, name):
    problems = []
    for number, blocks in page_blocks.items():
        if number <= chapter:
            problems += [f"{PAGES[number]}: {p}" for p in shown_too_early(blocks, name, chapter, number == chapter)]
    assert not problems, "; ".join(problems)


@pytest.mark.timeout(1800)
def test_the_pages_fold_minippos_answers_behind_your_turn_blocks(page_blocks):
    """The reader above is not reading nothing: the chapters hold code, Your turn blocks, and folded answers."""
    posed = {
        (number, name)
        for number, blocks in page_blocks.items()
        for b in blocks
        if b["kind"] == "turn"
        for name in b["names"]
    }
    folded = {
        (number, name)
        for number, blocks in page_blocks.items()
        for b in blocks
        for _, name in GRADED
        if b["kind"] == "code" and b["folded"] and defines(b, name)
    }
    assert all(any(b["kind"] == "code" for b in blocks) for blocks in page_blocks.values())
    assert len(posed & set(GRADED)) >= 20, sorted(posed & set(GRADED))
    assert {(7, "gae"), (6, "clip_objective"), (3, "loss_and_grad")} <= folded, sorted(folded)
