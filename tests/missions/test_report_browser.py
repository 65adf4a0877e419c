"""The campaign report as a reader sees it: report.html loaded in headless Chromium
(Debian's ``chromium`` and ``chromium-driver``, which ``scripts/setup.sh --test``
installs), driven by Selenium, in a window 1400 px wide.

Checked: every figure's image decodes (naturalWidth > 0), no table, figure or image
reaches past the window's right edge or overflows its own box, the page has no horizontal
scroll bar, and no header cell is empty. The report is built from the report tests'
campaign-shaped table (real catalog platforms, the seven families) with five
algorithms, one of which never ran a family."""

import shutil
from pathlib import Path

import pytest
from selenium import webdriver
from selenium.webdriver.chrome.options import Options
from selenium.webdriver.chrome.service import Service

from ft_sitl.missions.report import write_report
from ft_sitl.missions.results import to_frame
from ft_sitl.scenarios.families import FAMILIES
from tests.missions.test_report import META, SPEC, _real_platforms, _rows

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

WIDTH = 1400
ALGORITHMS = ["ego", "fast", "navrl", "pgo", "straight"]


def _executable(*names: str) -> str:
    for name in names:
        path = shutil.which(name) or (f"/usr/bin/{name}" if Path(f"/usr/bin/{name}").exists()
                                      else None)
        if path:
            return path
    pytest.fail(f"none of {', '.join(names)} is installed: the browser test needs Chromium "
                "and its WebDriver (scripts/setup.sh --test installs the Debian packages "
                "chromium and chromium-driver)")


@pytest.fixture(scope="module")
def browser():
    options = Options()
    options.binary_location = _executable("chromium", "chromium-browser")
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                f"--window-size={WIDTH},1000"):
        options.add_argument(arg)
    driver = webdriver.Chrome(options=options,
                              service=Service(_executable("chromedriver")))
    try:
        yield driver
    finally:
        driver.quit()


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    rows = _rows(ALGORITHMS, _real_platforms(8), list(FAMILIES), 2, seed=11)
    rows = [r for r in rows if not (r["algorithm"] == "navrl" and r["family"] == "maze")]
    out = tmp_path_factory.mktemp("browser")
    return write_report(to_frame(rows), out, campaign_spec=SPEC, meta=META)["report.html"]


# what the page looks like to the reader, measured by the browser
_MEASURE = """
const W = document.documentElement.clientWidth;
const boxes = [];
for (const el of document.querySelectorAll('table, figure, img, pre')) {
  const r = el.getBoundingClientRect();
  boxes.push({tag: el.tagName, name: el.className || el.alt || el.id || '',
              left: r.left, right: r.right, scroll: el.scrollWidth, client: el.clientWidth});
}
const images = [...document.images].map(i => ({name: i.alt, complete: i.complete,
                                               natural: i.naturalWidth}));
const emptyHeads = [...document.querySelectorAll('thead th')]
  .filter(th => th.textContent.trim() === '').map(th => th.closest('table').className);
return {inner: window.innerWidth, client: W,
        pageScroll: document.documentElement.scrollWidth, boxes, images, emptyHeads};
"""


def test_report_in_a_1400_px_browser_window(browser, page):
    browser.get(page.resolve().as_uri())
    m = browser.execute_script(_MEASURE)
    assert m["inner"] == WIDTH
    # every image decodes
    assert {i["name"] for i in m["images"]} == {f.stem for f in page.parent.glob("*.png")}
    assert len(m["images"]) == 7 + len(ALGORITHMS)
    for img in m["images"]:
        assert img["complete"] and img["natural"] > 0, img
    # nothing runs past the right edge or overflows its own box
    tables = {b["name"] for b in m["boxes"] if b["tag"] == "TABLE"}
    assert {"facts", "scores", "families", "fits", "coefficients", "collinearity",
            "failures", "metrics"} <= tables
    for b in m["boxes"]:
        assert b["left"] >= 0 and b["right"] <= m["client"], b
        if b["tag"] != "PRE":   # a <pre> scrolls by design (overflow-x: auto)
            assert b["scroll"] <= b["client"] + 1, b
    assert m["pageScroll"] <= m["client"], "the page scrolls sideways"
    assert m["emptyHeads"] == []
