"""Trial success against FlightBench's scenario difficulty and the platform's
indicators (issue 44, point 5).

Per algorithm, a logistic regression of each trial's success on

* the configuration's traversability obstruction ``to``, view occlusion ``vo`` and angle
  over length ``aol`` (:mod:`ft_sitl.scenarios.flightbench_metrics`, as committed in
  ``docs/results/scenario-difficulty/difficulty.json``);
* the platform's ``log TWR_max``, ``log alpha_xy,max`` (natural logarithms: alpha_xy,max
  spans 56-1,467 rad/s^2 over the catalog, a factor of 26) and its half span
  (:func:`ft_sitl.missions.regression.footprints`: the body's half span from protocol 5,
  the collision radius before);

every predictor standardised over the rows fitted (z-scores), so each coefficient is the
change of the log-odds of success per standard deviation of its predictor::

    logit P(success) = b0 + sum_j b_j (x_j - mean x_j) / sd x_j   [+ c_family]

Errors are clustered by platform (statsmodels' ``Logit`` with ``cov_type="cluster"``,
its default small-sample correction): the 70 trials of one platform share whatever the
platform does to them beyond the three indicators, so they are not 70 independent
observations. The metrics, though, take only one value per configuration, and the 36
trials of one configuration share whatever it does to them beyond its three metrics: the
metrics' errors clustered by platform alone are far too small. Each coefficient therefore
also carries errors clustered both ways, by platform and by configuration (``se2``,
``p2``, ``lo2``, ``hi2``: Cameron, Gelbach and Miller 2011, statsmodels' two-column
``groups``), which are the ones to read for the metrics.

:func:`fit_difficulty_models` fits per algorithm

* ``metrics``: the six predictors above (the scenario is described only by the three
  metrics);
* ``families``: the same with the scenario family as a factor (treatment coding,
  Forest the reference): the metrics then explain only what differs between the
  configurations of one family;

and, to say how much the metrics explain, the McFadden pseudo-R^2 of four nested
models: the indicators alone, with the metrics, with the families, with both
(:data:`COMPARISON`). A model that cannot be fitted says why instead of printing
numbers: no variation in success ("not estimable: no variation"), a family whose trials
all succeed or all fail (left out of the family models, named), predictors that separate
the successes from the failures (:func:`ft_sitl.missions.regression.separated`: the
maximum-likelihood estimate does not exist), or a fit that does not converge.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import statsmodels.api as sm

from ft_sitl import markdown as md
from ft_sitl.missions.regression import footprints, p_text, separated
from ft_sitl.scenarios.families import FAMILIES

#: the scenario's predictors: column, label
METRICS = (("to", "TO"), ("vo", "VO"), ("aol", "AOL"))
#: the platform's predictors: column, label
INDICATORS = (("log_twr", "log TWR_max"), ("log_alpha_xy", "log alpha_xy,max"),
              ("half_span_m", "half span"))
PREDICTORS = METRICS + INDICATORS
#: the nested models compared: name -> (predictor columns, with family effects)
COMPARISON = {
    "indicators": ([c for c, _ in INDICATORS], False),
    "indicators + metrics": ([c for c, _ in PREDICTORS], False),
    "indicators + families": ([c for c, _ in INDICATORS], True),
    "indicators + metrics + families": ([c for c, _ in PREDICTORS], True),
}


class DifficultyRegressionError(ValueError):
    """The inputs of the regression do not fit together; the message says how."""


# --------------------------------------------------------------------------------------
# the data
# --------------------------------------------------------------------------------------


def metrics_table(measured: Mapping) -> pd.DataFrame:
    """One row per configuration of a ``difficulty.json`` document (scripts/
    scenario_difficulty.py): ``scenario``, ``family``, ``to``, ``vo``, ``aol``."""
    rows = []
    for family, entries in measured["families"].items():
        for e in entries:
            if "flightbench" not in e:
                raise DifficultyRegressionError(
                    f"{e['difficulty']['scenario']}: no FlightBench metrics in the "
                    "difficulty document (rerun scripts/scenario_difficulty.py)")
            m = e["flightbench"]
            rows.append({"scenario": m["scenario"], "family": family, "to": m["to"],
                         "vo": m["vo"], "aol": m["aol"]})
    return pd.DataFrame(rows)


def design(trials: pd.DataFrame, metrics: pd.DataFrame) -> pd.DataFrame:
    """The trials with their configuration's metrics and their platform's predictors:
    ``algorithm``, ``platform``, ``family``, ``scenario``, ``success`` (0/1) and the
    :data:`PREDICTORS`' columns. Every trial's configuration must have metrics."""
    missing = sorted(set(trials["scenario"].astype(str)) - set(metrics["scenario"]))
    if missing:
        raise DifficultyRegressionError(
            f"{len(missing)} configuration(s) of the trials have no metrics: "
            f"{', '.join(missing[:5])}{' ...' if len(missing) > 5 else ''}")
    t = trials.copy()
    df = pd.DataFrame({
        "algorithm": t["algorithm"].astype(str).to_numpy(),
        "platform": t["platform"].astype(str).to_numpy(),
        "family": t["family"].astype(str).to_numpy(),
        "scenario": t["scenario"].astype(str).to_numpy(),
        "success": t["success"].astype(bool).astype(int).to_numpy(),
        "log_twr": np.log(pd.to_numeric(t["twr_max"]).astype(float).to_numpy()),
        "log_alpha_xy": np.log(pd.to_numeric(t["alpha_xy_max"]).astype(float).to_numpy()),
        "half_span_m": footprints(t).to_numpy(),
    })
    df = df.merge(metrics[["scenario", "to", "vo", "aol"]], on="scenario", how="left",
                  validate="many_to_one")
    bad = ~np.isfinite(df[[c for c, _ in PREDICTORS]].to_numpy()).all(axis=1)
    if bad.any():
        raise DifficultyRegressionError(f"{int(bad.sum())} trial(s) with a missing or "
                                        "non-finite predictor")
    return df


# --------------------------------------------------------------------------------------
# fitting
# --------------------------------------------------------------------------------------


@dataclass
class DifficultyFit:
    """One model of one algorithm (module docstring)."""

    algorithm: str
    model: str
    n_rows: int = 0
    n_successes: int = 0
    n_platforms: int = 0
    #: families in the fit (with family effects; the first is the reference) and those
    #: left out, with why
    families: tuple[str, ...] = ()
    left_out: tuple[tuple[str, str], ...] = ()
    #: one dict per predictor: column, label, coef, se, z, p, lo, hi (log-odds per SD,
    #: errors clustered by platform), se2, p2, lo2, hi2 (clustered by platform and by
    #: configuration), sd (the predictor's standard deviation, raw units)
    coefficients: list[dict] = field(default_factory=list)
    pseudo_r2: float = math.nan
    #: why there are no coefficients ("" when fitted)
    note: str = ""

    @property
    def fitted(self) -> bool:
        return bool(self.coefficients)

    def as_dict(self) -> dict:
        return {"algorithm": self.algorithm, "model": self.model, "n_rows": self.n_rows,
                "n_successes": self.n_successes, "n_platforms": self.n_platforms,
                "families": list(self.families),
                "left_out": [list(x) for x in self.left_out],
                "coefficients": [{k: (None if isinstance(v, float) and not math.isfinite(v)
                                      else v) for k, v in c.items()}
                                 for c in self.coefficients],
                "pseudo_r2": None if not math.isfinite(self.pseudo_r2) else self.pseudo_r2,
                "note": self.note}


def _families_in(df: pd.DataFrame) -> list[str]:
    present = set(df["family"])
    return [f for f in FAMILIES if f in present] + sorted(present - set(FAMILIES))


def fit_model(df: pd.DataFrame, algorithm: str, model: str, columns, with_families: bool
              ) -> DifficultyFit:
    """Fit one model to one algorithm's rows ``df`` (:func:`design`'s columns):
    ``columns`` standardised, family effects when ``with_families``, errors clustered by
    platform."""
    fit = DifficultyFit(algorithm=algorithm, model=model)
    labels = dict(PREDICTORS)
    if with_families:
        left = []
        keep = np.ones(len(df), dtype=bool)
        for fam in _families_in(df):
            m = (df["family"] == fam).to_numpy()
            k, n = int(df["success"][m].sum()), int(m.sum())
            if k in (0, n):
                left.append((fam, f"all {n} {'succeed' if k else 'fail'}"))
                keep &= ~m
        fit.left_out = tuple(left)
        df = df[keep]
        fit.families = tuple(_families_in(df))
    y = df["success"].to_numpy(dtype=float)
    fit.n_rows, fit.n_successes = len(df), int(y.sum())
    fit.n_platforms = int(df["platform"].nunique())
    if fit.n_rows == 0 or fit.n_successes in (0, fit.n_rows):
        fit.note = ("not estimable: no variation (every trial fitted "
                    f"{'succeeds' if fit.n_successes else 'fails'})" if fit.n_rows
                    else "not estimable: no rows")
        return fit
    x = df[list(columns)].to_numpy(dtype=float)
    sd = x.std(axis=0, ddof=1)
    flat = [labels[c] for c, s in zip(columns, sd) if not s > 0]
    if flat:
        fit.note = f"not estimable: no variation in {', '.join(flat)}"
        return fit
    z = (x - x.mean(axis=0)) / sd
    parts = [np.ones((len(df), 1)), z]
    if with_families and len(fit.families) > 1:
        fam = df["family"].to_numpy()
        parts.append(np.column_stack([(fam == f).astype(float) for f in fit.families[1:]]))
    X = np.column_stack(parts)
    if np.linalg.matrix_rank(X) < X.shape[1]:
        fit.note = "not estimable: the predictors are linearly dependent over these rows"
        return fit
    if separated(X, y):
        fit.note = ("not estimable: the predictors separate the successes from the failures "
                    "(no maximum-likelihood estimate)")
        return fit
    platform = pd.factorize(df["platform"])[0]
    both = np.column_stack([platform, pd.factorize(df["scenario"])[0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no convergence, overflow: say so, no numbers
        try:
            model = sm.Logit(y, X)
            res = model.fit(disp=0, maxiter=200, cov_type="cluster",
                            cov_kwds={"groups": platform})
            res2 = model.fit(disp=0, maxiter=200, start_params=res.params,
                             cov_type="cluster", cov_kwds={"groups": both})
        except (Warning, np.linalg.LinAlgError, ValueError) as exc:
            fit.note = f"not estimable: the fit failed ({type(exc).__name__}: {exc})"
            return fit
    if not res.mle_retvals.get("converged", False):
        fit.note = "not estimable: maximum likelihood did not converge"
        return fit
    ci, ci2 = np.asarray(res.conf_int()), np.asarray(res2.conf_int())
    for j, c in enumerate(columns, start=1):
        fit.coefficients.append({
            "column": c, "label": labels[c], "coef": float(res.params[j]),
            "se": float(res.bse[j]), "z": float(res.tvalues[j]), "p": float(res.pvalues[j]),
            "lo": float(ci[j, 0]), "hi": float(ci[j, 1]),
            "se2": float(res2.bse[j]), "p2": float(res2.pvalues[j]),
            "lo2": float(ci2[j, 0]), "hi2": float(ci2[j, 1]), "sd": float(sd[j - 1])})
    fit.pseudo_r2 = float(res.prsquared)
    return fit


def fit_difficulty_models(df: pd.DataFrame) -> dict:
    """Per algorithm of :func:`design`'s table: the ``metrics`` and ``families`` models
    (module docstring) and the pseudo-R^2 of the :data:`COMPARISON` models. Returns
    ``{"fits": [DifficultyFit...], "comparison": {algorithm: {model: pseudo-R^2 or
    None}}}``."""
    fits, comparison = [], {}
    for algo, g in df.groupby("algorithm", sort=True):
        cols = [c for c, _ in PREDICTORS]
        fits.append(fit_model(g, str(algo), "metrics", cols, False))
        fits.append(fit_model(g, str(algo), "families", cols, True))
        comparison[str(algo)] = {}
        for name, (columns, fams) in COMPARISON.items():
            f = fit_model(g, str(algo), name, columns, fams)
            comparison[str(algo)][name] = (round(f.pseudo_r2, 4)
                                           if math.isfinite(f.pseudo_r2) else None)
    return {"fits": fits, "comparison": comparison}


def measures_table(measured: Mapping) -> pd.DataFrame:
    """FlightBench's metrics and the project's own measures (path / line, turns, spare,
    filled, time) of each configuration of a ``difficulty.json`` document, indexed by
    the configuration's name."""
    rows = {}
    for entries in measured["families"].values():
        for e in entries:
            d, m = e["difficulty"], e["flightbench"]
            rows[d["scenario"]] = {
                "TO": m["to"], "VO": m["vo"], "AOL": m["aol"],
                "path / line": d["path_ratio"], "turns": d["turns"],
                "spare": d["passage_spare_m"], "filled": d["occupied_fraction"],
                "time": d["time_s"]}
    return pd.DataFrame.from_dict(rows, orient="index").astype(float)


def metric_correlations(measured: Mapping) -> pd.DataFrame:
    """Spearman rank correlations over the configurations between FlightBench's metrics
    and every measure of :func:`measures_table`."""
    return measures_table(measured).corr(method="spearman")


def success_correlations(df: pd.DataFrame, measured: Mapping) -> pd.DataFrame:
    """Spearman rank correlation over the configurations between each algorithm's
    success rate (over the platforms) and each measure of :func:`measures_table`: rows
    the measures, columns the algorithms. FlightBench validates its metrics this way
    (its Sec. 4, correlations over its 8 test cases); here there are 70."""
    rates = df.groupby(["scenario", "algorithm"])["success"].mean().unstack("algorithm")
    table = measures_table(measured).loc[rates.index]
    return pd.DataFrame({a: table.corrwith(rates[a], method="spearman")
                         for a in rates.columns})


# --------------------------------------------------------------------------------------
# tables
# --------------------------------------------------------------------------------------


def _signed(v: float) -> str:
    return f"{v:+.2f}"


def markdown_coefficients(fits, model: str) -> str:
    """One row per algorithm of ``model``'s fits: each predictor's log-odds per SD with
    its p-values (errors clustered by platform; by platform and configuration), then n
    and the pseudo-R^2; or why it is not estimable."""
    labels = [label for _, label in PREDICTORS]
    rows = []
    for f in fits:
        if f.model != model:
            continue
        if not f.fitted:
            rows.append([f.algorithm, f.note] + [""] * (len(labels) + 1))
            continue
        cells = [f"{_signed(c['coef'])} ({p_text(c['p'])}; {p_text(c['p2'])})"
                 for c in f.coefficients]
        rows.append([f.algorithm, *cells, f"{f.n_rows} ({f.n_successes})",
                     f"{f.pseudo_r2:.3f}"])
    return md.table(["algorithm", *labels, "trials (successes)", "pseudo-R^2"], rows)


def markdown_left_out(fits, model: str) -> str:
    """The families each algorithm's ``model`` fit left out, one line each (or none)."""
    lines = [f"- {f.algorithm}: " + "; ".join(f"{fam} ({why})" for fam, why in f.left_out)
             for f in fits if f.model == model and f.left_out]
    return "\n".join(lines) if lines else "- none"


def markdown_comparison(comparison: Mapping) -> str:
    """The pseudo-R^2 of the :data:`COMPARISON` models per algorithm."""
    names = list(COMPARISON)
    return md.table(["algorithm", *names], [
        [algo, *("-" if r2[n] is None else f"{r2[n]:.3f}" for n in names)]
        for algo, r2 in comparison.items()])


def markdown_success_correlations(corr: pd.DataFrame) -> str:
    """Each measure (rows) against each algorithm's success rate (columns)."""
    cols = list(corr.columns)
    return md.table(["measure", *cols], [
        [row, *(f"{corr.loc[row, c]:+.2f}" for c in cols)] for row in corr.index])


def markdown_correlations(corr: pd.DataFrame) -> str:
    """FlightBench's metrics (rows) against every measure (columns)."""
    cols = list(corr.columns)
    return md.table(["", *cols], [
        [row, *(f"{corr.loc[row, c]:+.2f}" for c in cols)] for row in ("TO", "VO", "AOL")])
