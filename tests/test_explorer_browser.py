"""The corridor explorer in the built book, driven in headless Chromium the way a reader would use it.

The built HTML (tests/conftest.py's ``built_book``) is served from 127.0.0.1 on a free port. Each test loads the
page, uses the explorer's own controls (buttons, radio buttons, sliders moved with the keyboard) and reads what
is on the screen: the trust-region light, the status line, the band, the event log. Any JavaScript error or other
SEVERE console message fails the test. Without Chromium, chromedriver or selenium the tests are skipped, except
under CI=true, where they fail: the explorer must be checked in CI.

To try the explorer on other built HTML without building the book, point MINIPPO_EXPLORER_HTML at its directory.
"""

from __future__ import annotations

import os
import re
import time
from pathlib import Path

import pytest
from _browser import chromium, serve

from minippo.toys import corridor as cd

# the first test may build the whole book (the built_book fixture); every wait below has its own, shorter limit
pytestmark = pytest.mark.timeout(1500)

PAGE = "05-clipping.html"


@pytest.fixture(scope="module")
def html_dir(request) -> Path:
    override = os.environ.get("MINIPPO_EXPLORER_HTML")
    if override:
        return Path(override)
    return request.getfixturevalue("built_book")


def explorer_page(html_dir: Path) -> str:
    """Chapter 5's page, or else the first page of the book that embeds an explorer."""
    preferred = html_dir / PAGE
    candidates = [preferred] if preferred.exists() else []
    candidates += sorted(p for p in html_dir.glob("*.html") if p != preferred)
    for page in candidates:
        if 'class="corridor-explorer"' in page.read_text(encoding="utf-8", errors="replace"):
            return page.name
    pytest.fail(f'no page of the built book in {html_dir} embeds <div class="corridor-explorer">')


@pytest.fixture(scope="module")
def site(html_dir):
    with serve(html_dir) as base:
        yield base + explorer_page(html_dir)


@pytest.fixture(scope="module")
def browser():
    with chromium("the explorer's browser test", "1100,1600") as driver:
        yield driver


def severe_messages(driver):
    return [entry["message"] for entry in driver.get_log("browser") if entry["level"] == "SEVERE"]


class Reader:
    """What a reader sees of, and does to, the first explorer on the page."""

    def __init__(self, driver, url):
        from selenium.webdriver.common.by import By

        self.By = By
        self.driver = driver
        driver.get(url)
        deadline = time.time() + 20
        while time.time() < deadline:
            roots = driver.find_elements(By.CSS_SELECTOR, "div.corridor-explorer")
            if roots and roots[0].get_attribute("data-ready") == "true":
                break
            time.sleep(0.05)
        else:
            pytest.fail("the explorer did not start on " + url + ": " + "; ".join(severe_messages(driver)))
        self.root = roots[0]
        self.count = len(roots)
        driver.execute_script("arguments[0].scrollIntoView()", self.root)

    def find(self, css):
        return self.root.find_element(self.By.CSS_SELECTOR, css)

    def find_all(self, css):
        return self.root.find_elements(self.By.CSS_SELECTOR, css)

    def preset(self, name):
        self.find(f"button.ce-preset[data-preset='{name}']").click()

    def fastest(self):
        from selenium.webdriver.common.keys import Keys

        self.find("input[data-setting='speed']").send_keys(Keys.END)

    def play(self):
        button = self.find("button.ce-play")
        if button.get_attribute("aria-pressed") != "true":
            button.click()

    def pause(self):
        button = self.find("button.ce-play")
        if button.get_attribute("aria-pressed") == "true":
            button.click()

    def step_until(self, until, most=6000):
        """Clicks Step (one epoch) until ``until(screen)`` holds; fails after ``most`` steps. Unlike watching a
        playing explorer, this cannot miss a state that lasts only a few epochs on a slow machine."""
        self.pause()
        step = self.find("button.ce-step")
        for _ in range(most):
            step.click()
            screen = self.screen()
            if until(screen):
                return screen
        pytest.fail(f"not reached in {most} steps; last screen {screen}")

    def objective(self, name):
        self.find(f"input[type='radio'][value='{name}']").click()

    def screen(self):
        """The light and the status line, read in one go (the explorer may be playing)."""
        texts = self.driver.execute_script(
            """
            const root = arguments[0];
            const text = (css) => root.querySelector(css).textContent.trim();
            return [text('.ce-light-text'), text('.ce-value.ce-round'), text('.ce-value.ce-epoch'),
                    text('.ce-value.ce-return'), text('.ce-value.ce-kl'), root.querySelector('.ce-light').className];
            """,
            self.root,
        )
        light, rnd, epoch, ret, kl, light_class = texts
        assert light in ("trust region held", "trust region broken"), light
        match_return = re.fullmatch(r"([−\-]?\d+\.\d+) / (\d+\.\d+) optimal", ret)
        match_kl = re.fullmatch(r"(\d+\.\d+) \(limit (\d+\.\d+)\)", kl)
        assert match_return and match_kl, (ret, kl)
        return {
            "light": light.rsplit(" ", 1)[1],
            "round": int(rnd),
            "epoch": epoch,
            "return": float(match_return.group(1).replace("−", "-")),
            "optimal": float(match_return.group(2)),
            "kl": float(match_kl.group(1)),
            "limit": float(match_kl.group(2)),
            "light_class": light_class,
        }

    def light(self):
        return self.screen()["light"]

    def stat(self, name):
        return self.find(f".ce-value.ce-{name}").text

    def round(self):
        return self.screen()["round"]

    def returns(self):
        """(return, optimal) as the status line shows them."""
        screen = self.screen()
        return screen["return"], screen["optimal"]

    def kl(self):
        screen = self.screen()
        return screen["kl"], screen["limit"]

    def log(self):
        """The log's lines, read in one script call: while playing, the list is redrawn between two reads."""
        return self.driver.execute_script(
            "return Array.from(arguments[0].querySelectorAll('.ce-log-list li'), (li) => li.textContent.trim());",
            self.root,
        )

    def watch(self, until, timeout=60.0, every=0.05):
        """Samples the screen until ``until(samples)`` is true; fails after ``timeout`` seconds."""
        samples = []
        deadline = time.time() + timeout
        while time.time() < deadline:
            samples.append(self.screen())
            if until(samples):
                return samples
            time.sleep(every)
        pytest.fail(f"timed out; last samples {samples[-3:]}")


@pytest.fixture
def reader(browser, site):
    severe_messages(browser)  # start each test with an empty console
    page = Reader(browser, site)
    yield page
    page.pause()
    errors = severe_messages(browser)
    assert not errors, "console errors: " + " | ".join(errors)


def test_the_explorer_starts_with_all_its_parts(reader):
    assert reader.light() == "held"
    assert reader.round() == 1 and reader.stat("epoch").startswith("0/")
    assert len(reader.find_all("button.ce-state")) == cd.N_STATES
    assert len(reader.find_all("button.ce-preset")) == 3
    assert {e.get_attribute("value") for e in reader.find_all("input[type='radio']")} == set(cd.OBJECTIVES)
    for setting in ("epsilon", "step_size", "epochs", "noise", "speed"):
        slider = reader.find(f"input[data-setting='{setting}']")
        label = reader.root.find_element(reader.By.CSS_SELECTOR, f"label[for='{slider.get_attribute('id')}']")
        assert label.text.strip(), setting  # every control has a visible label
    ret, optimal = reader.returns()
    uniform = cd.expected_return([[0.0, 0.0]] * cd.N_STATES)
    assert (round(ret, 3), optimal) == (round(uniform, 3), round(cd.optimal_return(), 3))


def test_stepping_shows_the_numbers_minippo_computes(reader):
    reader.preset("clip")
    step = reader.find("button.ce-step")
    for _ in range(25):
        step.click()
    expected = cd.run({"preset": "clip"}, ticks=25)[-1]
    assert reader.round() == expected["round"] and reader.stat("epoch") == f"{expected['epoch']}/10"
    assert reader.returns()[0] == pytest.approx(expected["return"], abs=6e-4)
    assert reader.kl()[0] == pytest.approx(expected["kl"], abs=6e-4)
    # the table shows the selected state's numbers: select s4 with the keyboard
    from selenium.webdriver.common.keys import Keys

    reader.find_all("button.ce-state")[4].send_keys(Keys.ENTER)
    cells = [c.text for c in reader.find_all(".ce-table tbody tr")[1].find_elements(reader.By.TAG_NAME, "td")]
    assert cells[0] == f"{round(100 * expected['probs'][4][1])}%"
    assert float(cells[1]) == pytest.approx(expected["ratios"][4][1], abs=6e-3)


def test_clip_preset_holds_the_light_and_the_return_rises(reader):
    reader.preset("clip")
    start, optimal = reader.returns()
    reader.fastest()
    reader.play()
    samples = reader.watch(lambda s: s[-1]["round"] >= 30)
    reader.pause()
    lights = {sample["light"] for sample in samples}
    assert lights == {"held"}, samples
    assert not [line for line in reader.log() if "broke the limit" in line]  # not even between two samples
    ret = reader.returns()[0]
    assert start < 0.0 < ret
    assert ret >= 0.9 * optimal
    by_round = {}
    for sample in samples:
        by_round[sample["round"]] = sample["return"]  # the last value seen in each round
    rounds = sorted(by_round)
    assert by_round[rounds[-1]] > by_round[rounds[len(rounds) // 3]] > by_round[rounds[0]], by_round  # rising


def test_no_clip_preset_breaks_the_band(reader):
    reader.preset("noclip")
    broken = reader.step_until(lambda screen: screen["light"] == "broken")
    assert broken["kl"] > broken["limit"]  # the light and the numbers agree
    assert "ce-broken" in broken["light_class"]  # drawn as broken, not only labelled so
    reader.watch(lambda s: any("broke the limit" in line for line in reader.log()), timeout=10)


def test_switching_to_clip_mid_run_brings_the_light_back(reader):
    reader.preset("noclip")
    reader.fastest()
    switched_in = reader.step_until(lambda screen: screen["light"] == "broken")["round"]
    reader.objective("clip")
    assert any("objective → clip" in line for line in reader.log())
    reader.play()
    # the snapshot refreshes at the end of the round; from the round after next on, the clip keeps the light on
    samples = reader.watch(lambda s: s[-1]["round"] >= switched_in + 12, timeout=60)
    reader.pause()
    later = [sample["light"] for sample in samples if sample["round"] >= switched_in + 2]
    assert later and set(later) == {"held"}, samples
    broke = [line for line in reader.log() if "broke the limit" in line]
    rounds_broken = [int(re.match(r"round (\d+)", line).group(1)) for line in broke]
    assert all(r < switched_in + 2 for r in rounds_broken), broke
    assert reader.light() == "held"


def test_moving_epsilon_changes_the_band(reader):
    from selenium.webdriver.common.keys import Keys

    reader.preset("clip")
    band = reader.find("rect.ce-band")
    width_at = {}
    width_at[0.2] = band.size["width"]
    assert band.get_attribute("data-low") == "0.80" and band.get_attribute("data-high") == "1.20"
    slider = reader.find("input[data-setting='epsilon']")
    slider.send_keys(Keys.HOME)
    width_at[0.05] = band.size["width"]
    assert band.get_attribute("data-low") == "0.95" and band.get_attribute("data-high") == "1.05"
    assert reader.find("output[for='" + slider.get_attribute("id") + "']").text == "0.05"
    assert reader.kl()[1] < 0.01
    slider.send_keys(Keys.END)
    width_at[0.5] = band.size["width"]
    assert band.get_attribute("data-low") == "0.50" and band.get_attribute("data-high") == "1.50"
    assert reader.kl()[1] == pytest.approx(0.25)
    assert width_at[0.05] < width_at[0.2] < width_at[0.5]
    assert width_at[0.5] == pytest.approx(10 * width_at[0.05], rel=0.05)  # the band is drawn to scale
    assert any("ε → 0.50" in line for line in reader.log())


def test_huge_step_preset_stays_bounded(reader):
    """Clip with a ten times larger step and 40 epochs: the KL peaks higher than under the clip preset, but far
    below the unclipped objective with the same step. The chart's KL axis, scaled to the largest KL seen, is read
    off the screen and checked against minippo's own trajectory up to the same tick."""
    reader.preset("hugestep")
    reader.fastest()
    reader.play()
    reader.watch(lambda s: s[-1]["round"] >= 10, timeout=60)
    reader.pause()
    screen = reader.screen()
    epoch, epochs = (int(x) for x in screen["epoch"].split("/"))
    ticks = (screen["round"] - 1) * epochs + epoch
    axis_top = float(reader.find("svg.ce-chart text.ce-axis-kl").text)  # the first KL label is the axis top
    trace = cd.run({"preset": "hugestep"}, ticks=ticks)
    peak = max(r["kl"] for r in trace)
    assert axis_top == pytest.approx(max(2.5 * cd.kl_limit(0.2), 1.08 * peak), abs=0.006)
    unclipped = cd.run({"preset": "hugestep", "objective": "cpi"}, ticks=ticks)
    assert peak < 0.25 * max(r["kl"] for r in unclipped)
    assert screen["return"] > 0.8 * screen["optimal"]


def test_a_slider_drag_is_one_line_of_the_log(reader):
    """Dragging ε through many values moves the band at every value but logs the change once, when the drag ends."""
    from selenium.webdriver.common.action_chains import ActionChains

    reader.preset("clip")
    before = reader.log()
    slider = reader.find("input[data-setting='epsilon']")
    band = reader.find("rect.ce-band")
    # note the band's lower edge at every value the slider passes through
    reader.driver.execute_script(
        "const [slider, band] = arguments; window.bandLows = [];"
        "slider.addEventListener('input', () => window.bandLows.push(band.getAttribute('data-low')));",
        slider,
        band,
    )
    drag = ActionChains(reader.driver).click_and_hold(slider)
    for _ in range(6):
        drag.move_by_offset(-12, 0)
    drag.release().perform()
    lows = reader.driver.execute_script("return window.bandLows;")
    assert len(set(lows)) >= 3, lows  # the band followed the drag
    added = reader.log()[: len(reader.log()) - len(before)]
    assert len([line for line in added if "ε →" in line]) == 1, added
    assert f"band [{band.get_attribute('data-low')}," in added[0]  # the line names where the drag ended


def test_band_labels_do_not_overlap_at_the_narrowest_band(reader):
    from selenium.webdriver.common.keys import Keys

    reader.preset("clip")
    reader.find("input[data-setting='epsilon']").send_keys(Keys.HOME)  # ε = 0.05
    low, high = reader.driver.execute_script(
        "return Array.from(arguments[0].querySelectorAll('text.ce-band-label'), (t) => {"
        "const box = t.getBoundingClientRect(); return [box.left, box.right, t.textContent];});",
        reader.root,
    )
    assert (low[2], high[2]) == ("0.95", "1.05")
    assert low[1] <= high[0], (low, high)


def test_the_kl_penalty_chapter_shows_beta_and_logs_its_changes(browser, site):
    """Chapter 9 embeds the explorer on L^KLPEN: β is in the status line, and eq. 8's rule acts at a round's end."""
    page = Reader(browser, site.rsplit("/", 1)[0] + "/09-kl-penalty.html")
    assert page.find("input[type='radio'][value='klpen']").get_attribute("checked")
    beta = page.find(".ce-stat-beta")
    assert beta.is_displayed() and page.stat("beta") == "1"
    screen = page.step_until(lambda s: s["round"] == 2)
    expected = cd.run({"preset": "clip", "objective": "klpen"}, ticks=11)[-1]
    assert screen["epoch"] == "1/10" and page.stat("beta") == f"{expected['beta']:g}"
    assert any("β doubles to 2" in line for line in page.log()), page.log()
    assert not severe_messages(browser)
