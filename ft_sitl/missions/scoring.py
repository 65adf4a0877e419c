"""Statistics and the FLYINGTRUST composite score over the results table.

Three entry points, all reading the table of :mod:`ft_sitl.missions.results` (one row per
trial):

* :func:`success_table` -- success rate per group (by default per algorithm, scenario
  family and platform: the paper's ``S_{a,s,m}``) with a seeded percentile-bootstrap
  confidence interval (Sec. IV-B: 95 %, B = 1000) and, next to it, the Wilson score
  interval (:func:`wilson_interval`), which stays informative for small groups.
* :func:`composite_score` -- the weighted score, weighted variance, normalised variance
  and variance-penalised final score per algorithm (Sec. III-C, eqs. 12-19), with the
  missing-scenario renormalisation and a ``comparable`` flag.
* :func:`failure_breakdown` -- how often each exit reason (:data:`results.REASONS`)
  occurs per group.

:func:`final_score` and :func:`final_scores_from_table` are eq. 17-18 alone, on numbers,
so published Score / Var columns can be checked. The definitions, defaults and the
decisions taken where the paper is silent are written up in ``docs/scoring.md``.

Bootstrap method: a group of ``n`` Bernoulli trials with ``k`` successes is resampled
``B`` times; drawing ``n`` trials with replacement and counting successes is exactly a
Binomial(n, k/n) draw, so each resample is one ``rng.binomial`` draw (no index arrays).
The interval is the (1-ci)/2 and (1+ci)/2 quantiles of the ``B`` resampled rates
(numpy's default linear interpolation). Each group gets its own generator, seeded from
``seed`` and a stable digest of the group's key, so a group's interval does not depend on
which other groups are in the table or in what order they come.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Iterable, Mapping, Sequence
from numbers import Real

import numpy as np
import pandas as pd
from scipy.stats import binomtest

from ft_sitl.missions.results import REASONS
from ft_sitl.physics.catalog import catalog
from ft_sitl.physics.series import SERIES_CATEGORY
from ft_sitl.scenarios.families import CATEGORY, FAMILIES

#: The paper's initial scenario weights (Sec. IV, Q5) by scenario category. ``user``
#: scenarios (imported meshes, custom families) count like theoretical ones.
DEFAULT_SCENARIO_WEIGHTS = {"classic": 1.2, "theoretical": 1.0, "user": 1.0}
#: The paper's initial platform weights (Sec. IV, Q5) by platform category. ``user``
#: platforms and the controlled ``series`` (synthetic, like the virtual set) count like
#: virtual ones.
DEFAULT_PLATFORM_WEIGHTS = {"real": 1.5, "virtual": 1.0, "user": 1.0, SERIES_CATEGORY: 1.0}
#: The paper's stability-penalty coefficient (Sec. IV, Q5).
DEFAULT_BETA = 0.3

CELL = ("algorithm", "family", "platform")
SCORE_COLUMNS = ("algorithm", "Score", "Var", "Var_norm", "FinalScore", "missing_scenarios",
                 "comparable", "n_trials", "n_cells", "missing_cells")


# --------------------------------------------------------------------------- helpers
def _require_columns(df: pd.DataFrame, columns: Iterable[str], what: str) -> None:
    missing = [c for c in columns if c not in df.columns]
    if missing:
        raise ValueError(f"{what}: the table has no column(s) {', '.join(map(repr, missing))} "
                         f"(columns: {', '.join(map(str, df.columns))})")


def _as_by(by) -> tuple[str, ...]:
    if isinstance(by, str):
        by = (by,)
    by = tuple(by)
    if not by:
        raise ValueError("by: give at least one column to group by")
    if len(set(by)) != len(by):
        raise ValueError(f"by: repeated column in {by!r}")
    return by


def _check_keys_present(df: pd.DataFrame, by: Sequence[str], what: str) -> None:
    for c in by:
        n_missing = int(df[c].isna().sum())
        if n_missing:
            raise ValueError(f"{what}: {n_missing} row(s) have no value in column {c!r}; "
                             "every trial must name its group")


def _group_seed(seed: int, by: Sequence[str], key: Sequence) -> np.random.Generator:
    text = "\x1f".join(f"{c}={k}" for c, k in zip(by, key, strict=True))
    digest = hashlib.blake2b(text.encode("utf-8"), digest_size=8).digest()
    return np.random.default_rng(np.random.SeedSequence([seed, int.from_bytes(digest,
                                                                              "little")]))


def bootstrap_interval(n: int, successes: int, *, B: int, ci: float,
                       rng: np.random.Generator) -> tuple[float, float]:
    """Percentile-bootstrap interval of the success rate of ``n`` Bernoulli trials with
    ``successes`` successes: ``B`` Binomial(n, successes/n) resamples (equivalent to
    resampling the trials with replacement), quantiles (1-ci)/2 and (1+ci)/2."""
    if n <= 0:
        raise ValueError(f"bootstrap_interval: n must be > 0, got {n}")
    if not 0 <= successes <= n:
        raise ValueError(f"bootstrap_interval: successes must be in [0, {n}], got {successes}")
    rates = rng.binomial(n, successes / n, size=B) / n
    lo, hi = np.quantile(rates, [(1.0 - ci) / 2.0, (1.0 + ci) / 2.0])
    return float(lo), float(hi)


def wilson_interval(n: int, successes: int, *, ci: float = 0.95) -> tuple[float, float]:
    """Wilson score interval of the success rate of ``n`` Bernoulli trials with
    ``successes`` successes (scipy's ``binomtest(...).proportion_ci(method="wilson")``).

    Unlike the percentile bootstrap it does not collapse for an all-success or
    all-failure group: 10/10 gives [0.72, 1], not [1, 1]."""
    if n <= 0:
        raise ValueError(f"wilson_interval: n must be > 0, got {n}")
    if not 0 <= successes <= n:
        raise ValueError(f"wilson_interval: successes must be in [0, {n}], got {successes}")
    interval = binomtest(int(successes), int(n)).proportion_ci(confidence_level=float(ci),
                                                               method="wilson")
    return float(interval.low), float(interval.high)


# --------------------------------------------------------------------------- success
def success_table(df: pd.DataFrame, by=CELL, *, B: int = 1000, seed: int = 0,
                  ci: float = 0.95) -> pd.DataFrame:
    """Success rate, bootstrap and Wilson confidence intervals per group of trials.

    ``by`` is any tuple of columns of the results table: the default is the paper's cell
    (algorithm, family, platform); ``("algorithm", "family")`` pools the platforms of each
    scenario family, ``("algorithm",)`` pools everything per algorithm. Pooling means the
    trials of the group are taken together (rate = successes / n), resampled as one sample.

    Returns one row per group present in ``df`` (sorted by ``by``), with the ``by``
    columns, ``n`` (trials), ``successes``, ``rate``, ``ci_lo`` and ``ci_hi`` (the
    percentile bootstrap: ``B`` resamples, seeded by ``seed``; see the module docstring:
    same seed, same intervals; each group's interval is independent of the rest of the
    table), and ``wilson_lo``, ``wilson_hi`` (:func:`wilson_interval`, no resampling).
    """
    by = _as_by(by)
    _require_columns(df, (*by, "success"), "success_table")
    if isinstance(B, bool) or not isinstance(B, int | np.integer) or B < 1:
        raise ValueError(f"success_table: B must be a positive integer, got {B!r}")
    if isinstance(ci, bool) or not isinstance(ci, Real) or not 0.0 < float(ci) < 1.0:
        raise ValueError(f"success_table: ci must be a number in (0, 1), got {ci!r}")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"success_table: seed must be a non-negative integer, got {seed!r}")
    _check_keys_present(df, by, "success_table")
    if df["success"].isna().any():
        raise ValueError("success_table: some rows have no 'success' value")

    ok = df["success"].astype(bool)
    grouped = ok.groupby([df[c] for c in by], observed=True, sort=True)
    counts = grouped.agg(["size", "sum"])
    out = counts.reset_index()
    out.columns = [*by, "n", "successes"]
    out["n"] = out["n"].astype(int)
    out["successes"] = out["successes"].astype(int)
    out["rate"] = out["successes"] / out["n"]
    lo, hi, w_lo, w_hi = (np.empty(len(out)) for _ in range(4))
    keys = out[list(by)].itertuples(index=False, name=None)
    for i, (key, n, k) in enumerate(zip(keys, out["n"], out["successes"], strict=True)):
        lo[i], hi[i] = bootstrap_interval(int(n), int(k), B=int(B), ci=float(ci),
                                          rng=_group_seed(int(seed), by, key))
        w_lo[i], w_hi[i] = wilson_interval(int(n), int(k), ci=float(ci))
    out["ci_lo"] = lo
    out["ci_hi"] = hi
    out["wilson_lo"] = w_lo
    out["wilson_hi"] = w_hi
    for c in by:
        if isinstance(df[c].dtype, pd.CategoricalDtype):
            out[c] = out[c].cat.remove_unused_categories()
    return out


# --------------------------------------------------------------------------- score
def final_score(score, var, beta: float, var_max):
    """Eq. 17-18: ``score * (1 - beta * var / var_max)``.

    ``score`` in percent (0..100), ``var`` and ``var_max`` the weighted variances of the
    success rates (0..0.25). Scalars or arrays. ``var_max == 0`` (no algorithm varies at
    all) gives ``Var_norm = 0``, i.e. no penalty."""
    check_beta(beta)
    score = np.asarray(score, dtype=float)
    var = np.asarray(var, dtype=float)
    var_max = np.asarray(var_max, dtype=float)
    if np.any(var < 0) or np.any(var_max < 0):
        raise ValueError("final_score: variances must be >= 0")
    if np.any(var > var_max):
        raise ValueError(f"final_score: var {var} exceeds var_max {var_max} "
                         "(var_max is the largest Var over the algorithms compared)")
    with np.errstate(invalid="ignore", divide="ignore"):
        var_norm = np.where(var_max > 0, var / np.where(var_max > 0, var_max, 1.0), 0.0)
    out = score * (1.0 - beta * var_norm)
    return float(out) if out.ndim == 0 else out


def final_scores_from_table(scores: Mapping[str, tuple[float, float]],
                            beta: float = DEFAULT_BETA) -> dict[str, float]:
    """FinalScore per algorithm from published ``{name: (Score, Var)}`` (eq. 17-18), the
    normalising maximum taken over the given algorithms."""
    if not scores:
        raise ValueError("final_scores_from_table: no algorithms given")
    var_max = max(float(v) for _, v in scores.values())
    return {name: final_score(float(s), float(v), beta, var_max)
            for name, (s, v) in scores.items()}


def check_beta(beta, what: str = "beta") -> None:
    """The rule for the stability-penalty coefficient (eq. 18); ``what`` names it."""
    if isinstance(beta, bool) or not isinstance(beta, Real) or not 0.0 <= float(beta) <= 1.0:
        raise ValueError(f"{what} must be a number in [0, 1] (eq. 18), got {beta!r}")


def _category_of(cells: pd.DataFrame, key: str, cat_col: str, what: str) -> dict[str, str]:
    """Map each value of ``key`` to its one category, or raise naming the conflict."""
    pairs = cells[[key, cat_col]].drop_duplicates()
    out: dict[str, str] = {}
    for name, cat in pairs.itertuples(index=False, name=None):
        if pd.isna(cat):
            raise ValueError(f"composite_score: {what} {name!r} has no {cat_col}")
        if name in out and out[name] != cat:
            raise ValueError(f"composite_score: {what} {name!r} appears with two categories "
                             f"({out[name]!r} and {cat!r}) in column {cat_col!r}")
        out[str(name)] = str(cat)
    return out


def _cells(df: pd.DataFrame) -> pd.DataFrame:
    """The (algorithm, family, platform) cells with rate, n and both categories."""
    if "success" in df.columns:
        _require_columns(df, (*CELL, "success", "scenario_category", "platform_category"),
                         "composite_score")
        _check_keys_present(df, CELL, "composite_score")
        g = df.groupby([df[c].astype(str) for c in CELL], observed=True, sort=True)
        cells = g["success"].agg(["mean", "size"]).reset_index()
        cells.columns = [*CELL, "rate", "n"]
        fam = _category_of(df.assign(family=df["family"].astype(str)), "family",
                           "scenario_category", "family")
        plat = _category_of(df.assign(platform=df["platform"].astype(str)), "platform",
                            "platform_category", "platform")
    elif "rate" in df.columns:
        _require_columns(df, (*CELL, "rate"), "composite_score (rates table)")
        _check_keys_present(df, CELL, "composite_score")
        cells = df[list(CELL) + ["rate"] + (["n"] if "n" in df.columns else [])].copy()
        for c in CELL:
            cells[c] = cells[c].astype(str)
        if cells.duplicated(list(CELL)).any():
            raise ValueError("composite_score: the rates table has more than one row for some "
                             "(algorithm, family, platform); give one rate per cell")
        if "n" not in cells.columns:
            cells["n"] = pd.NA
        rates = pd.to_numeric(cells["rate"], errors="coerce")
        if rates.isna().any() or (rates < 0).any() or (rates > 1).any():
            raise ValueError("composite_score: every 'rate' must be a number in [0, 1]")
        cells["rate"] = rates.astype(float)
        fam = _lookup_categories(df, cells, "family", "scenario_category")
        plat = _lookup_categories(df, cells, "platform", "platform_category")
    else:
        raise ValueError("composite_score: give the trial table (with a 'success' column) or "
                         "a rates table (with a 'rate' column, e.g. from success_table)")
    cells["scenario_category"] = cells["family"].map(fam)
    cells["platform_category"] = cells["platform"].map(plat)
    return cells


def _lookup_categories(df, cells, key, cat_col) -> dict[str, str]:
    """Categories for a rates table: its own column if present, else the package's
    families (scenario category) or the platform catalog (platform category)."""
    if cat_col in df.columns:
        return _category_of(df.assign(**{key: df[key].astype(str)}), key, cat_col, key)
    names = sorted(cells[key].unique())
    if key == "family":
        known = CATEGORY
    else:
        known = {name: p.category for name, p in catalog().items()}
    unknown = [n for n in names if n not in known]
    if unknown:
        raise ValueError(f"composite_score: no {cat_col} for {key}(s) "
                         f"{', '.join(map(repr, unknown))}; add a {cat_col!r} column to the "
                         "rates table")
    return {n: known[n] for n in names}


def resolve_weights(given, defaults: dict[str, float], names_to_cat: dict[str, str],
                    known_names: Iterable[str], what: str) -> tuple[dict[str, float], dict]:
    """Weight per name: a per-name entry wins over its category's entry; entries given
    override the paper's defaults, the rest keep them. The rule for weights given (keys:
    a category or a known name; values: finite numbers > 0) is checked here, for the
    scorer and for campaign files alike; ``what`` names them in messages."""
    if given is None:
        given = {}
    if not isinstance(given, Mapping):
        raise ValueError(f"{what}: give a dict of weights by category or name, "
                         f"got {type(given).__name__}")
    categories = set(defaults) | set(names_to_cat.values())
    known = set(known_names) | set(names_to_cat)
    for k, v in given.items():
        if not isinstance(k, str) or (k not in categories and k not in known):
            raise ValueError(
                f"{what}: unknown key {k!r}: neither a category "
                f"({', '.join(sorted(categories))}) nor a name in the results "
                f"({', '.join(sorted(names_to_cat))})")
        if (isinstance(v, bool) or not isinstance(v, Real) or not math.isfinite(float(v))
                or float(v) <= 0):
            raise ValueError(f"{what}[{k!r}] = {v!r}: weights must be finite numbers > 0")
    merged = {**defaults, **{k: float(v) for k, v in given.items()}}
    out = {}
    for name, cat in names_to_cat.items():
        if name in given:
            out[name] = float(given[name])
        elif cat in merged:
            out[name] = merged[cat]
        else:
            raise ValueError(f"{what}: no weight for {name!r} (category {cat!r}); give one "
                             f"for the category or the name")
    return out, merged


def composite_score(df_or_rates: pd.DataFrame, *, scenario_weights: Mapping | None = None,
                    platform_weights: Mapping | None = None, beta: float = DEFAULT_BETA,
                    all_families: Iterable[str] | None = None) -> pd.DataFrame:
    """The FLYINGTRUST composite score per algorithm (Sec. III-C, eqs. 12-19).

    ``df_or_rates`` is the trial table (``S_{a,s,m}`` = the fraction of successful trials
    of each algorithm, family and platform) or a rates table with columns algorithm,
    family, platform, rate (and optionally n, scenario_category, platform_category; without
    the category columns the package's families and platform catalog supply them).

    Weights: ``scenario_weights`` and ``platform_weights`` map a category (scenario:
    classic / theoretical / user; platform: real / virtual / user) or a single family or
    platform name to an initial weight ``w > 0``. Given entries override the paper's
    defaults (:data:`DEFAULT_SCENARIO_WEIGHTS`, :data:`DEFAULT_PLATFORM_WEIGHTS`); a name
    entry wins over its category's entry.

    Per algorithm ``a``, over the cells (s, m) it has results for, with
    ``W = w_s w_m / sum(w_s' w_m')`` (eqs. 12-14, 19 in one normalisation):
    ``Score = 100 sum W S``, ``Var = sum W (S - Score/100)^2``,
    ``Var_norm = Var / max_a' Var_a'`` (over all algorithms in the table; 0 if that max is
    0), ``FinalScore = Score (1 - beta Var_norm)``.

    Missing data: a scenario family of ``all_families`` (default: every family in the
    table) in which the algorithm has no trial at all is dropped for it and listed in
    ``missing_scenarios`` (eq. 19). ``missing_cells`` counts (family, platform) cells of
    the table's full grid the algorithm lacks (whole missing families included).
    ``comparable`` is True only when the algorithm covers the full grid, i.e. its score
    is computed over the same evaluation set as a complete algorithm's.

    Returns one row per algorithm (sorted by name) with :data:`SCORE_COLUMNS`; the
    resolved weights per family and platform are in ``.attrs``.
    """
    check_beta(beta)
    if len(df_or_rates) == 0:
        raise ValueError("composite_score: the table is empty")
    cells = _cells(df_or_rates)
    families = sorted(cells["family"].unique())
    platforms = sorted(cells["platform"].unique())
    if all_families is None:
        grid_families = families
    else:
        if isinstance(all_families, str):
            raise ValueError("all_families: give a list of family names, not one string")
        grid_families = list(dict.fromkeys(str(f) for f in all_families))
        extra = [f for f in families if f not in grid_families]
        if extra:
            raise ValueError(f"all_families: the results have family(ies) "
                             f"{', '.join(map(repr, extra))} not in all_families "
                             f"{grid_families!r}")

    fam_cat = dict(cells[["family", "scenario_category"]].drop_duplicates()
                   .itertuples(index=False, name=None))
    plat_cat = dict(cells[["platform", "platform_category"]].drop_duplicates()
                    .itertuples(index=False, name=None))
    w_s, merged_s = resolve_weights(scenario_weights, DEFAULT_SCENARIO_WEIGHTS, fam_cat,
                                    list(FAMILIES) + grid_families, "scenario_weights")
    w_m, merged_m = resolve_weights(platform_weights, DEFAULT_PLATFORM_WEIGHTS, plat_cat,
                                    (), "platform_weights")

    cells["w"] = cells["family"].map(w_s) * cells["platform"].map(w_m)
    grid_size = len(grid_families) * len(platforms)
    rows = []
    for algo, c in cells.groupby("algorithm", sort=True):
        W = c["w"].to_numpy() / c["w"].sum()
        S = c["rate"].to_numpy(dtype=float)
        score_hat = float(np.sum(W * S))
        var = float(np.sum(W * (S - score_hat) ** 2))
        present = set(c["family"])
        n = pd.to_numeric(c["n"], errors="coerce")
        rows.append({
            "algorithm": algo,
            "Score": 100.0 * score_hat,
            "Var": var,
            "missing_scenarios": [f for f in grid_families if f not in present],
            "n_trials": int(n.sum()) if n.notna().all() else pd.NA,
            "n_cells": len(c),
            "missing_cells": grid_size - len(c),
        })
    out = pd.DataFrame(rows)
    var_max = float(out["Var"].max())
    out["Var_norm"] = out["Var"] / var_max if var_max > 0 else 0.0
    out["FinalScore"] = final_score(out["Score"].to_numpy(), out["Var"].to_numpy(), beta,
                                    var_max)
    out["comparable"] = out["missing_cells"] == 0
    out["n_trials"] = out["n_trials"].astype("Int64")
    out = out[list(SCORE_COLUMNS)]
    out.attrs.update({"beta": float(beta), "scenario_weights": w_s, "platform_weights": w_m,
                      "all_families": list(grid_families), "platforms": platforms,
                      "scenario_weight_table": merged_s, "platform_weight_table": merged_m})
    return out


# --------------------------------------------------------------------------- failures
def failure_breakdown(df: pd.DataFrame, by=("algorithm",)) -> pd.DataFrame:
    """How often each exit reason occurs per group: a long table with the ``by``
    columns, ``reason`` (every one of :data:`REASONS`, in that order, zero counts
    included), ``count``, ``n`` (trials in the group) and ``fraction`` (count / n; the
    fractions of a group sum to 1, ``success`` included)."""
    by = _as_by(by)
    _require_columns(df, (*by, "reason"), "failure_breakdown")
    _check_keys_present(df, by, "failure_breakdown")
    reason = df["reason"].astype("object")
    bad = reason.isna() | ~reason.isin(REASONS)
    if bad.any():
        vals = sorted({str(v) for v in reason[bad]})
        raise ValueError(f"failure_breakdown: {int(bad.sum())} row(s) have no known reason "
                         f"({', '.join(vals)}); reasons are {', '.join(REASONS)}")
    reason = pd.Categorical(reason, categories=list(REASONS))
    counts = pd.crosstab([df[c] for c in by], reason, dropna=False)
    counts = counts.reindex(columns=list(REASONS), fill_value=0)
    counts = counts[counts.sum(axis=1) > 0]
    long = counts.stack().rename("count").reset_index()
    long.columns = [*by, "reason", "count"]
    long["reason"] = pd.Categorical(long["reason"].astype(str), categories=list(REASONS))
    long["count"] = long["count"].astype(int)
    long["n"] = long.groupby(list(by), observed=True)["count"].transform("sum").astype(int)
    long["fraction"] = long["count"] / long["n"]
    long = long.sort_values([*by, "reason"], kind="stable").reset_index(drop=True)
    for c in by:
        if isinstance(long[c].dtype, pd.CategoricalDtype):
            long[c] = long[c].cat.remove_unused_categories()
    return long
