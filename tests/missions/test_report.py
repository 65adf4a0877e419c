"""The campaign report (ft_sitl.missions.report): files, embedded figures, tables."""

import base64
import math
import sys
import xml.etree.ElementTree as ET
from html.parser import HTMLParser

import matplotlib
import matplotlib.image
import numpy as np
import pytest

from ft_sitl.missions import regression, scoring
from ft_sitl.missions.report import platform_grid_layout, write_report
from ft_sitl.missions.results import COLUMNS, REASONS, to_frame
from ft_sitl.physics.catalog import catalog
from ft_sitl.scenarios.families import CATEGORY, FAMILIES

pytestmark = pytest.mark.slow  # campaign reports: matplotlib figures, seconds each

FIGURES = ("success_by_family", "success_vs_indicators", "success_partial_dependence",
           "platform_grid", "composite_score", "failures_by_algorithm", "failures_by_family")
META = {"code_version": "0.1.0+g1234abc", "machine": {"cpu_model": "Test CPU 9000",
                                                      "n_cpus": 8},
        "started_utc": "2026-01-02T03:04:05Z", "finished_utc": "2026-01-02T03:06:05Z",
        "wall_time_s": 120.0, "workers": 4}
SPEC = {"name": "unit-test campaign", "algorithms": ["ego", "straight"],
        "families": list(FAMILIES), "trials": 3}


def _rows(algorithms, platforms, families, trials, seed):
    """Trial rows as a campaign writes them; success more likely with a larger TWR_max."""
    rng = np.random.default_rng(seed)
    rows = []
    for algo_i, algo in enumerate(algorithms):
        for p in platforms:
            ind = p.indicators()
            for fam in families:
                for t in range(trials):
                    p_ok = min(0.95, 0.12 * ind.twr_max + 0.1 * algo_i)
                    ok = bool(rng.random() < p_ok)
                    reason = "success" if ok else str(rng.choice(REASONS[1:]))
                    r = dict.fromkeys(COLUMNS)
                    r.update(
                        trial_id=f"{algo}/{p.name}/{fam}/{t}", campaign="unit-test",
                        algorithm=algo, algorithm_params="{}", platform=p.name,
                        platform_category=p.category, mass_kg=p.mass_kg,
                        twr_max=ind.twr_max, alpha_xy_max=float(ind.alpha_xy_max_rad_s2),
                        alpha_z_max=float(ind.alpha_z_max_rad_s2), family=fam,
                        scenario_category=CATEGORY.get(fam, "user"), scenario_index=t,
                        scenario_seed=0, scenario=f"{fam}-{t}", trial=t, seed=t,
                        success=ok, reason=reason, detail="" if ok else "synthetic",
                        time_to_goal_s=float(rng.uniform(10, 40)) if ok else math.nan,
                        path_length_m=float(rng.uniform(40, 80)),
                        max_tilt_deg=math.nan, sim_time_s=60.0, wall_time_s=0.5,
                        code_version="test")
                    rows.append(r)
    return rows


def _real_platforms(n):
    return [p for p in catalog().values() if p.category == "real"][:n]


class _Page(HTMLParser):
    """Tags opened / closed, <img> sources and the text of each table by class."""

    VOID = {"meta", "img", "br", "hr", "link", "input"}

    def __init__(self):
        super().__init__()
        self.stack, self.errors, self.imgs, self.tables, self.text = [], [], [], {}, []
        self._table = None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "img":
            self.imgs.append(a)
        if tag == "table":
            self._table = a.get("class", "")
            self.tables[self._table] = []
        if tag not in self.VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"</{tag}> closes {self.stack[-1:]}")
        else:
            self.stack.pop()
        if tag == "table":
            self._table = None

    def handle_data(self, data):
        self.text.append(data)
        if self._table is not None:
            self.tables[self._table].append(data)


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    df = to_frame(_rows(["ego", "straight"], _real_platforms(6), list(FAMILIES), 3, seed=5))
    out = tmp_path_factory.mktemp("campaign")
    rc_before = dict(matplotlib.rcParams)
    figs_before = (sys.modules["matplotlib.pyplot"].get_fignums()
                   if "matplotlib.pyplot" in sys.modules else None)
    paths = write_report(df, out, campaign_spec=SPEC, meta=META)
    state = {"rc_same": dict(matplotlib.rcParams) == rc_before,
             "figs_same": figs_before is None
             or sys.modules["matplotlib.pyplot"].get_fignums() == figs_before}
    return df, out, paths, state


def _parse(path):
    page = _Page()
    page.feed(path.read_text(encoding="utf-8"))
    page.close()
    return page


def test_every_file_is_written_into_out_dir_report(campaign):
    _, out, paths, _ = campaign
    names = [*FIGURES, "heatmap_ego", "heatmap_straight"]
    expected = {"report.html", "summary.md"} | {f"{n}.{e}" for n in names for e in ("png",
                                                                                  "svg")}
    assert set(paths) == expected
    for name, p in paths.items():
        assert p == out / "report" / name and p.stat().st_size > 0


def test_html_is_well_formed_and_embeds_every_figure(campaign):
    _, out, paths, _ = campaign
    page = _parse(paths["report.html"])
    assert page.errors == [] and page.stack == []
    embedded = {img["alt"]: img["src"] for img in page.imgs}
    pngs = {n[:-4] for n in paths if n.endswith(".png")}
    assert set(embedded) == pngs
    for name, src in embedded.items():
        prefix = "data:image/png;base64,"
        assert src.startswith(prefix)
        assert base64.b64decode(src[len(prefix):]) == paths[f"{name}.png"].read_bytes()
    html_text = paths["report.html"].read_text(encoding="utf-8")
    assert "http://" not in html_text.replace("http://www.w3.org", "")
    assert "<link" not in html_text and "<script" not in html_text


def test_html_shows_the_composite_scores_and_the_run_facts(campaign):
    df, _, paths, _ = campaign
    page = _parse(paths["report.html"])
    scores = " ".join(page.tables["scores"])
    expected = scoring.composite_score(df)
    assert len(expected) == 2
    for r in expected.itertuples(index=False):
        for text in (r.algorithm, f"{r.Score:.2f}", f"{r.Var:.3f}", f"{r.FinalScore:.2f}"):
            assert text in scores
    facts = " ".join(page.tables["facts"])
    for text in ("0.1.0+g1234abc", "Test CPU 9000", "n_cpus: 8", "2026-01-02T03:04:05Z",
                 "120.0 s", f"{len(df) / 120.0:.3g}", "workers", str(len(df))):
        assert text in facts
    text = " ".join(page.text)
    assert "unit-test campaign" in text and "trials: 3" in text   # the spec, as YAML
    assert "Random Perlin-Noise" in " ".join(page.tables["families"])


def test_figures_are_real_png_and_svg_files(campaign):
    _, _, paths, _ = campaign
    for name, p in paths.items():
        if name.endswith(".png"):
            img = matplotlib.image.imread(p)
            assert img.ndim == 3 and img.shape[0] > 150 and img.shape[1] > 150, name
        elif name.endswith(".svg"):
            assert ET.parse(p).getroot().tag == "{http://www.w3.org/2000/svg}svg", name


def test_summary_markdown_links_the_figures(campaign):
    df, _, paths, _ = campaign
    md = paths["summary.md"].read_text(encoding="utf-8")
    for name in paths:
        if name.endswith(".png"):
            assert f"]({name})" in md
    for r in scoring.composite_score(df).itertuples(index=False):
        assert f"| {r.algorithm} | {r.Score:.2f} | {r.Var:.3f} |" in md


def test_no_matplotlib_global_state_changes(campaign):
    *_, state = campaign
    assert state == {"rc_same": True, "figs_same": True}


def test_edge_case_one_algorithm_one_platform_one_family_all_failing(tmp_path):
    rows = _rows(["lonely"], _real_platforms(1), ["maze"], 4, seed=0)
    for r in rows:
        r.update(success=False, reason="timeout", time_to_goal_s=math.nan)
    df = to_frame(rows)
    paths = write_report(df, tmp_path, campaign_spec={}, meta={})
    assert all(p.exists() for p in paths.values())
    page = _parse(paths["report.html"])
    assert page.errors == [] and len(page.imgs) == len(FIGURES) + 1
    scores = " ".join(page.tables["scores"])
    assert "0.00" in scores and "yes" in scores
    assert "not recorded" in " ".join(page.tables["facts"])
    # the same table gives byte-identical figures (only the "generated" time differs)
    again = write_report(df, tmp_path / "again", campaign_spec={}, meta={})
    for name, p in paths.items():
        if name.endswith((".png", ".svg")):
            assert again[name].read_bytes() == p.read_bytes(), name


def test_user_platform_and_scenario_and_missing_combinations(tmp_path):
    rows = _rows(["a", "b"], _real_platforms(2), ["forest", "perlin", "my_mesh"], 2, seed=1)
    for r in rows[:6]:   # a user platform (no catalog entry) with its own indicators
        r.update(platform="my-quad", platform_category="user", twr_max=2.0,
                 alpha_xy_max=300.0, alpha_z_max=12.0)
    # algorithm b never ran perlin; "my_mesh" is a user scenario family
    rows = [r for r in rows if not (r["algorithm"] == "b" and r["family"] == "perlin")]
    df = to_frame(rows)
    paths = write_report(df, tmp_path, campaign_spec={"families": ["forest", "perlin"]},
                         meta={"machine": "a plain string"})
    page = _parse(paths["report.html"])
    assert page.errors == []
    scores = " ".join(page.tables["scores"])
    assert "Random Perlin-Noise" in scores and "no †" in scores
    assert "my_mesh" in " ".join(page.tables["families"])
    assert "a plain string" in " ".join(page.tables["facts"])


def test_platform_grid_layout_places_by_alpha_xy_rows_and_twr_columns():
    import pandas as pd

    plats = list(catalog().values())
    ind = pd.DataFrame({"twr_max": [p.indicators().twr_max for p in plats],
                        "alpha_xy_max": [float(p.indicators().alpha_xy_max_rad_s2)
                                         for p in plats]},
                       index=[p.name for p in plats])
    nrows, ncols, where = platform_grid_layout(ind)
    assert (nrows, ncols) == (6, 6) and len(set(where.values())) == 36
    rows = [sorted((c, n) for n, (r, c) in where.items() if r == k) for k in range(nrows)]
    for k in range(nrows - 1):   # every row's alpha_xy lies below the next row's
        assert max(ind.loc[n, "alpha_xy_max"] for _, n in rows[k]) <= min(
            ind.loc[n, "alpha_xy_max"] for _, n in rows[k + 1])
    for row in rows:             # TWR_max never decreases left to right
        twr = [ind.loc[n, "twr_max"] for _, n in row]
        assert twr == sorted(twr)
    nrows, ncols, where = platform_grid_layout(ind.iloc[:7])
    assert (nrows, ncols) == (3, 3)
    assert sorted(r for r, _ in where.values()) == [0, 0, 0, 1, 1, 1, 2]


def test_full_catalog_campaign_report_has_every_file_and_a_36_platform_grid(tmp_path):
    # 36 platforms x 7 families x 10 trials, one algorithm: the size of a paper campaign
    # (how long the report takes, seconds, is measured in bench/bench_search.py)
    df = to_frame(_rows(["ego"], list(catalog().values()), list(FAMILIES), 10, seed=2))
    assert len(df) == 2520 and df["platform"].nunique() == 36
    paths = write_report(df, tmp_path, campaign_spec=SPEC, meta=META)
    names = [*FIGURES, "heatmap_ego"]
    assert set(paths) == {"report.html", "summary.md"} | {f"{n}.{e}" for n in names
                                                          for e in ("png", "svg")}
    assert all(p == tmp_path / "report" / n and p.stat().st_size > 0 for n, p in paths.items())
    page = _parse(paths["report.html"])
    assert page.errors == [] and {img["alt"] for img in page.imgs} == set(names)
    assert "2520" in " ".join(page.tables["facts"])
    # the 6 x 6 grid of platforms: a tall figure
    assert matplotlib.image.imread(paths["platform_grid.png"]).shape[0] > 800


# --------------------------------------------------------------------------- issue 20
def test_family_table_shows_successes_bootstrap_and_wilson_intervals(campaign):
    df, _, paths, _ = campaign
    families = " ".join(_parse(paths["report.html"]).tables["families"])
    md = paths["summary.md"].read_text(encoding="utf-8")
    fam = scoring.success_table(df, ("algorithm", "family"))
    for r in fam.itertuples(index=False):
        lines = (f"{r.rate:.2f} ({r.successes}/{r.n})", f"boot [{r.ci_lo:.2f}, {r.ci_hi:.2f}]",
                 f"Wilson [{r.wilson_lo:.2f}, {r.wilson_hi:.2f}]")
        for text in lines:
            assert text in families
        assert "<br>".join(lines) in md


def test_run_facts_have_no_empty_header_row(campaign):
    _, _, paths, _ = campaign
    html_text = paths["report.html"].read_text(encoding="utf-8")
    start = html_text.index('<table class="facts">')
    facts = html_text[start:html_text.index("</table>", start)]
    assert "<thead>" not in facts and '<tr><th scope="row">code version</th>' in facts
    md = paths["summary.md"].read_text(encoding="utf-8")
    assert "- **code version**: 0.1.0+g1234abc" in md and "|  |  |" not in md


def test_regression_section_reads_each_algorithms_fit(campaign):
    df, _, paths, _ = campaign
    page = _parse(paths["report.html"])
    md = paths["summary.md"].read_text(encoding="utf-8")
    fits = regression.fit_success_models(df)
    coefs = regression.coefficient_table(fits)
    assert len(coefs) == 2 * 4 and set(coefs["algorithm"]) == {"ego", "straight"}
    text = " ".join(page.text)
    for r in coefs.itertuples(index=False):
        assert r.reading in text and f"  - {r.reading}" in md
        if math.isfinite(r.p):
            row = f"| {r.algorithm} | {r.indicator} | {r.per} | {r.coef:+.2f} ({r.se:.2f}) |"
            assert row in md
    fit_table = " ".join(page.tables["fits"])
    for f in fits:
        assert f"{f.n_rows} ({f.n_successes})" in fit_table
    col = regression.collinearity(df)
    collinear = " ".join(page.tables["collinearity"])
    for name in ("TWR_max", "log2 alpha_xy,max", "footprint", "mass (not in the fit)"):
        assert name in collinear
    assert f"{col.loc['TWR_max', 'VIF']:.1f}" in collinear


def test_regression_degenerate_cases_are_said_in_the_report(tmp_path):
    # one algorithm that always fails, one whose forest trials all succeed
    rows = _rows(["a", "b"], _real_platforms(6), ["forest", "maze", "perlin"], 3, seed=4)
    for r in rows:
        if r["algorithm"] == "a" or (r["algorithm"] == "b" and r["family"] == "forest"):
            ok = r["algorithm"] == "b"
            r.update(success=ok, reason="success" if ok else "timeout")
    paths = write_report(to_frame(rows), tmp_path, campaign_spec={}, meta={})
    page = _parse(paths["report.html"])
    fits = " ".join(page.tables["fits"])
    assert "no family with both successes and failures: nothing to fit" in fits
    assert "Forest (all 18 fail)" in fits and "Forest (all 18 succeed)" in fits
    assert "not fitted" in fits
    assert "not fitted (no family with both successes and failures" in " ".join(page.text)


def test_heatmap_cells_show_successes_trials_and_wilson_interval(campaign):
    df, _, paths, _ = campaign
    svg = paths["heatmap_ego.svg"].read_text(encoding="utf-8")
    cells = scoring.success_table(df)
    ego = cells[cells["algorithm"] == "ego"]
    assert len(ego) == 6 * 7
    for r in ego.itertuples(index=False):
        assert f"{r.successes}/{r.n}" in svg
        assert f"[{r.wilson_lo:.2f}, {r.wilson_hi:.2f}]" in svg


def test_success_by_family_marks_zero_rates_and_missing_families(tmp_path):
    rows = _rows(["a", "b"], _real_platforms(2), ["forest", "perlin"], 2, seed=1)
    for r in rows:   # a fails every perlin trial; b never ran forest
        if r["algorithm"] == "a" and r["family"] == "perlin":
            r.update(success=False, reason="collision")
    rows = [r for r in rows if not (r["algorithm"] == "b" and r["family"] == "forest")]
    paths = write_report(to_frame(rows), tmp_path, campaign_spec={}, meta={})
    svg = paths["success_by_family.svg"].read_text(encoding="utf-8")
    assert "rate 0" in svg and "no trials (n/a)" in svg and "n/a" in svg
    # a table without zeros or gaps has neither legend entry
    full = _rows(["a"], _real_platforms(2), ["forest"], 4, seed=0)
    for r in full:
        r.update(success=True, reason="success")
    svg = write_report(to_frame(full), tmp_path / "full", campaign_spec={},
                       meta={})["success_by_family.svg"].read_text(encoding="utf-8")
    assert "rate 0" not in svg and "n/a" not in svg


def test_nothing_in_any_figure_is_cut_off_by_its_edge(campaign):
    """The bounding box of everything a figure draws (labels, titles, tick labels, legend,
    cell values) lies inside the figure: a heatmap's long y label used to run past the
    top and bottom edges."""
    from matplotlib import rc_context
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from ft_sitl.missions import report

    df, *_ = campaign
    t = report._Tables(df, 50, 0)
    with rc_context(report._RC):
        for name, _, make in report._figures(t):
            fig = make(t)
            canvas = FigureCanvasAgg(fig)
            canvas.draw()
            drawn = fig.get_tightbbox(canvas.get_renderer())   # inches
            w, h = fig.get_size_inches()
            eps = 1.0 / report._DPI
            assert (drawn.x0 >= -eps and drawn.y0 >= -eps and drawn.x1 <= w + eps
                    and drawn.y1 <= h + eps), (name, drawn, (w, h))


def test_a_resumed_campaigns_rate_counts_only_the_recorded_runs_trials(tmp_path):
    """A run stopped before its end records nothing in runs.json: its rows are not in the
    recorded wall time, so the rate divides the recorded runs' trials, and the facts say
    how many rows came from unrecorded runs."""
    import json

    from ft_sitl.missions.campaign import report_meta
    from ft_sitl.missions.report import _run_facts

    df = to_frame(_rows(["straight"], _real_platforms(2), ["forest"], 5, seed=1))
    run = {"started_utc": "2026-01-02T03:04:05Z", "finished_utc": "2026-01-02T03:05:05Z",
           "wall_time_s": 20.0, "trials_run": 4, "workers": 2, "machine": {"n_cpus": 2}}
    (tmp_path / "runs.json").write_text(json.dumps([run]))
    meta = report_meta(tmp_path, {"code_version": "x"})
    assert meta["trials_run"] == 4 and meta["wall_time_s"] == 20.0
    facts = dict(_run_facts(df, meta))
    assert facts["trials per second"] == "0.2"
    assert facts["trials flown by the recorded runs"].startswith(f"4 (the other {len(df) - 4}")
    # runs.json from before runs recorded their trials: every row counts, as before
    del run["trials_run"]
    (tmp_path / "runs.json").write_text(json.dumps([run]))
    meta = report_meta(tmp_path, {"code_version": "x"})
    facts = dict(_run_facts(df, meta))
    assert "trials_run" not in meta and "trials flown by the recorded runs" not in facts
    assert facts["trials per second"] == f"{len(df) / 20.0:.3g}"


# --------------------------------------------------------------------------- issue 44
def test_a_mark_no_score_carries_is_not_explained(campaign):
    """Every algorithm flew the full grid: no dagger in the composite figure, its title or
    the notes (the dagger's explanation used to be printed beside no dagger)."""
    _, _, paths, _ = campaign
    assert "†" not in paths["composite_score.svg"].read_text(encoding="utf-8")
    assert "† marks" not in paths["report.html"].read_text(encoding="utf-8")
    assert "† marks" not in paths["summary.md"].read_text(encoding="utf-8")
