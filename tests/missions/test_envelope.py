"""The capability-envelope analysis (missions/envelope.py) on rows whose answer is known."""

import math

import numpy as np
import pandas as pd
import pytest

from ft_sitl.missions import envelope
from ft_sitl.physics.catalog import catalog, series

LEVELS = ("gentle", "paper", "brisk", "aggressive")


def _rows(platforms, success_of, *, families=("forest", "sudden_drop"), trials=10,
          levels=LEVELS, seed=0):
    """Rows of every platform x family x level x trial, success drawn from
    ``success_of(platform, family, level)`` (a probability; 0/1 for fixed outcomes)."""
    rng = np.random.default_rng(seed)
    rows = []
    for p in platforms:
        ind = p.indicators()
        for fam in families:
            for lv in levels:
                prob = success_of(p, fam, lv)
                for t in range(trials):
                    rows.append({
                        "algorithm": "ego", "platform": p.name,
                        "platform_category": "series" if p.name.startswith("series-")
                        else "real", "family": fam, "aggressiveness": lv,
                        "twr_max": ind.twr_max, "alpha_xy_max": ind.alpha_xy_max_rad_s2,
                        "success": bool(rng.random() < prob), "trial": t,
                        "protocol_version": 9, "spec": None,
                        "max_tilt_deg": 30.0, "saturation_fraction": 0.1,
                        "time_to_goal_s": 20.0,
                    })
    return pd.DataFrame(rows)


def _twr_series(base_slug="0.55kg-UAV1"):
    return [p for name, p in series().items() if name.startswith(f"series-{base_slug}-twr")]


def test_the_threshold_is_the_first_value_from_which_all_stay_near_the_best():
    values = np.array([1.2, 1.5, 2.0, 3.0, 4.0])
    assert envelope.threshold(values, np.array([0.0, 0.5, 0.95, 1.0, 0.92])) == 2.0
    # a dip above the first good value moves the threshold above the dip
    assert envelope.threshold(values, np.array([0.95, 0.5, 1.0, 0.7, 1.0])) == 4.0
    assert envelope.threshold(values, np.array([1.0, 1.0, 1.0, 1.0, 1.0])) == 1.2
    assert math.isnan(envelope.threshold(np.array([]), np.array([])))
    # the strongest member short of the best: no value has only good members above it
    assert math.isnan(envelope.threshold(values, np.array([1.0, 1.0, 1.0, 1.0, 0.5])))


def test_the_envelope_of_a_series_that_fails_below_twr_2_is_found_with_its_interval():
    members = _twr_series()
    assert len(members) >= 5
    rows = _rows(members, lambda p, f, lv: 1.0 if p.indicators().twr_max >= 2.0 - 1e-9
                 or lv == "gentle" else 0.0)
    env = envelope.envelope_thresholds(rows, n_boot=200)
    got = env.set_index(["family", "level"])
    for fam in ("forest", "sudden_drop"):
        assert got.loc[(fam, "gentle"), "threshold"] == pytest.approx(1.2)
        for lv in ("paper", "brisk", "aggressive"):
            row = got.loc[(fam, lv)]
            assert row["threshold"] == pytest.approx(2.0)
            # fixed outcomes: every resample gives the same threshold
            assert row["lo"] == pytest.approx(2.0) and row["hi"] == pytest.approx(2.0)
    assert list(env["level"].unique()) == list(LEVELS)


def test_dose_response_counts_and_wilson_intervals():
    members = _twr_series()
    rows = _rows(members, lambda p, f, lv: 0.5, trials=20)
    dose = envelope.dose_response(rows)
    assert len(dose) == len(members) * 2 * len(LEVELS)
    assert (dose["n"] == 20).all()
    assert ((dose["lo"] <= dose["rate"]) & (dose["rate"] <= dose["hi"])).all()
    assert set(dose["kind"]) == {"twr"}
    np.testing.assert_allclose(sorted(dose["value"].unique()),
                               sorted(p.indicators().twr_max for p in members), rtol=1e-9)


def test_size_controlled_fit_finds_the_indicator_that_decides_and_not_size():
    # catalog platforms whose success depends on TWR only: the fit gives TWR a positive,
    # significant coefficient and the half span none
    plats = list(catalog().values())

    def chance(p, fam, lv):
        return 1.0 / (1.0 + math.exp(-3.0 * (p.indicators().twr_max - 2.2)))

    rows = _rows(plats, chance, trials=30, levels=("paper",), seed=3)
    fits = envelope.size_controlled_fits(rows)
    cat = fits[fits["sample"] == "catalog"].set_index("term")
    assert cat.loc["log TWR_max", "coef_per_sd"] > 0.5
    assert cat.loc["log TWR_max", "p"] < 0.01
    assert cat.loc["half span", "p"] > 0.01 or abs(cat.loc["half span", "coef_per_sd"]) < \
        abs(cat.loc["log TWR_max", "coef_per_sd"]) / 3
    assert (fits["note"].str.contains("platforms")).all()


def test_a_fit_without_variation_says_so_instead_of_zero_slopes():
    plats = list(catalog().values())[:8]
    rows = _rows(plats, lambda p, f, lv: 1.0, levels=("paper",))
    fits = envelope.size_controlled_fits(rows)
    assert fits["coef_per_sd"].isna().all()
    assert fits["note"].str.startswith("not estimable").all()


def test_level_tolerance_is_the_highest_level_keeping_80_percent_of_the_gentle_success():
    plats = list(catalog().values())[:2]
    rates = {"gentle": 1.0, "paper": 0.9, "brisk": 0.7, "aggressive": 0.9}
    rows = _rows(plats, lambda p, f, lv: rates[lv], trials=10)
    # make the outcomes exact: the first round(rate x n) trials succeed
    rows["success"] = [t < round(rates[lv] * 10) for t, lv in
                       zip(rows["trial"], rows["aggressiveness"], strict=True)]
    tol = envelope.level_tolerance(rows)
    assert set(tol["highest_kept"]) == {"paper"}  # brisk falls below 0.8 and stops it
    assert tol["gentlest"].eq("gentle").all()


def test_rows_without_the_axis_at_the_paper_limits_count_as_the_paper_level():
    plats = list(catalog().values())[:1]
    rows = _rows(plats, lambda p, f, lv: 1.0, levels=("paper",))
    rows["aggressiveness"] = ""
    rows["speed_limit_m_s"], rows["acc_limit_m_s2"] = 4.0, 3.0
    other = rows.copy()
    other["speed_limit_m_s"] = 5.0
    got = envelope.with_levels(pd.concat([rows, other], ignore_index=True))
    assert len(got) == len(rows)
    assert set(got["aggressiveness"]) == {"paper"}


def test_row_metrics_hover_tilt_and_time_ratio():
    df = pd.DataFrame({"twr_max": [2.0, 1.0], "max_tilt_deg": [30.0, 10.0],
                       "saturation_fraction": [0.0, 0.5], "time_to_goal_s": [20.0, np.nan]})
    m = envelope.row_metrics(df, bounds=pd.Series([10.0, 10.0]))
    assert m["hover_tilt_deg"].iloc[0] == pytest.approx(60.0)
    assert m["tilt_ratio"].iloc[0] == pytest.approx(0.5)
    assert m["hover_tilt_deg"].iloc[1] == pytest.approx(0.0)
    assert m["time_ratio"].iloc[0] == pytest.approx(2.0)
    assert math.isnan(m["time_ratio"].iloc[1])


def test_the_time_bound_takes_the_lesser_of_the_level_and_the_platform_acceleration():
    seen = []

    def path_time(speed, acc):
        seen.append((speed, acc))
        return 10.0

    assert envelope.time_bound_s(path_time, 8.0, 10.0, 1.2) == 10.0
    assert seen[-1][1] == pytest.approx(9.80665 * math.sqrt(1.2**2 - 1))
    envelope.time_bound_s(path_time, 4.0, 3.0, 3.0)
    assert seen[-1] == (4.0, 3.0)
    assert envelope.time_bound_s(path_time, 4.0, 3.0, 1.0) == math.inf


def _texts_at_least(fig, pt):
    # every text the figure draws, ticks and legend included, at or above ``pt``
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.text import Text

    FigureCanvasAgg(fig).draw()
    sizes = [t.get_fontsize() for t in fig.findobj(Text) if t.get_text().strip()]
    assert sizes, "the figure has no text"
    return min(sizes) >= pt


def test_the_envelope_figures_draw_every_panel_with_readable_text():
    from ft_sitl.missions import envelope_plots as ep

    members = [p for name, p in series().items()
               if name.startswith(("series-0.55kg-UAV1-", "series-5.00kg-UAV16-"))]
    rows = _rows(members, lambda p, f, lv: min(1.0, p.indicators().twr_max / 3.0),
                 trials=6)
    dose = envelope.dose_response(rows)
    env = envelope.envelope_thresholds(rows, n_boot=20)
    cat = _rows(list(catalog().values())[:5], lambda p, f, lv: 0.8, trials=4)
    tol = envelope.level_tolerance(cat)
    for fig, panels in ((ep.fig_dose_response(dose, "twr"), 2),
                        (ep.fig_dose_response(dose, "axy"), 2),
                        (ep.fig_envelope(env), 2),
                        (ep.fig_level_tolerance(tol), 1)):
        assert len([a for a in fig.axes if a.get_title()]) == panels
        assert _texts_at_least(fig, ep.MIN_FONT_PT)
        assert fig.legends or fig.axes[-1].get_ylabel()  # a key to read the lines by
    fig = ep.fig_envelope(env)
    titles = {a.get_title() for a in fig.axes}
    assert titles == {"ego"}
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "forest" in labels and "body 0.55kg-UAV1" in labels


def test_time_bounds_re_time_the_body_path_under_each_rows_level(tmp_path):
    import json

    from ft_sitl.missions.spec import TrialSpec

    def row(platform, speed, acc, twr):
        spec = TrialSpec("ego", platform, "forest", scenario_index=1)
        return {"spec": json.dumps(spec.to_dict()), "speed_limit_m_s": speed,
                "acc_limit_m_s2": acc, "twr_max": twr}

    df = pd.DataFrame([row("0.55kg-UAV 1", 2.0, 2.0, 3.6), row("0.55kg-UAV 1", 8.0, 10.0, 3.6),
                       row("series-0.55kg-UAV1-twr1.2", 8.0, 10.0, 1.2),
                       {"spec": "not json", "speed_limit_m_s": 4.0, "acc_limit_m_s2": 3.0,
                        "twr_max": 2.0}])
    b = envelope.time_bounds(df, cache_dir=tmp_path)
    assert math.isnan(b.iloc[3])
    gentle, fast, weak = b.iloc[0], b.iloc[1], b.iloc[2]
    # forest 1 is ~40 m: at 2 m/s it takes over 20 s, at 8 m/s a fraction of that; the
    # weak member of the same body cannot accelerate at 10 m/s^2, so it takes longer
    assert gentle > 20.0 and fast < gentle / 2.5 and fast < weak < gentle
    assert list(tmp_path.glob("*.json")), "the path is cached"


def test_the_report_section_is_there_for_levels_or_series_and_lists_its_tables():
    from ft_sitl.missions import envelope_report as er

    members = _twr_series()
    rows = _rows(members, lambda p, f, lv: min(1.0, p.indicators().twr_max / 3.0), trials=6)
    rows["tracking_rms_m"] = 0.2
    cat = _rows(list(catalog().values())[:6], lambda p, f, lv: 0.7, trials=6, seed=1)
    cat["tracking_rms_m"] = 0.1
    both = pd.concat([rows, cat], ignore_index=True)
    assert er.has_envelope(both)
    one_level = cat[cat["aggressiveness"] == "paper"]
    assert not er.has_envelope(one_level)
    t = er.envelope_tables(both, n_boot=20)
    names = [name for name, _, _ in er.envelope_figures(t)]
    assert names == ["envelope", "envelope_dose_twr", "envelope_tolerance"]
    md = er.markdown(t)
    for title in ("Q2 with size held fixed", "Envelope thresholds",
                  "What each catalog platform tolerates", "Per-row metrics"):
        assert f"### {title}" in md
    # the metrics table: per algorithm, level and sample, the medians given
    assert set(t.rows["sample"]) == {"series", "catalog"}
    got = t.rows.set_index(["level", "sample"])["tracking_rms_m"]
    assert got[("paper", "series")] == pytest.approx(0.2)
    assert got[("paper", "catalog")] == pytest.approx(0.1)


def test_a_campaign_of_series_platforms_gets_a_composite_score():
    # the series weigh like the virtual set; before, the score refused their category
    from ft_sitl.missions import scoring

    rows = _rows(_twr_series()[:3], lambda p, f, lv: 0.5, trials=4, levels=("paper",))
    rows["scenario_category"] = "classic"
    score = scoring.composite_score(rows)
    assert len(score) == 1 and np.isfinite(score["FinalScore"]).all()


def test_over_the_series_the_body_holds_the_size_and_twr_is_fitted():
    # two bodies, TWR deciding within each: the series fit has TWR (and alpha) terms, the
    # body as a fixed effect, and no half span (it would be collinear with the body)
    members = [p for name, p in series().items()
               if name.startswith(("series-0.55kg-UAV1-", "series-5.00kg-UAV16-"))]

    def chance(p, fam, lv):
        return 1.0 / (1.0 + math.exp(-2.0 * (p.indicators().twr_max - 2.5)))

    rows = _rows(members, chance, trials=40, levels=("brisk",), seed=5)
    fits = envelope.size_controlled_fits(rows)
    got = fits[fits["sample"] == "series"].set_index("term")
    assert got.loc["log TWR_max", "coef_per_sd"] > 0.5 and got.loc["log TWR_max", "p"] < 0.01
    assert math.isnan(got.loc["half span", "coef_per_sd"])
    assert got["note"].str.contains("platforms").all()


def test_one_algorithm_s_rows_are_taken_from_one_protocol_version():
    df = pd.DataFrame({"algorithm": ["ego", "ego", "fast", "fast", "ego"],
                       "protocol_version": [9, 11, 9, 9, 11], "x": range(5)})
    out = envelope.of_protocols(df, {"ego": 11})
    assert list(out["x"]) == [1, 2, 3, 4]  # EGO's 11 rows, Fast's as they are
    assert list(envelope.of_protocols(df, {})["x"]) == [0, 1, 2, 3, 4]
    with pytest.raises(ValueError, match=r"no fast rows of protocol 11 \(its rows: "
                                         r"protocols \[9\]\)"):
        envelope.of_protocols(df, {"fast": 11})
