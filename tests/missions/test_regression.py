"""Success against the kinodynamic indicators (ft_sitl.missions.regression): the logistic
regression per algorithm, its degenerate cases, Firth's fit, the footprint, collinearity.

The tables are built from the catalog's platforms with success drawn from a known model,
so the fitted odds ratios can be checked against the truth."""

import math

import numpy as np
import pandas as pd
import pytest
from scipy.special import expit

from ft_sitl.missions import regression as reg
from ft_sitl.missions.results import COLUMNS, to_frame
from ft_sitl.missions.spec import TrialSpec
from ft_sitl.physics.catalog import catalog, get_platform
from ft_sitl.scenarios.families import CATEGORY, FAMILIES

PLATFORMS = list(catalog().values())
FAMILY_SHIFT = dict(zip(FAMILIES, (1.5, -0.5, 0.5, -1.0, 0.0, -0.3, 0.8), strict=True))


def _table(logit, *, trials=2, seed=0, algorithm="ego", platforms=PLATFORMS,
           families=FAMILIES, protocol=1, with_spec=False):
    """Rows as a campaign writes them; success ~ Bernoulli(expit(logit(platform, family)))."""
    rng = np.random.default_rng(seed)
    rows = []
    for p in platforms:
        ind = p.indicators()
        spec = (TrialSpec(algorithm, p.name, "forest", protocol=protocol).to_json()
                if with_spec else None)
        for fam in families:
            for t in range(trials):
                ok = bool(rng.random() < expit(logit(p, ind, fam)))
                r = dict.fromkeys(COLUMNS)
                r.update(trial_id=f"{algorithm}/{p.name}/{fam}/{t}", algorithm=algorithm,
                         platform=p.name, platform_category=p.category, mass_kg=p.mass_kg,
                         twr_max=ind.twr_max, alpha_xy_max=float(ind.alpha_xy_max_rad_s2),
                         alpha_z_max=float(ind.alpha_z_max_rad_s2), family=fam,
                         scenario_category=CATEGORY.get(fam, "user"), trial=t, seed=t,
                         success=ok, reason="success" if ok else "collision",
                         protocol_version=protocol, spec=spec)
                rows.append(r)
    return to_frame(rows)


def _twr_model(beta):
    return lambda p, ind, fam: FAMILY_SHIFT[fam] + beta * (ind.twr_max - 3.0)


def _fit(df):
    (fit,) = reg.fit_success_models(df)
    return fit


# --------------------------------------------------------------------------- the fit
def test_success_that_rises_with_twr_gives_an_odds_ratio_above_1():
    beta = 0.8   # odds x2.2 per unit of TWR_max, nothing else matters
    fit = _fit(_table(_twr_model(beta), trials=4, seed=1))
    assert fit.method == "logit" and fit.left_out == () and len(fit.families) == 7
    assert fit.indicators == ("twr_max", "alpha_xy_max", "alpha_z_max", "footprint_m")
    c = fit.coefficient("twr_max")
    assert c["odds_ratio"] > 1.0 and c["p"] < 1e-3 and c["or_lo"] > 1.0
    assert c["or_lo"] < math.exp(beta) < c["or_hi"]
    text = reg.reading(fit, "twr_max")
    assert text.startswith("success rises with TWR_max: odds x")
    assert "per unit, 95 % CI [" in text and "p < 0.001" in text
    # the others have no effect by construction: their intervals cover 1
    for col in ("alpha_xy_max", "alpha_z_max", "footprint_m"):
        c = fit.coefficient(col)
        assert c["or_lo"] < 1.0 < c["or_hi"], col


def test_success_that_falls_with_the_footprint_is_read_as_falling():
    fit = _fit(_table(lambda p, ind, fam: 0.5 - 12.0 * (p.collision_radius_m - 0.27),
                      trials=4, seed=2))
    c = fit.coefficient("footprint_m")
    assert c["or_hi"] < 1.0 and c["p"] < 0.01
    # the step is 0.1 m: odds x exp(-1.2) = 0.30 per 0.1 m
    assert c["or_lo"] < math.exp(-1.2) < c["or_hi"]
    assert reg.reading(fit, "footprint_m").startswith("success falls with footprint: odds x")


@pytest.mark.slow
def test_without_any_dependence_the_interval_covers_1_about_95_percent_of_the_time():
    # the Wald intervals are calibrated: 60 tables with success independent of everything
    covered = {c: 0 for c in ("twr_max", "alpha_xy_max", "alpha_z_max", "footprint_m")}
    n = 60
    for seed in range(n):
        fit = _fit(_table(lambda p, ind, fam: FAMILY_SHIFT[fam], trials=1, seed=100 + seed))
        assert fit.method == "logit", fit.note
        for col in covered:
            c = fit.coefficient(col)
            covered[col] += c["or_lo"] < 1.0 < c["or_hi"]
    for col, k in covered.items():
        assert 0.85 * n <= k <= n, (col, k)      # 95 % expected; 0.85: 3.6 sd below
    assert sum(covered.values()) < 4 * n          # and not always (intervals not too wide)


def test_no_detectable_effect_is_said_so_with_the_numbers():
    fit = _fit(_table(lambda p, ind, fam: FAMILY_SHIFT[fam], trials=1, seed=7))
    for col, label in (("twr_max", "TWR_max"), ("footprint_m", "footprint")):
        c = fit.coefficient(col)
        if c["p"] >= reg.ALPHA:
            text = reg.reading(fit, col)
            assert text.startswith(f"no detectable effect of {label} (odds x")
            assert f"p = {reg.p_text(c['p'])}" in text


def test_the_coefficient_table_has_one_row_per_algorithm_and_indicator():
    df = pd.concat([_table(_twr_model(0.8), trials=2, seed=3, algorithm="a"),
                    _table(_twr_model(0.0), trials=2, seed=4, algorithm="b")],
                   ignore_index=True)
    fits = reg.fit_success_models(df)
    assert [f.algorithm for f in fits] == ["a", "b"]
    table = reg.coefficient_table(fits)
    assert len(table) == 8
    assert list(table["indicator"][:4]) == ["TWR_max", "alpha_xy,max", "alpha_z,max",
                                            "footprint"]
    a_twr = table[(table["algorithm"] == "a") & (table["indicator"] == "TWR_max")].iloc[0]
    assert a_twr["odds_ratio"] == pytest.approx(math.exp(a_twr["coef"]))
    assert a_twr["or_lo"] == pytest.approx(math.exp(a_twr["coef"] - 1.959964 * a_twr["se"]))


# --------------------------------------------------------------------------- degenerate
def test_families_where_all_succeed_or_all_fail_are_left_out_and_named():
    def model(p, ind, fam):
        if fam == "forest":
            return 50.0      # always succeeds
        if fam == "maze":
            return -50.0     # always fails
        return FAMILY_SHIFT[fam] + 0.8 * (ind.twr_max - 3.0)

    fit = _fit(_table(model, trials=2, seed=5))
    assert fit.left_out == (("forest", "all 72 succeed"), ("maze", "all 72 fail"))
    assert "forest" not in fit.families and "maze" not in fit.families
    assert fit.n_rows == 5 * 72 and fit.method == "logit"
    assert fit.coefficient("twr_max")["or_lo"] > 1.0


def test_an_algorithm_that_always_fails_is_not_fitted_and_says_why():
    fit = _fit(_table(lambda p, ind, fam: -50.0, trials=1, seed=0, algorithm="straight"))
    assert not fit.fitted and fit.n_rows == 0 and len(fit.left_out) == 7
    assert "no family with both successes and failures" in fit.note
    assert fit.coefficient("twr_max") is None
    assert reg.reading(fit, "twr_max").startswith("not fitted (")
    table = reg.coefficient_table([fit])
    assert table["p"].isna().all() and (table["method"] == "").all()


def test_outcomes_the_same_on_every_platform_are_not_estimable_not_zero_slopes():
    # the straight baseline on the quick preset: in each configuration every vehicle meets
    # the same fate, so each platform's rate equals its family's (here 1/2 in forest and
    # urban, 0 elsewhere); maximum likelihood would print slopes of exactly 0 with p = 1
    df = _table(lambda p, ind, fam: 0.0, trials=2, seed=0, algorithm="straight")
    df["success"] = (df["family"].isin(["forest", "urban"]) & (df["trial"] == 0)).to_numpy()
    fit = _fit(df)
    assert not fit.fitted and fit.families == ("forest", "urban")
    assert fit.note.startswith("not estimable: no variation between platforms")
    assert fit.coefficient("twr_max") is None
    assert reg.reading(fit, "twr_max") == fit.note   # said once, not "not fitted (not ...)"
    assert reg.coefficient_table([fit])["p"].isna().all()
    # one platform that differs once is variation: fitted
    first = df.index[(df["family"] == "forest") & (df["trial"] == 1)][0]
    df.loc[first, "success"] = True
    assert _fit(df).fitted


def test_separation_switches_to_firths_fit_with_finite_estimates():
    # success exactly when TWR_max > 3: maximum likelihood would run off to infinity
    fit = _fit(_table(lambda p, ind, fam: 60.0 if ind.twr_max > 3.0 else -60.0, trials=1,
                      seed=0))
    assert fit.method == "firth" and "separation" in fit.note
    c = fit.coefficient("twr_max")
    assert np.isfinite(fit.params).all() and np.isfinite(fit.cov).all()
    assert c["odds_ratio"] > 1.0 and math.isfinite(c["or_hi"])
    assert "TWR_max" in reg.reading(fit, "twr_max")


def test_too_few_trials_are_not_fitted():
    df = _table(_twr_model(0.5), trials=1, seed=3, platforms=PLATFORMS[:6],
                families=("forest", "perlin"))
    df["success"] = [True, True, False, False] * 3   # rows: platform by platform, forest & perlin
    fit = _fit(df)
    # 12 trials, 6 successes and 6 failures for 5 coefficients (4 indicators, 1 family)
    assert not fit.fitted and fit.n_rows == 12 and fit.indicators != ()
    assert fit.note == "not fitted: 6 successes for 5 coefficients (needs 2 per coefficient)"
    df["success"] = [True, True] + [False] * 10
    assert _fit(df).note == ("not fitted: 2 successes for 5 coefficients (needs 2 per "
                             "coefficient)")


def test_collinear_and_constant_indicators_are_left_out():
    # one platform: every indicator is constant; nothing varies
    fit = _fit(_table(lambda p, ind, fam: FAMILY_SHIFT[fam], trials=6, seed=0,
                      platforms=PLATFORMS[:1]))
    assert not fit.fitted and fit.indicators == ()
    assert fit.note == "no indicator varies over the trials fitted"
    assert {label for label, _ in fit.dropped_indicators} == {
        "TWR_max", "alpha_xy,max", "alpha_z,max", "footprint"}
    # three platforms: at most two indicators can vary independently of the intercept
    fit = _fit(_table(lambda p, ind, fam: FAMILY_SHIFT[fam], trials=10, seed=0,
                      platforms=PLATFORMS[:3]))
    assert fit.fitted and fit.indicators == ("twr_max", "alpha_xy_max")
    dropped = dict(fit.dropped_indicators)
    assert dropped["alpha_z,max"] == "a linear combination of the others over the 3 " \
                                     "platform(s) fitted"
    assert reg.reading(fit, "footprint_m").startswith("footprint not in the fit: a linear")


def test_rows_without_a_footprint_are_left_out_and_counted():
    df = _table(_twr_model(0.8), trials=2, seed=6)
    df["platform"] = df["platform"].astype(str)
    df.loc[df["platform"] == PLATFORMS[0].name, "platform"] = "my-own-quad"  # not a catalog
    fit = _fit(df)
    assert fit.note.startswith("14 trial(s) without all four indicators left out")
    assert fit.n_rows == len(df) - 14


# --------------------------------------------------------------------------- Firth
def test_firth_on_a_two_by_two_table_is_the_log_odds_ratio_with_half_counts():
    # a known closed form: for one binary covariate, Firth's slope is log of the odds
    # ratio with 1/2 added to every cell (Haldane's correction); also with a zero cell
    for (a, b), (c, d) in (((10, 0), (3, 7)), ((6, 4), (3, 7)), ((5, 0), (0, 5))):
        x = np.array([1.0] * (a + b) + [0.0] * (c + d))
        y = np.array([1.0] * a + [0.0] * b + [1.0] * c + [0.0] * d)
        X = np.column_stack([np.ones_like(x), x])
        est, cov = reg.firth_logit(X, y)
        want = math.log(((a + 0.5) / (b + 0.5)) / ((c + 0.5) / (d + 0.5)))
        assert est[1] == pytest.approx(want, abs=1e-7)
        assert est[0] == pytest.approx(math.log((c + 0.5) / (d + 0.5)), abs=1e-7)
        assert cov[1, 1] > 0


def test_firth_maximises_the_penalised_likelihood():
    rng = np.random.default_rng(0)
    X = np.column_stack([np.ones(40), rng.normal(size=40), rng.normal(size=40)])
    y = (X[:, 1] + 0.3 * rng.normal(size=40) > 0).astype(float)

    def penalised(b):
        eta = X @ b
        p = expit(eta)
        info = X.T @ ((p * (1 - p))[:, None] * X)
        return np.sum(y * eta - np.logaddexp(0, eta)) + 0.5 * np.linalg.slogdet(info)[1]

    est, _ = reg.firth_logit(X, y)
    for j in range(3):
        e = np.zeros(3)
        e[j] = 1e-5
        assert (penalised(est + e) - penalised(est - e)) / 2e-5 == pytest.approx(0, abs=1e-5)
        assert penalised(est + 100 * e) < penalised(est)


def test_separation_is_found_complete_and_quasi_complete_and_not_otherwise():
    x = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0])
    X = np.column_stack([np.ones(6), x])
    assert reg.separated(X, np.array([0, 0, 0, 1, 1, 1]))          # complete
    assert reg.separated(X, np.array([0, 0, 1, 0, 1, 1]).astype(float)) is False
    Xq = np.column_stack([np.ones(6), [0, 0, 1, 1, 2, 2]])
    assert reg.separated(Xq, np.array([0, 0, 0, 1, 1, 1]))         # quasi: a tie at 1


# --------------------------------------------------------------------------- footprint
def test_footprint_is_the_half_span_from_protocol_5_and_the_collision_radius_before():
    plats = PLATFORMS[:3]
    old = _table(lambda *a: 0.0, trials=1, platforms=plats, families=("forest",), protocol=1)
    new = _table(lambda *a: 0.0, trials=1, platforms=plats, families=("forest",), protocol=5,
                 with_spec=True)
    assert new["spec"].notna().all() and old["spec"].isna().all()
    for df, want in ((old, lambda p: p.collision_radius_m),
                     (new, lambda p: p.body().half_span_m)):
        got = reg.footprints(df)
        assert got.tolist() == [want(get_platform(n)) for n in df["platform"].astype(str)]
    # a protocol-5 row without a spec: the catalog platform under the row's version
    bare = new.assign(spec=None)
    assert reg.footprints(bare).tolist() == reg.footprints(new).tolist()
    unknown = old.assign(platform="no-such-platform")
    assert reg.footprints(unknown).isna().all()


# --------------------------------------------------------------------------- collinearity
def test_collinearity_reports_correlations_and_variance_inflation_over_platforms():
    df = _table(lambda *a: 0.0, trials=3, families=("forest", "maze"))
    col = reg.collinearity(df)
    assert list(col.index) == ["TWR_max", "alpha_xy,max", "alpha_z,max", "footprint", "mass"]
    assert list(col.columns) == ["TWR_max", "alpha_xy,max", "alpha_z,max", "footprint", "VIF"]
    # one point per platform: the same as computed from the catalog directly
    pts = pd.DataFrame({"TWR_max": [p.indicators().twr_max for p in PLATFORMS],
                        "alpha_xy,max": [math.log2(p.indicators().alpha_xy_max_rad_s2)
                                         for p in PLATFORMS],
                        "alpha_z,max": [p.indicators().alpha_z_max_rad_s2 for p in PLATFORMS],
                        "footprint": [p.collision_radius_m for p in PLATFORMS]})
    for c in pts.columns:
        others = pts.drop(columns=c)
        A = np.column_stack([np.ones(len(pts)), others.to_numpy()])
        resid = pts[c] - A @ np.linalg.lstsq(A, pts[c], rcond=None)[0]
        r2 = 1 - resid.var() / pts[c].var()
        assert col.loc[c, "VIF"] == pytest.approx(1 / (1 - r2), rel=1e-9)
        assert col.loc[c, c] == pytest.approx(1.0)
    mass = [p.mass_kg for p in PLATFORMS]
    assert col.loc["mass", "footprint"] == pytest.approx(np.corrcoef(mass, pts["footprint"])[0, 1])
    assert np.isnan(col.loc["mass", "VIF"])
    # with 2 platforms nothing can be said
    assert reg.collinearity(df[df["platform"].isin([p.name for p in PLATFORMS[:2]])]) \
        .isna().all().all()


# --------------------------------------------------------------------------- dependence
def test_partial_dependence_follows_the_true_curve_and_brackets_it():
    beta = 0.8
    df = _table(_twr_model(beta), trials=4, seed=1)
    fit = _fit(df)
    grid = np.linspace(*fit.ranges["twr_max"], 9)
    mean, lo, hi = fit.partial_dependence("twr_max", grid, seed=0)
    assert np.all(np.diff(mean) > 0) and np.all(lo <= mean) and np.all(mean <= hi)
    # the truth at the other indicators' means (no effect) averaged over the families
    truth = np.mean([expit(FAMILY_SHIFT[f] + beta * (grid - 3.0)) for f in FAMILIES], axis=0)
    assert np.all(np.abs(mean - truth) < 0.08)
    assert np.mean((lo <= truth) & (truth <= hi)) >= 0.8
    again = fit.partial_dependence("twr_max", grid, seed=0)
    assert all(np.array_equal(a, b) for a, b in zip(again, (mean, lo, hi)))
    with pytest.raises(ValueError, match="not in the fit"):
        _fit(_table(lambda *a: -50.0, trials=1)).partial_dependence("twr_max", grid)
