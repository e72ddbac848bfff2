"""The demo's ``report.html`` opened in headless Chromium: every figure rendered, a clean console.

The browser is driven through Selenium and the system's chromedriver (Debian packages
``chromium`` and ``chromium-driver``; nothing is downloaded). Without them the test is
skipped on a workstation and FAILS in CI (``CI=true``). A screenshot of the whole page is saved
to ``$MUSCLEMETAB_ARTEFACTS`` (CI keeps that folder) or to the test's temporary folder; its
path is printed.
"""

from __future__ import annotations

import base64
import io
import os
import shutil
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

CHROMIUM_FLAGS = (
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--window-size=1280,1024",
)

#: Every <img> and <svg> of the page: loaded, decoded, and laid out with a non-empty box.
FIGURES_JS = """
return Array.from(document.querySelectorAll('img, svg'))
  .filter(e => !(e.tagName.toLowerCase() === 'svg' && e.parentElement.closest('svg')))
  .map(e => {
    const r = e.getBoundingClientRect();
    const img = e.tagName.toLowerCase() === 'img';
    return {tag: e.tagName.toLowerCase(), label: e.getAttribute('alt') || e.id || '',
            complete: img ? e.complete : true,
            natural_w: img ? e.naturalWidth : r.width, natural_h: img ? e.naturalHeight : r.height,
            box_w: r.width, box_h: r.height};
  });
"""


def _browser():
    """``(chromium, chromedriver)`` paths, or the reason they cannot be had."""
    try:
        import selenium  # noqa: F401
    except ImportError:
        return None, "selenium is not installed (pip install -e '.[test]')"
    chromium = next((p for p in map(shutil.which, ("chromium", "chromium-browser")) if p), None)
    driver = shutil.which("chromedriver")
    if chromium is None or driver is None:
        return None, "no Chromium/chromedriver on this machine (apt-get install chromium chromium-driver)"
    return (chromium, driver), None


class _Figures(HTMLParser):
    """Count the top-level <img> and <svg> elements of the page source."""

    def __init__(self):
        super().__init__()
        self.count, self.svg_depth = 0, 0

    def handle_starttag(self, tag, attrs):
        if tag == "img" and not self.svg_depth:
            self.count += 1
        elif tag == "svg":
            self.count += not self.svg_depth
            self.svg_depth += 1

    def handle_endtag(self, tag):
        if tag == "svg":
            self.svg_depth -= 1


@pytest.fixture()
def chromium(tmp_path):
    found, reason = _browser()
    if found is None:
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(f"the browser test must run in CI: {reason}")
        pytest.skip(reason)
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    binary, chromedriver = found
    options = webdriver.ChromeOptions()
    options.binary_location = binary
    for flag in CHROMIUM_FLAGS:
        options.add_argument(flag)
    options.add_argument(f"--user-data-dir={tmp_path / 'chromium-profile'}")
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(options=options, service=Service(executable_path=chromedriver))
    driver.set_page_load_timeout(120)
    try:
        yield driver
    finally:
        driver.quit()


def _screenshot_folder(tmp_path) -> Path:
    folder = Path(os.environ.get("MUSCLEMETAB_ARTEFACTS") or tmp_path)
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def test_demo_report_renders_in_headless_chromium(demo, chromium, tmp_path, capsys):
    from selenium.webdriver.support.ui import WebDriverWait

    out, _ = demo
    report = out / "report.html"
    source = _Figures()
    source.feed(report.read_text(encoding="utf-8"))
    assert source.count >= 5

    chromium.get(report.as_uri())
    WebDriverWait(chromium, 60).until(
        lambda d: d.execute_script("return document.readyState === 'complete' && "
                                   "Array.from(document.images).every(i => i.complete)"))
    figures = chromium.execute_script(FIGURES_JS)
    # the browser sees every figure of the page source, each decoded and laid out
    assert len(figures) == source.count
    for f in figures:
        assert f["complete"] and f["natural_w"] > 0 and f["natural_h"] > 0, f
        assert f["box_w"] > 0 and f["box_h"] > 0, f

    errors = [e for e in chromium.get_log("browser") if e["level"] in ("SEVERE", "ERROR")]
    assert not errors, errors

    # a screenshot of the whole page, kept for a human to look at
    width, height = chromium.execute_script(
        "return [document.documentElement.scrollWidth, document.documentElement.scrollHeight]")
    shot = chromium.execute_cdp_cmd("Page.captureScreenshot", {
        "format": "png", "captureBeyondViewport": True,
        "clip": {"x": 0, "y": 0, "width": width, "height": min(height, 16000), "scale": 1}})
    png = base64.b64decode(shot["data"])
    path = _screenshot_folder(tmp_path) / "report_demo.png"
    path.write_bytes(png)
    with capsys.disabled():
        print(f"\nscreenshot of report.html: {path}")
    import matplotlib.image

    pixels = matplotlib.image.imread(io.BytesIO(png), format="png")
    assert pixels.shape[0] >= min(height, 16000) - 1 and pixels.shape[1] >= width - 1
    # not a blank page: the rendered figures and text vary the pixels
    assert float(np.std(pixels[..., :3])) > 0.05
