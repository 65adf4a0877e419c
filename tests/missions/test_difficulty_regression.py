"""Success against FlightBench's metrics and the indicators: the coefficients of a known
logistic model come back, standardised and with errors clustered by platform; the cases
that cannot be fitted say why; the committed regression is the committed data's."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import statsmodels.api as sm
from scipy.special import expit

from ft_sitl.missions.difficulty_regression import (
    PREDICTORS,
    DifficultyRegressionError,
    design,
    fit_difficulty_models,
    fit_model,
    markdown_coefficients,
    metrics_table,
)
from ft_sitl.missions.regression import footprints
from ft_sitl.physics.catalog import catalog

HERE = Path(__file__).resolve().parents[2] / "docs" / "results" / "scenario-difficulty"
FAMS = ("forest", "maze", "urban")


def synthetic(b_to: float, b_span: float, *, seed: int = 0, n_configs: int = 60,
              all_fail: str | None = None):
    """Trials of every catalog platform on ``n_configs`` configurations of three families,
    success drawn from a logistic model in the standardised TO and half span."""
    rng = np.random.default_rng(seed)
    plats = list(catalog().values())
    metrics = pd.DataFrame({
        "scenario": [f"{FAMS[i % 3]}-{i:02d}-s0" for i in range(n_configs)],
        "family": [FAMS[i % 3] for i in range(n_configs)],
        "to": rng.gamma(2.0, 1.5, n_configs), "vo": rng.random(n_configs) * 3,
        "aol": rng.random(n_configs) * 0.1})
    ind = {p.name: p.indicators() for p in plats}
    rows = [{"algorithm": "a", "platform": p.name, "family": m.family,
             "scenario": m.scenario, "twr_max": ind[p.name].twr_max,
             "alpha_xy_max": ind[p.name].alpha_xy_max_rad_s2, "protocol_version": 6,
             "to": m.to}
            for p in plats for m in metrics.itertuples()]
    trials = pd.DataFrame(rows)
    span = footprints(trials).to_numpy()
    z_to = (trials["to"] - trials["to"].mean()) / trials["to"].std()
    z_span = (span - span.mean()) / span.std(ddof=1)
    p = expit(0.3 + b_to * z_to + b_span * z_span)
    trials["success"] = rng.random(len(trials)) < p
    if all_fail:
        trials.loc[trials["family"] == all_fail, "success"] = False
    return trials.drop(columns="to"), metrics


def coef(fit, column):
    return next(c for c in fit.coefficients if c["column"] == column)


def test_known_coefficients_come_back_per_standard_deviation():
    trials, metrics = synthetic(-1.0, -0.6)
    fit = fit_model(design(trials, metrics), "a", "metrics",
                    [c for c, _ in PREDICTORS], False)
    assert fit.fitted and fit.n_platforms == 36
    to, span = coef(fit, "to"), coef(fit, "half_span_m")
    assert to["coef"] == pytest.approx(-1.0, abs=0.15)
    assert span["coef"] == pytest.approx(-0.6, abs=0.25)
    assert to["p"] < 0.001 and span["p"] < 0.01
    assert to["lo"] < to["coef"] < to["hi"]
    # a predictor with no effect: an interval round 0
    vo = coef(fit, "vo")
    assert vo["lo"] < 0.0 < vo["hi"] or abs(vo["coef"]) < 0.2
    assert to["sd"] == pytest.approx(metrics["to"].std(ddof=1), rel=0.05)


def test_clustered_errors_are_wider_when_platforms_differ_beyond_the_indicators():
    # a platform effect the indicators do not carry: clustering by platform must widen
    # the half span's interval against the plain one
    trials, metrics = synthetic(-1.0, 0.0, seed=3)
    rng = np.random.default_rng(5)
    shift = dict(zip(trials["platform"].unique(), rng.normal(0.0, 1.5, 36)))
    u = rng.random(len(trials))
    d = design(trials, metrics)
    z = (d["to"] - d["to"].mean()) / d["to"].std()
    d["success"] = (u < expit(0.3 - z + d["platform"].map(shift))).astype(int)
    fit = fit_model(d, "a", "metrics", [c for c, _ in PREDICTORS], False)
    x = d[[c for c, _ in PREDICTORS]].to_numpy()
    plain = sm.Logit(d["success"].to_numpy(), sm.add_constant(
        (x - x.mean(0)) / x.std(0, ddof=1))).fit(disp=0)
    assert coef(fit, "half_span_m")["se"] > 1.5 * plain.bse[6]


def test_a_family_where_everything_fails_is_left_out_of_the_family_model():
    trials, metrics = synthetic(-1.0, -0.5, all_fail="maze")
    d = design(trials, metrics)
    fit = fit_model(d, "a", "families", [c for c, _ in PREDICTORS], True)
    assert fit.left_out == (("maze", f"all {int((d['family'] == 'maze').sum())} fail"),)
    assert fit.families == ("forest", "urban")
    assert fit.fitted


def test_no_variation_is_said_so_not_printed_as_zeros():
    trials, metrics = synthetic(0.0, 0.0)
    trials["success"] = False
    d = design(trials, metrics)
    fit = fit_model(d, "a", "metrics", [c for c, _ in PREDICTORS], False)
    assert not fit.fitted
    assert fit.note == "not estimable: no variation (every trial fitted fails)"
    table = markdown_coefficients([fit], "metrics")
    assert "not estimable: no variation" in table and "+0.00" not in table


def test_trials_without_metrics_are_refused():
    trials, metrics = synthetic(-1.0, 0.0)
    with pytest.raises(DifficultyRegressionError, match="have no metrics"):
        design(trials, metrics.iloc[1:])


def test_a_document_without_flightbench_metrics_is_refused():
    with pytest.raises(DifficultyRegressionError, match="no FlightBench metrics"):
        metrics_table({"families": {"forest": [{"difficulty": {"scenario": "forest-01-s0"}}]}})


def test_the_models_compared_are_nested_in_fit():
    trials, metrics = synthetic(-1.0, -0.5)
    r2 = fit_difficulty_models(design(trials, metrics))["comparison"]["a"]
    assert r2["indicators + metrics"] > r2["indicators"]
    assert r2["indicators + metrics + families"] >= r2["indicators + metrics"] - 1e-9


def test_the_committed_regression_is_of_the_committed_metrics():
    measured = json.loads((HERE / "difficulty.json").read_text())
    done = json.loads((HERE / "regression.json").read_text())
    assert done["rows"] == 12_600 and done["protocols"] == [6]
    table = metrics_table(measured)
    assert len(table) == 70
    fits = {(f["algorithm"], f["model"]): f for f in done["fits"]}
    assert {a for a, _ in fits} == {"ego", "fast", "navrl", "pgo", "straight"}
    for f in fits.values():
        for c in f["coefficients"]:
            assert math.isfinite(c["coef"]) and c["lo"] <= c["coef"] <= c["hi"]
