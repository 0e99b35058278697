"""The book's display equations fit their column, measured in headless Chromium on every page of the built book.

MathJax breaks a long display equation at its operators (``displayOverflow: 'linebreak'`` in book/_config.yml); what
it cannot break is split by hand. An equation that still does not fit is cut at the column's edge behind a
scrollbar, and a reader sees half a formula. At a desktop's 1280 pixels no display equation may be wider than its
column; at a phone's 390 pixels at most a tenth of them may be (a few fractions cannot be made narrower than a phone
without making them unreadable).

"Wider than its column" is measured on the ink: the boxes of the rendered characters and rules of each equation,
against the content box of the ``div.math`` Sphinx puts it in and against the equation's number, "(14.4)", which
Sphinx floats at the column's right: ink past the column's edge or under the number is a formula cut short.
Any SEVERE console message (a MathJax file that did not load, say) fails a test too, and so does a request to any
host but the test's own: the book renders math offline.

To measure another build without building the book, point MINIPPO_BOOK_HTML at its HTML directory.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
from _browser import chromium, serve

pytestmark = pytest.mark.timeout(1500)  # the first test may build the whole book

DESKTOP, PHONE = (1280, 900), (390, 844)
PHONE_SHARE = 0.1  # at most this share of the book's display equations may be wider than a phone's column
SLACK = 1.0  # CSS pixels: rounding of the boxes' edges

# For each display equation of the page (a div.math that holds MathJax's display container): how far its ink reaches
# past the column on either side, in CSS pixels, and the first characters of its TeX for the report.
MEASURE = """
const done = arguments[arguments.length - 1];
const measure = () => [...document.querySelectorAll("article div.math")].map((box) => {
    const container = box.querySelector("mjx-container[display='true']");
    if (!container) return {rendered: false, tex: box.textContent.trim().slice(0, 80)};
    const math = container.querySelector("mjx-math");
    const style = getComputedStyle(box), outer = box.getBoundingClientRect();
    const left = outer.left + box.clientLeft + parseFloat(style.paddingLeft);
    const right = left + box.clientWidth - parseFloat(style.paddingLeft) - parseFloat(style.paddingRight);
    const number = box.querySelector(".eqno"), label = number && number.getBoundingClientRect();
    let inkLeft = Infinity, inkRight = -Infinity, underNumber = false;
    for (const node of math.querySelectorAll("*")) {
        if (node.children.length) continue;  // the leaves: characters, rules, spaces
        const rect = node.getBoundingClientRect();
        if (rect.width <= 0 || rect.height <= 0) continue;
        inkLeft = Math.min(inkLeft, rect.left);
        inkRight = Math.max(inkRight, rect.right);
        underNumber ||= !!label && rect.right > label.left + 1 && rect.left < label.right - 1
                         && rect.bottom > label.top + 1 && rect.top < label.bottom - 1;
    }
    const source = container.querySelector("mjx-assistive-mml, math");
    return {rendered: true, id: box.id, column: right - left, underNumber,
            past: Math.max(inkRight - right, left - inkLeft, 0),
            tex: (box.getAttribute("data-tex") || (source ? source.textContent : "")).trim().slice(0, 80)};
});
// a page without math loads no MathJax; one with math and no MathJax shows its display math unrendered
if (!(window.MathJax && MathJax.startup && MathJax.startup.promise)) { done({equations: measure()}); }
else { MathJax.startup.promise.then(() => done({equations: measure()}), (e) => done({error: String(e)})); }
"""


@pytest.fixture(scope="module")
def html_dir(request) -> Path:
    override = os.environ.get("MINIPPO_BOOK_HTML")
    return Path(override) if override else request.getfixturevalue("built_book")


@pytest.fixture(scope="module")
def site(html_dir):
    with serve(html_dir) as base:
        yield base


@pytest.fixture(scope="module")
def driver():
    with chromium("the equations' browser test") as chrome:
        chrome.set_script_timeout(60)
        yield chrome


def book_pages(html_dir: Path) -> list[str]:
    return sorted(path.name for path in html_dir.glob("*.html") if path.stem not in ("genindex", "search", "index"))


def requests_made(driver) -> list[str]:
    return driver.execute_script("return performance.getEntriesByType('resource').map((entry) => entry.name)")


def equations_of(driver, url: str, size: tuple[int, int]) -> list[dict]:
    """Loads ``url`` in a viewport of ``size`` CSS pixels (a touch screen below 600 pixels), waits for MathJax to
    finish, and measures each display equation; fails on a SEVERE console message or a request off the test's host."""
    width, height = size
    mobile = width < 600
    driver.execute_cdp_cmd(
        "Emulation.setDeviceMetricsOverride",
        {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": mobile},
    )
    driver.get_log("browser")  # drop what earlier pages logged
    driver.get(url)
    deadline = time.time() + 20
    while driver.execute_script("return document.readyState") != "complete":
        if time.time() > deadline:
            pytest.fail(f"{url} did not load in 20 s")
        time.sleep(0.05)
    result = driver.execute_async_script(MEASURE)
    assert "error" not in result, f"{url}: {result.get('error')}"
    severe = [entry["message"] for entry in driver.get_log("browser") if entry["level"] == "SEVERE"]
    assert severe == [], f"{url}: {severe}"
    host = url.split("/")[2]
    elsewhere = [name for name in requests_made(driver) if name.split("/")[2] != host]
    assert elsewhere == [], f"{url} asked another host for {elsewhere}"
    unrendered = [e["tex"] for e in result["equations"] if not e["rendered"]]
    assert unrendered == [], f"{url}: display math MathJax did not render: {unrendered}"
    return result["equations"]


def too_wide(equations: list[dict]) -> list[dict]:
    return [e for e in equations if e["past"] > SLACK or e["underNumber"]]


def report(page: str, equations: list[dict]) -> str:
    return "; ".join(
        f"{page} {e['id'] or e['tex']!r}: {e['past']:.0f} px past a {e['column']:.0f} px column"
        + (", under its number" if e["underNumber"] else "")
        for e in equations
    )


@pytest.fixture(scope="module")
def measured(driver, site, html_dir) -> dict[tuple[int, int], dict[str, list[dict]]]:
    """Every page's display equations at both widths: {size: {page: equations}}."""
    pages = book_pages(html_dir)
    assert len(pages) >= 20, f"{html_dir} holds {len(pages)} pages"
    return {size: {page: equations_of(driver, site + page, size) for page in pages} for size in (DESKTOP, PHONE)}


def test_the_measure_sees_an_equation_wider_than_its_column(driver, site, html_dir):
    """The same measure on a page of the book whose column is made too narrow for its widest equation: it must see
    the overflow, or the two tests below could pass on a measure that sees nothing."""
    page = "14-grpo-dpo.html" if (html_dir / "14-grpo-dpo.html").exists() else book_pages(html_dir)[0]
    fitting = equations_of(driver, site + page, DESKTOP)
    assert fitting, f"{page} has no display equation"
    driver.execute_script("for (const box of document.querySelectorAll('article div.math')) box.style.width = '40px';")
    narrowed = driver.execute_async_script(MEASURE)["equations"]
    assert len(too_wide(narrowed)) == len(narrowed), report(page, narrowed)


def test_no_display_equation_is_wider_than_its_column_on_a_desktop(measured):
    pages = measured[DESKTOP]
    total = sum(len(equations) for equations in pages.values())
    wide = {page: too_wide(equations) for page, equations in pages.items() if too_wide(equations)}
    assert total >= 50, f"only {total} display equations found in the book"
    assert wide == {}, "wider than the column at 1280 px: " + "; ".join(report(p, e) for p, e in wide.items())


def test_at_most_a_tenth_of_the_display_equations_are_wider_than_a_phone(measured):
    pages = measured[PHONE]
    total = sum(len(equations) for equations in pages.values())
    wide = {page: too_wide(equations) for page, equations in pages.items() if too_wide(equations)}
    count = sum(len(equations) for equations in wide.values())
    assert count <= PHONE_SHARE * total, (
        f"{count} of {total} display equations are wider than the column at 390 px: "
        + "; ".join(report(p, e) for p, e in wide.items())
    )
