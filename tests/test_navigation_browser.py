"""The book's navigation in headless Chromium, on a 390-pixel phone and on a 1400-pixel desktop.

A reader on a phone taps the menu button ("Toggle primary sidebar"), sees the chapter list and follows a link to
another chapter; on a desktop the same button collapses the sidebar and brings it back. The built HTML
(tests/conftest.py's ``built_book``) is served from 127.0.0.1. Without Chromium, chromedriver or selenium the tests
are skipped, except under CI=true, where they fail. Any SEVERE console message fails a test.

To try another build without building the book, point MINIPPO_BOOK_HTML at its HTML directory.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
from _browser import chromium, serve

pytestmark = pytest.mark.timeout(1500)  # the first test may build the whole book

PHONE, DESKTOP = (390, 844), (1400, 900)
START, TARGET = "01-network.html", "05-clipping.html"


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
    with chromium("the navigation test") as chrome:
        yield chrome


def open_page(driver, url: str, size: tuple[int, int], mobile: bool, exact: bool = True):
    """Loads ``url`` in a viewport of exactly ``size`` CSS pixels (a touch screen when ``mobile``); ``exact=False``
    lets a phone's viewport grow to a page wider than the screen, for a test to measure it."""
    width, height = size
    driver.execute_cdp_cmd(
        "Emulation.setDeviceMetricsOverride",
        {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": mobile},
    )
    driver.execute_cdp_cmd("Emulation.setTouchEmulationEnabled", {"enabled": mobile})
    driver.get_log("browser")  # drop what earlier pages logged
    driver.get(url)
    wait_for(lambda: driver.execute_script("return document.readyState") == "complete", "the page to load")
    assert not exact or driver.execute_script("return window.innerWidth") == width


def wait_for(condition, what: str, seconds: float = 10):
    deadline = time.time() + seconds
    while time.time() < deadline:
        if condition():
            return
        time.sleep(0.05)
    pytest.fail(f"waited {seconds} s for {what}")


def visible_menu_buttons(driver):
    from selenium.webdriver.common.by import By

    buttons = driver.find_elements(By.CSS_SELECTOR, "button[aria-label='Toggle primary sidebar'], .primary-toggle")
    return [b for b in buttons if b.is_displayed()]


def chapter_link(driver, href: str):
    """The sidebar's link to ``href``, and whether a reader can see it: shown, with a size, inside the screen."""
    return driver.execute_script(
        """
        const link = document.querySelector(`.bd-sidebar-primary a[href="${arguments[0]}"]`);
        if (!link) return null;
        const box = link.getBoundingClientRect(), style = getComputedStyle(link);
        const onScreen = box.width > 0 && box.height > 0 && box.right > 0 && box.left < window.innerWidth
                         && box.bottom > 0 && box.top < window.innerHeight;
        const hit = onScreen && document.elementFromPoint(box.left + box.width / 2, box.top + box.height / 2);
        return {onScreen, shown: style.visibility !== "hidden" && onScreen && (hit === link || link.contains(hit))};
        """,
        href,
    )


def severe_messages(driver):
    return [entry["message"] for entry in driver.get_log("browser") if entry["level"] == "SEVERE"]


def test_phone_menu_opens_the_chapter_list_and_a_chapter_link_works(driver, site):
    from selenium.webdriver.common.by import By

    open_page(driver, site + START, PHONE, mobile=True)
    link = chapter_link(driver, TARGET)
    assert link is not None, f"{START} has no sidebar link to {TARGET}"
    assert not link["shown"], "on a phone the chapter list should stay closed until the menu is opened"

    buttons = visible_menu_buttons(driver)
    assert len(buttons) == 1, f"expected one visible menu button on a phone, found {len(buttons)}"
    buttons[0].click()
    wait_for(lambda: chapter_link(driver, TARGET)["shown"], "the chapter list to open after tapping the menu button")

    driver.find_element(By.CSS_SELECTOR, f'.bd-sidebar-primary a[href="{TARGET}"]').click()
    wait_for(lambda: driver.current_url.endswith(TARGET), f"the link to take the reader to {TARGET}")
    wait_for(lambda: driver.execute_script("return document.readyState") == "complete", "the chapter to load")
    heading = driver.find_element(By.CSS_SELECTOR, "article h1").text
    assert "clip" in heading.lower(), heading
    assert not chapter_link(driver, START)["shown"], "the chapter list should be closed on the new page"
    assert severe_messages(driver) == []


def test_desktop_menu_button_collapses_and_restores_the_sidebar(driver, site):
    open_page(driver, site + START, DESKTOP, mobile=False)
    assert chapter_link(driver, TARGET)["shown"], "on a desktop the chapter list is open from the start"
    article_width = driver.execute_script("return document.querySelector('.bd-article-container').offsetWidth")

    buttons = visible_menu_buttons(driver)
    assert len(buttons) == 1, f"expected one visible menu button on a desktop, found {len(buttons)}"
    buttons[0].click()
    wait_for(lambda: not chapter_link(driver, TARGET)["onScreen"], "the sidebar to collapse")
    assert driver.execute_script("return document.querySelector('dialog[open]')") is None, "no pop-up on a desktop"
    wider = driver.execute_script("return document.querySelector('.bd-article-container').offsetWidth")
    assert wider > article_width, (article_width, wider)

    buttons[0].click()
    wait_for(lambda: chapter_link(driver, TARGET)["shown"], "the sidebar to come back")
    assert severe_messages(driver) == []


def test_dark_mode_keeps_the_figures_and_the_explorer_readable(driver, site):
    """The theme switch turns the page dark; the figures keep their own opaque light background (a transparent
    PNG would put black axis labels on the dark page) and the explorer's text keeps its contrast."""
    from selenium.webdriver.common.by import By

    open_page(driver, site + "05-clipping.html", DESKTOP, mobile=False)
    driver.execute_script("localStorage.clear()")
    open_page(driver, site + "05-clipping.html", DESKTOP, mobile=False)
    switch = [b for b in driver.find_elements(By.CSS_SELECTOR, ".theme-switch-button") if b.is_displayed()][0]
    for _ in range(3):
        if driver.execute_script("return document.documentElement.dataset.theme") == "dark":
            break
        switch.click()
    assert driver.execute_script("return document.documentElement.dataset.theme") == "dark"

    page_background, figures = driver.execute_script(
        """
        const rgb = (el) => getComputedStyle(el).backgroundColor;
        const figures = [...document.querySelectorAll("article img[src*='_images/']")].map((img) => {
            const canvas = document.createElement("canvas");
            canvas.width = img.naturalWidth; canvas.height = img.naturalHeight;
            const context = canvas.getContext("2d");
            context.drawImage(img, 0, 0);
            const corner = context.getImageData(1, 1, 1, 1).data;
            return [img.getAttribute("src"), [...corner]];
        });
        return [rgb(document.body), figures];
        """
    )
    assert luminance(page_background) < 0.1, f"the page is not dark: {page_background}"
    assert figures, "no figures on the page"
    for src, (red, green, blue, alpha) in figures:
        assert alpha == 255 and min(red, green, blue) > 200, f"{src} is not drawn on an opaque light background"

    text, background = driver.execute_script(
        """
        const root = document.querySelector("div.corridor-explorer");
        let el = root;
        while (el && ["rgba(0, 0, 0, 0)", "transparent"].includes(getComputedStyle(el).backgroundColor)) {
            el = el.parentElement;
        }
        return [getComputedStyle(root.querySelector(".ce-value") || root).color, getComputedStyle(el).backgroundColor];
        """
    )
    assert contrast(text, background) >= 4.5, (text, background)
    assert severe_messages(driver) == []


def luminance(css_color: str) -> float:
    """WCAG relative luminance of an ``rgb(...)`` or ``rgba(...)`` colour."""
    channels = [float(v) / 255 for v in css_color[css_color.index("(") + 1 : -1].split(",")[:3]]
    linear = [c / 12.92 if c <= 0.03928 else ((c + 0.055) / 1.055) ** 2.4 for c in channels]
    return 0.2126 * linear[0] + 0.7152 * linear[1] + 0.0722 * linear[2]


def contrast(first: str, second: str) -> float:
    light, dark = sorted((luminance(first), luminance(second)), reverse=True)
    return (light + 0.05) / (dark + 0.05)


TABLE_PAGES = ("12-pixels.html", "13-language-model.html", "14-grpo-dpo.html")


@pytest.mark.parametrize("page", TABLE_PAGES)
def test_the_tables_of_chapters_12_to_14_fit_a_phone(driver, site, page):
    """Chapters 12, 13 and 14 show results as tables of a few short numbers: on a 390-pixel phone each must be
    read whole, without scrolling sideways inside its box."""
    open_page(driver, site + page, PHONE, mobile=True)
    tables = driver.execute_script(
        """
        return [...document.querySelectorAll("article table")].map((table) => {
            const box = table.getBoundingClientRect(), parent = table.parentElement;
            return {first: table.innerText.slice(0, 40), right: box.right, width: table.scrollWidth,
                    room: parent.clientWidth};
        });
        """
    )
    assert len(tables) >= 2, f"{page} shows {len(tables)} tables"
    too_wide = [t for t in tables if t["width"] > t["room"] or t["right"] > PHONE[0]]
    assert too_wide == [], too_wide
    assert severe_messages(driver) == []


def test_no_page_is_wider_than_a_phone(driver, site, html_dir):
    """Every page of the book fits a 390-pixel phone: nothing in its prose (a long inline command, say) pushes the page
    wider than the screen; code blocks, tables and outputs scroll inside their own boxes."""
    pages = sorted(path.name for path in html_dir.glob("*.html") if path.stem not in ("genindex", "search"))
    too_wide = {}
    for page in pages:
        open_page(driver, site + page, PHONE, mobile=True, exact=False)
        width = driver.execute_script("return document.documentElement.scrollWidth")
        if width > PHONE[0]:
            too_wide[page] = width
    assert len(pages) >= 20 and too_wide == {}, too_wide
