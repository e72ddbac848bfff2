"""The reports of the demo and of a two-subject study opened in headless Chromium, 1 400 and
900 px wide: every figure rendered inside the page's width, a clean console.

The browser is driven through Selenium and the system's chromedriver (Debian packages
``chromium`` and ``chromium-driver``; nothing is downloaded). Without them the test is
skipped on a workstation and FAILS in CI (``CI=true``). A screenshot of the whole page, and one
of every figure at 900 px, are saved to ``$MUSCLEMETAB_ARTEFACTS`` (CI keeps that folder) or to
the test's temporary folder; the paths are printed.
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


@pytest.fixture(scope="module")
def _one_chromium(tmp_path_factory):
    """One headless Chromium for the module's tests (a browser's start is its largest cost)."""
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
    options.add_argument(f"--user-data-dir={tmp_path_factory.mktemp('chromium') / 'chromium-profile'}")
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(options=options, service=Service(executable_path=chromedriver))
    driver.set_page_load_timeout(120)
    try:
        yield driver
    finally:
        driver.quit()


@pytest.fixture()
def chromium(_one_chromium):
    """The module's Chromium as a test finds a new one: a blank page at the window size of its
    flags, its console log emptied (what a test reads of it is its own)."""
    _one_chromium.set_window_size(1280, 1024)
    _one_chromium.get("about:blank")
    _one_chromium.get_log("browser")
    return _one_chromium


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


# ------------------------------------------------------------------ every figure, two widths, two studies


FIGURE_BOXES_JS = """
return Array.from(document.querySelectorAll('figure img')).map(e => {
  const r = e.getBoundingClientRect();
  return {id: e.closest('figure').previousElementSibling.id, complete: e.complete, natural_w: e.naturalWidth,
          box_w: r.width, box_h: r.height, left: r.left, right: r.right};
});
"""


def _every_figure(driver, report: Path, width: int, shots: Path | None, prefix: str) -> list[dict]:
    """Open ``report`` at ``width`` px; every figure decoded and inside the page; at 900 px each
    figure's screenshot into ``shots``."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    driver.set_window_size(width, 1000)
    driver.get(report.as_uri())
    WebDriverWait(driver, 60).until(
        lambda d: d.execute_script("return document.readyState === 'complete' && "
                                   "Array.from(document.images).every(i => i.complete)"))
    viewport = driver.execute_script("return document.documentElement.clientWidth")
    boxes = driver.execute_script(FIGURE_BOXES_JS)
    for b in boxes:
        assert b["complete"] and b["natural_w"] > 0 and b["box_h"] > 0, b
        assert b["left"] >= 0 and b["right"] <= viewport + 0.5, (width, b)  # never wider than the page
    assert driver.execute_script("return document.documentElement.scrollWidth") <= viewport + 1
    if shots is not None:
        for b, element in zip(boxes, driver.find_elements(By.CSS_SELECTOR, "figure img")):
            driver.execute_script("arguments[0].scrollIntoView()", element)
            path = shots / f"{prefix}_{b['id'].removeprefix('figure-')}_{width}px.png"
            path.write_bytes(element.screenshot_as_png)
    return boxes


@pytest.mark.slow
@pytest.mark.opensim
@pytest.mark.parametrize("which", ["demo", "two_subjects"])
def test_every_figure_at_1400_and_900_px(which, request, chromium, tmp_path, capsys):
    import re

    from musclemetab.report.plan import FIGURE_NAMES

    out = request.getfixturevalue("demo")[0] if which == "demo" else request.getfixturevalue("two_subjects")[0]
    report = out / "report.html"
    text = report.read_text(encoding="utf-8")
    drawn = re.findall(r'<h3 id="figure-([^"]+)">Figure \d+\.', text)
    assert drawn == list(FIGURE_NAMES)
    shots = _screenshot_folder(tmp_path) / f"figures_{which}"
    shots.mkdir(parents=True, exist_ok=True)
    wide = _every_figure(chromium, report, 1400, None, which)
    narrow = _every_figure(chromium, report, 900, shots, which)
    assert [b["id"] for b in wide] == [b["id"] for b in narrow] and len(narrow) == text.count("<figure>")
    assert all(n["box_w"] <= w["box_w"] for n, w in zip(narrow, wide))
    saved = sorted(shots.glob(f"{which}_*_900px.png"))
    assert len(saved) == len(narrow)
    errors = [e for e in chromium.get_log("browser") if e["level"] in ("SEVERE", "ERROR")]
    assert not errors, errors
    with capsys.disabled():
        print(f"\nscreenshots of the {which} report's figures at 900 px: {shots}")
