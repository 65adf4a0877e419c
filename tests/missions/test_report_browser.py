"""The campaign report as a reader sees it: report.html loaded in headless Chromium
(Debian's ``chromium`` and ``chromium-driver``, which ``scripts/setup.sh --test``
installs), driven by Selenium, in a window 1400 px wide.

Checked: every figure's image decodes (naturalWidth > 0), no table, figure or image
reaches past the window's right edge or overflows its own box, the page has no horizontal
scroll bar, and no header cell is empty. Each figure's SVG, opened in the same browser:
every text is at least 9 px there (at 100 %) and as the page shows its PNG (scaled to the
column), legends list what the figure draws and nothing else, the platform grid names the
algorithms, the composite score labels both bars, the partial-dependence figure says which
algorithm has no line and why. The report is built from the report tests'
campaign-shaped table (real catalog platforms, the seven families) with five
algorithms, one of which never ran a family; two exit reasons never occur, and the
straight baseline meets the same fate on every platform (not estimable)."""

import shutil
from pathlib import Path

import pytest
from selenium import webdriver
from selenium.webdriver.chrome.options import Options
from selenium.webdriver.chrome.service import Service

from ft_sitl.missions import scoring
from ft_sitl.missions.report import _DPI, platform_grid_layout, write_report
from ft_sitl.missions.results import REASONS, to_frame
from ft_sitl.scenarios.families import FAMILIES
from tests.missions.test_report import META, SPEC, _real_platforms, _rows

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

WIDTH = 1400
ALGORITHMS = ["ego", "fast", "navrl", "pgo", "straight"]
PLATFORMS = 8
#: exit reasons no trial of the page's table ends with
NEVER = ("geofence", "loss_of_control")
#: the smallest text a reader is shown (px)
MIN_TEXT_PX = 9.0


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


def _table():
    rows = _rows(ALGORITHMS, _real_platforms(PLATFORMS), list(FAMILIES), 2, seed=11)
    rows = [r for r in rows if not (r["algorithm"] == "navrl" and r["family"] == "maze")]
    for r in rows:
        if r["reason"] in NEVER:
            r["reason"] = "collision"
        if r["algorithm"] == "straight":   # every vehicle meets the same fate
            ok = r["family"] in ("forest", "urban") and r["trial"] == 0
            r.update(success=ok, reason="success" if ok else "collision")
    return to_frame(rows)


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    out = tmp_path_factory.mktemp("browser")
    return write_report(_table(), out, campaign_spec=SPEC, meta=META)["report.html"]


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


# every <text> of an SVG opened as the page: its size in user units (the figure's pt) and
# as drawn at 100 % (px); a text's size is its largest glyph's (a subscript is smaller)
_SVG_TEXTS = """
const out = [];
for (const t of document.querySelectorAll('text')) {
  const m = t.getScreenCTM();
  const scale = Math.hypot(m.a, m.b);
  let size = parseFloat(getComputedStyle(t).fontSize);
  for (const s of t.querySelectorAll('tspan'))
    size = Math.max(size, parseFloat(getComputedStyle(s).fontSize));
  out.push({text: t.textContent.trim(), units: size, px: size * scale,
            legend: !!t.closest('g[id^="legend_"]')});
}
return out;
"""
_SHOWN = """
return [...document.images].map(i => ({name: i.alt, scale: i.clientWidth / i.naturalWidth}));
"""


def _svg(browser, page, name):
    browser.get((page.parent / f"{name}.svg").resolve().as_uri())
    return browser.execute_script(_SVG_TEXTS)


def test_every_figures_text_is_readable_in_its_svg_and_on_the_page(browser, page):
    browser.get(page.resolve().as_uri())
    shown = {i["name"]: i["scale"] for i in browser.execute_script(_SHOWN)}
    assert len(shown) == 7 + len(ALGORITHMS)
    for name, scale in shown.items():
        texts = [t for t in _svg(browser, page, name) if t["text"]]
        assert texts, name
        for t in texts:
            # at 100 % (1 pt = 4/3 px) and as the page draws the PNG (1 pt = DPI/72 px,
            # scaled to the column)
            on_page = t["units"] * _DPI / 72 * scale
            assert t["px"] >= MIN_TEXT_PX and on_page >= MIN_TEXT_PX, (name, t, on_page)


def test_exit_reason_legends_list_the_reasons_that_occur_only(browser, page):
    occurring = [r for r in REASONS if r not in NEVER]
    assert occurring == [r for r in REASONS
                         if r in set(scoring.failure_breakdown(_table()).query("count > 0")
                                     ["reason"].astype(str))]
    for name in ("failures_by_algorithm", "failures_by_family"):
        legend = [t["text"] for t in _svg(browser, page, name) if t["legend"]]
        assert [x for x in legend if x != "exit reason"] == occurring, name
    # the table too, and it says which never occur
    browser.get(page.resolve().as_uri())
    head = browser.execute_script(
        "return [...document.querySelectorAll('table.failures thead th')]"
        ".map(th => th.textContent)")
    assert head == ["Algorithm", "Trials", *occurring]
    assert "No trial ended with: geofence, loss_of_control." in browser.find_element(
        "tag name", "body").text


_PANELS = """
const box = e => { const r = e.getBoundingClientRect();
                   return {left: r.left, right: r.right, top: r.top, bottom: r.bottom}; };
const fig = document.querySelector('g[id^="figure_"]');
const axes = [...fig.children].filter(g => /^axes_/.test(g.id)).map(box);
const legends = [...document.querySelectorAll('g[id^="legend_"]')].map(box);
return {axes, legends};
"""


def test_failures_by_family_puts_its_legend_in_the_grids_empty_slot(browser, page):
    browser.get((page.parent / "failures_by_family.svg").resolve().as_uri())
    m = browser.execute_script(_PANELS)
    # five algorithms: 2 rows x 3 panels, the sixth slot holds the legend
    assert len(m["axes"]) == 6 and len(m["legends"]) == 1
    legend, top_right, bottom_left = m["legends"][0], m["axes"][2], m["axes"][3]
    cx, cy = (legend["left"] + legend["right"]) / 2, (legend["top"] + legend["bottom"]) / 2
    assert top_right["left"] <= cx <= top_right["right"], (legend, top_right)
    assert bottom_left["top"] <= cy <= bottom_left["bottom"], (legend, bottom_left)


def test_platform_grid_names_the_algorithms_under_its_bottom_row(browser, page):
    texts = [t["text"] for t in _svg(browser, page, "platform_grid")]
    _, ncols, _ = platform_grid_layout(
        _table().drop_duplicates("platform").set_index("platform")[["twr_max",
                                                                    "alpha_xy_max"]])
    for algo in ALGORITHMS:   # the legend, and under each bottom panel
        assert texts.count(algo) == 1 + ncols, (algo, texts.count(algo))


def test_composite_score_labels_both_bars_and_explains_only_marks_it_shows(browser, page):
    texts = [t["text"] for t in _svg(browser, page, "composite_score")]
    scores = scoring.composite_score(_table())
    for r in scores.itertuples(index=False):
        assert f"{r.Score:.2f}" in texts and f"{r.FinalScore:.2f}" in texts
    # navrl never ran Maze: its label carries the dagger the title explains
    assert "navrl †" in texts and any("† = not directly comparable" in t for t in texts)


def test_partial_dependence_says_which_algorithm_has_no_line_and_why(browser, page):
    texts = [t["text"] for t in _svg(browser, page, "success_partial_dependence")]
    assert any("straight (not estimable: no variation between platforms)" in t
               for t in texts), texts
    legend = [t["text"] for t in _svg(browser, page, "success_partial_dependence")
              if t["legend"]]
    assert "straight" not in legend and {"ego", "fast", "pgo"} <= set(legend)


# --- the capability-envelope section (issue 44) ----------------------------------------
ENVELOPE_LEVELS = {"gentle": (2.0, 2.0), "paper": (4.0, 3.0), "brisk": (6.0, 6.0),
                   "aggressive": (8.0, 10.0)}


def _envelope_table():
    from ft_sitl.physics.catalog import series

    members = [p for name, p in series().items()
               if name.startswith(("series-0.55kg-UAV1-", "series-5.00kg-UAV16-"))]
    platforms = members + _real_platforms(6)
    rows = []
    for k, (level, (speed, acc)) in enumerate(ENVELOPE_LEVELS.items()):
        for r in _rows(["ego", "fast", "pgo"], platforms, ["forest", "sudden_drop"], 3,
                       seed=20 + k):
            r.update(trial_id=f"{r['trial_id']}/{level}", aggressiveness=level,
                     speed_limit_m_s=speed, acc_limit_m_s2=acc, max_tilt_deg=30.0,
                     saturation_fraction=0.01 * k, tracking_rms_m=0.1 * (k + 1))
            rows.append(r)
    return to_frame(rows)


@pytest.fixture(scope="module")
def envelope_page(tmp_path_factory):
    out = tmp_path_factory.mktemp("envelope")
    return write_report(_envelope_table(), out, campaign_spec=SPEC, meta=META,
                        B=50)["report.html"]


def test_the_envelope_section_fits_the_window_and_its_figures_are_readable(browser,
                                                                           envelope_page):
    browser.get(envelope_page.resolve().as_uri())
    m = browser.execute_script(_MEASURE)
    tables = {b["name"] for b in m["boxes"] if b["tag"] == "TABLE"}
    assert {"envelope-fits", "envelope-thresholds", "envelope-tolerance",
            "envelope-metrics"} <= tables
    for b in m["boxes"]:
        assert b["left"] >= 0 and b["right"] <= m["client"], b
        if b["tag"] != "PRE":
            assert b["scroll"] <= b["client"] + 1, b
    assert m["pageScroll"] <= m["client"], "the page scrolls sideways"
    assert m["emptyHeads"] == []
    shown = {i["name"]: i["scale"] for i in browser.execute_script(_SHOWN)}
    new = {"envelope", "envelope_dose_twr", "envelope_dose_axy", "envelope_tolerance"}
    assert new <= set(shown)
    for name in new:
        assert shown[name] > 0
        texts = [t for t in _svg(browser, envelope_page, name) if t["text"]]
        assert texts, name
        for t in texts:
            on_page = t["units"] * _DPI / 72 * shown[name]
            assert t["px"] >= MIN_TEXT_PX and on_page >= MIN_TEXT_PX, (name, t, on_page)
    # the envelope's legend names the families and the bodies it draws, nothing else
    legend = {t["text"] for t in _svg(browser, envelope_page, "envelope") if t["legend"]}
    assert legend == {"forest", "sudden_drop", "body 0.55kg-UAV1", "body 5.00kg-UAV16"}
