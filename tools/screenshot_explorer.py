"""Screenshots of the corridor explorer in two states, for the README: docs/img/explorer-clip.png and
docs/img/explorer-noclip.png.

    python tools/screenshot_explorer.py [--out docs/img] [--html book/_build/html]

By default the explorer is shown on a bare page that loads book/_static/explorer/ (no book build needed); with
--html it is shown on the built book's chapter 5 page instead. The explorer is driven with its own Step button,
so the pictures are the same on every run: "Clipped objective" after 7 rounds of 10 epochs (state s4's ratios
held at the band's edges), and "No clip, many epochs" 30 epochs into its first round, with the band broken.
Uses headless Chromium (/usr/bin/chromium and /usr/bin/chromedriver) through selenium, like
tests/test_explorer_browser.py.
"""

from __future__ import annotations

import argparse
import functools
import http.server
import shutil
import sys
import tempfile
import threading
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXPLORER = ROOT / "book" / "_static" / "explorer"
CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")
WIDTH = 800  # about sphinx-book-theme's content column, plus margins

BARE_PAGE = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width, initial-scale=1">
<title>corridor explorer</title>
<link rel="stylesheet" href="_static/explorer/corridor-explorer.css">
<script src="_static/explorer/corridor-explorer.js"></script>
<style>body { margin: 0; padding: 8px 16px; background: #fff; }</style>
</head><body><div class="corridor-explorer" data-preset="clip"></div></body></html>
"""

# (file name, preset, Step presses, state to show in the ratio track and the table)
SHOTS = [
    ("explorer-clip.png", "clip", 70, 4),
    ("explorer-noclip.png", "noclip", 30, 0),
]


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


def serve(directory: Path):
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_Quiet, directory=str(directory)))
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server


def start_browser(profile: str):
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for flag in (
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--disable-background-networking",
        "--disable-component-update",
        "--no-first-run",
        "--disable-sync",
        f"--user-data-dir={profile}",
        f"--window-size={WIDTH},2000",
        "--force-device-scale-factor=2",
        "--hide-scrollbars",
    ):
        options.add_argument(flag)
    return webdriver.Chrome(service=Service(str(CHROMEDRIVER)), options=options)


def take(driver, url: str, preset: str, steps: int, state: int, out: Path) -> None:
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    driver.get(url)
    WebDriverWait(driver, 20).until(
        lambda d: d.find_elements(By.CSS_SELECTOR, "div.corridor-explorer[data-ready='true']")
    )
    root = driver.find_element(By.CSS_SELECTOR, "div.corridor-explorer")
    driver.execute_script(
        """
        const [root, preset, steps, state] = arguments;
        const button = root.querySelector(`button.ce-preset[data-preset='${preset}']`);
        if (button.getAttribute('aria-pressed') !== 'true') button.click();
        const step = root.querySelector('button.ce-step');
        for (let i = 0; i < steps; i++) step.click();
        root.querySelectorAll('button.ce-state')[state].click();
        root.scrollIntoView();
        """,
        root,
        preset,
        steps,
        state,
    )
    driver.execute_script("document.activeElement && document.activeElement.blur()")
    root.screenshot(str(out))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "img", help="directory for the PNG files")
    parser.add_argument("--html", type=Path, help="the built book's HTML directory, to use its 05-clipping.html")
    args = parser.parse_args(argv)
    if not CHROMIUM.exists() or not CHROMEDRIVER.exists():
        print(f"error: needs {CHROMIUM} and {CHROMEDRIVER} (apt-get install chromium chromium-driver)", file=sys.stderr)
        return 2
    try:
        import selenium  # noqa: F401
    except ImportError:
        print("error: needs selenium (pip install -e '.[browser]')", file=sys.stderr)
        return 2
    if args.html is not None and not (args.html / "05-clipping.html").exists():
        print(f"error: {args.html / '05-clipping.html'} does not exist; build the book first", file=sys.stderr)
        return 2

    work = Path(tempfile.mkdtemp(prefix="minippo-screens-"))
    profile = tempfile.mkdtemp(prefix="minippo-chromium-")
    try:
        if args.html is None:
            (work / "_static").mkdir()
            shutil.copytree(EXPLORER, work / "_static" / "explorer")
            (work / "index.html").write_text(BARE_PAGE, encoding="utf-8")
            site, page = work, "index.html"
        else:
            site, page = args.html, "05-clipping.html"
        args.out.mkdir(parents=True, exist_ok=True)
        server = serve(site)
        driver = start_browser(profile)
        try:
            url = f"http://127.0.0.1:{server.server_port}/{page}"
            for name, preset, steps, state in SHOTS:
                take(driver, url, preset, steps, state, args.out / name)
                print(f"wrote {args.out / name}")
        finally:
            driver.quit()
            server.shutdown()
            server.server_close()
    finally:
        shutil.rmtree(work, ignore_errors=True)
        shutil.rmtree(profile, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
